"""The checkout's numba cache is emptied exactly when the compiled sources changed
(:mod:`isoflow._numba_cache`): numba alone would load a loop compiled before a block it
inlines changed."""

from __future__ import annotations

from pathlib import Path

import pytest

from isoflow import _numba_cache


def _tree(root: Path) -> Path:
    pkg = root / "isoflow"
    (pkg / "_compiled").mkdir(parents=True)
    (pkg / "sphere").mkdir()
    (pkg / "_compiled" / "blocks.py").write_text("x = 1\n")
    (pkg / "sphere" / "compiled.py").write_text("y = 2\n")
    (pkg / "sphere" / "figures.py").write_text("z = 3\n")  # not inlined anywhere
    return pkg


def test_refresh_keeps_a_fresh_cache_and_empties_a_stale_one(tmp_path, monkeypatch) -> None:
    pkg = _tree(tmp_path / "src")
    monkeypatch.setattr(_numba_cache, "_PACKAGE", pkg)
    cache = tmp_path / "cache"
    assert _numba_cache.refresh(cache)  # created and stamped
    entry = cache / "loop.nbi"
    entry.write_text("compiled")
    assert not _numba_cache.refresh(cache) and entry.exists()  # same sources: kept
    (pkg / "sphere" / "figures.py").write_text("z = 4\n")
    assert not _numba_cache.refresh(cache) and entry.exists()  # a file nothing inlines
    (pkg / "_compiled" / "blocks.py").write_text("x = 2\n")
    assert _numba_cache.refresh(cache) and not entry.exists()  # an inlined block: emptied
    assert (cache / "SOURCES").read_text().strip() == _numba_cache.compiled_sources_digest()


@pytest.mark.parametrize("change", ["content", "name"])
def test_digest_follows_the_inlined_sources(tmp_path, monkeypatch, change: str) -> None:
    pkg = _tree(tmp_path / "src")
    monkeypatch.setattr(_numba_cache, "_PACKAGE", pkg)
    before = _numba_cache.compiled_sources_digest()
    f = pkg / "_compiled" / "blocks.py"
    if change == "content":
        f.write_text("x = 1  # edited\n")
    else:
        f.rename(pkg / "_compiled" / "blocks2.py")
    assert _numba_cache.compiled_sources_digest() != before
