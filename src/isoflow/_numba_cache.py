"""numba's on-disk cache kept true to isoflow's compiled sources, for a source checkout.

numba's cache checks only the file that defines a function: a compiled loop that inlines a
block from another module (every stage inlines its layout's blocks) is loaded stale from the
cache after that block changes, and runs the old code without a word. :func:`refresh` empties
a cache directory whenever the compiled layer's sources differ from those it was filled from
(their digest is kept in the directory's ``SOURCES`` file). The test suite
(``tests/conftest.py``) and the benchmark suite (``benchmarks/run_all.py``) run with the
checkout's own cache directory, ``.numba_cache``, and call it before numba is imported.

A source checkout installed in editable mode (``pip install -e .``, the README's commands)
keeps numba's entries in the ``__pycache__`` directories beside the sources, and a ``git pull``
that changes a block but not the stage that inlines it would leave the stage stale there.
``import isoflow`` therefore calls :func:`refresh_checkout_cache`: in a checkout (the package
under ``src/`` beside a ``pyproject.toml``) and with numba's default cache locations (no
``NUMBA_CACHE_DIR``), it deletes the package's cached entries (``__pycache__/*.nbi``,
``*.nbc``) when the compiled sources differ from the stamp ``__pycache__/numba-sources`` and
stamps them anew. A wheel or sdist install does not need it: installing writes every source
file anew, which invalidates every cached entry. A ``NUMBA_CACHE_DIR`` you set is yours: the
test and benchmark suites refresh their own (:func:`refresh`), nothing else touches it. This
module imports nothing heavy (no numba).
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

__all__ = ["INLINED", "compiled_sources_digest", "refresh", "refresh_checkout_cache"]

#: The sources whose functions other modules' compiled code inlines (relative to the package).
INLINED = ("_compiled", "_kernel_fields.py", "sphere/compiled.py")

_PACKAGE = Path(__file__).resolve().parent


def compiled_sources_digest(package: Path | None = None) -> str:
    """SHA-256 of the :data:`INLINED` sources of ``package`` (default: this package), their
    paths and contents in a fixed order."""
    root = _PACKAGE if package is None else package
    files: list[Path] = []
    for name in INLINED:
        p = root / name
        files.extend(sorted(p.rglob("*.py")) if p.is_dir() else [p] if p.exists() else [])
    h = hashlib.sha256()
    for f in files:
        h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def refresh(cache: Path) -> bool:
    """Empty the numba cache directory ``cache`` unless it was filled from the current
    sources (the digest in ``cache / "SOURCES"``), and stamp it; returns whether it was
    emptied (or created)."""
    stamp = cache / "SOURCES"
    digest = compiled_sources_digest()
    if stamp.exists() and stamp.read_text().strip() == digest:
        return False
    if cache.exists():
        shutil.rmtree(cache, ignore_errors=True)
    cache.mkdir(parents=True, exist_ok=True)
    stamp.write_text(digest + "\n")
    return True


def refresh_checkout_cache(package: Path | None = None) -> bool:
    """Delete the package's numba entries in its ``__pycache__`` directories when it is a
    source checkout whose compiled sources changed since they were stamped (module
    docstring); returns whether they were deleted. Does nothing for an installed package, with
    ``NUMBA_CACHE_DIR`` set, or where the checkout is not writable."""
    root = _PACKAGE if package is None else package
    if os.environ.get("NUMBA_CACHE_DIR"):
        return False
    if root.parent.name != "src" or not (root.parent.parent / "pyproject.toml").is_file():
        return False
    stamp = root / "__pycache__" / "numba-sources"
    digest = compiled_sources_digest(root)
    try:
        if stamp.read_text().strip() == digest:
            return False
    except OSError:
        pass  # no stamp yet: entries of unknown sources
    try:
        for entry in root.rglob("*.nb[ic]"):
            if entry.parent.name == "__pycache__":
                entry.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest + "\n")
    except OSError:
        return False
    return True
