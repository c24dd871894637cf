"""Sphinx configuration of the isoflow documentation.

Build from the repository root with ``sphinx-build -W -b html docs docs/_build/html``;
``ISOFLOW_DOCS_QUICK=1`` runs the gallery's examples in their small versions (as CI does).
"""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
# module docstrings have prose sections of their own ("Conventions", "The sweep file (TOML)");
# numpydoc renders them as written and says so in a UserWarning each, on every build
warnings.filterwarnings("ignore", message="Unknown section", category=UserWarning)

import isoflow  # noqa: E402

project = "isoflow"
author = "the isoflow developers"
copyright = "the isoflow developers (MIT licence)"
release = isoflow.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    # MathJax 3 copied into the site (_static/mathjax), so the maths renders without network
    "sphinx-mathjax-offline",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "isoflow_docs",
]

nitpicky = True
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "**.zip"]
templates_path: list[str] = []
default_role = "py:obj"

autodoc_typehints = "none"
autodoc_member_order = "bysource"
autosummary_generate = False
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

html_theme = "pydata_sphinx_theme"
html_title = f"isoflow {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path: list[str] = []
html_show_sourcelink = False

sphinx_gallery_conf = {
    "examples_dirs": ["../examples"],
    "gallery_dirs": ["auto_examples"],
    "filename_pattern": r"/plot_",
    "image_scrapers": ("isoflow_docs.figure_scraper",),
    "reset_modules": ("isoflow_docs.reset_figures",),
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "sphinx_gallery.sorting.FileNameSortKey",
    # the examples print what they show; the value of a cell's last expression (the Text of
    # fig.suptitle, the Legend of ax.legend) is not output
    "capture_repr": (),
    "min_reported_time": 1,
    "show_memory": False,
    "plot_gallery": "True",
}
