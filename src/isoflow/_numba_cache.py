"""numba's on-disk cache kept true to isoflow's compiled sources, for a source checkout.

numba's cache checks only the file that defines a function: a compiled loop that inlines a
block from another module (every stage inlines its layout's blocks) is loaded stale from the
cache after that block changes, and runs the old code without a word. :func:`refresh` empties
a cache directory whenever the compiled layer's sources differ from those it was filled from
(their digest is kept in the directory's ``SOURCES`` file). The test suite
(``tests/conftest.py``) and the benchmark suite (``benchmarks/run_all.py``) run with the
checkout's own cache directory, ``.numba_cache``, and call it before numba is imported.

An installed package does not need it: installing writes every source file anew, which
invalidates every cached entry. This module imports nothing heavy (no numba).
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

__all__ = ["INLINED", "compiled_sources_digest", "refresh"]

#: The sources whose functions other modules' compiled code inlines (relative to the package).
INLINED = ("_compiled", "_kernel_fields.py", "sphere/compiled.py")

_PACKAGE = Path(__file__).resolve().parent


def compiled_sources_digest() -> str:
    """SHA-256 of the :data:`INLINED` sources (their paths and contents, in a fixed order)."""
    files: list[Path] = []
    for name in INLINED:
        p = _PACKAGE / name
        files.extend(sorted(p.rglob("*.py")) if p.is_dir() else [p] if p.exists() else [])
    h = hashlib.sha256()
    for f in files:
        h.update(str(f.relative_to(_PACKAGE)).encode() + b"\0" + f.read_bytes() + b"\0")
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
