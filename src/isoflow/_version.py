"""The installed version of isoflow, in one place.

Modules that record the version (result files, experiment summaries) import it from here, not
from the package root, so that no module imports the package that imports it.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["__version__"]

try:
    __version__: str = version("isoflow")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"
