"""The checkout's numba cache is emptied exactly when the compiled sources changed
(:mod:`isoflow._numba_cache`): numba alone would load a loop compiled before a block it
inlines changed."""

from __future__ import annotations

import os
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


def _checkout(root: Path) -> Path:
    """A source checkout: ``root/pyproject.toml`` and the package under ``root/src``, with
    numba entries in two ``__pycache__`` directories."""
    pkg = _tree(root / "src")
    (root / "pyproject.toml").write_text("[project]\nname = 'isoflow'\n")
    for d in (pkg / "__pycache__", pkg / "_compiled" / "__pycache__"):
        d.mkdir()
        (d / "loop.nbi").write_text("index")
        (d / "loop.1.nbc").write_text("compiled")
        (d / "module.cpython-311.pyc").write_text("bytecode")
    return pkg


def _entries(pkg: Path) -> list[str]:
    return sorted(str(p.relative_to(pkg)) for p in pkg.rglob("__pycache__/*"))


def test_a_checkouts_stale_entries_go_and_fresh_ones_stay(tmp_path, monkeypatch) -> None:
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _checkout(tmp_path)
    bytecode = [e for e in _entries(pkg) if e.endswith(".pyc")]
    assert _numba_cache.refresh_checkout_cache(pkg)  # no stamp: entries of unknown sources
    assert _entries(pkg) == sorted([*bytecode, "__pycache__/numba-sources"])
    stamp = (pkg / "__pycache__" / "numba-sources").read_text().strip()
    assert stamp == _numba_cache.compiled_sources_digest(pkg)
    entry = pkg / "_compiled" / "__pycache__" / "loop.nbi"
    entry.write_text("index")
    assert not _numba_cache.refresh_checkout_cache(pkg) and entry.exists()  # unchanged
    (pkg / "sphere" / "figures.py").write_text("z = 4\n")
    assert not _numba_cache.refresh_checkout_cache(pkg) and entry.exists()  # not inlined
    (pkg / "_compiled" / "blocks.py").write_text("x = 2\n")
    assert _numba_cache.refresh_checkout_cache(pkg) and not entry.exists()  # inlined: gone


def test_an_installed_package_and_a_chosen_cache_are_left_alone(tmp_path, monkeypatch) -> None:
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    installed = _checkout(tmp_path / "a")
    site = tmp_path / "b" / "site-packages"
    site.mkdir(parents=True)
    installed = installed.rename(site / "isoflow")  # no src/ beside a pyproject.toml
    before = _entries(installed)
    assert not _numba_cache.refresh_checkout_cache(installed) and _entries(installed) == before
    pkg = _checkout(tmp_path / "c")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    before = _entries(pkg)
    assert not _numba_cache.refresh_checkout_cache(pkg) and _entries(pkg) == before


def test_importing_isoflow_from_a_checkout_stamps_its_cache() -> None:
    import subprocess
    import sys

    import isoflow

    pkg = Path(isoflow.__file__).resolve().parent
    if pkg.parent.name != "src" or not (pkg.parent.parent / "pyproject.toml").is_file():
        pytest.skip("isoflow is installed, not a source checkout")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    code = "import isoflow, sys; sys.stdout.write(str('numba' in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "False"  # the check does not load numba
    stamp = (pkg / "__pycache__" / "numba-sources").read_text().strip()
    assert stamp == _numba_cache.compiled_sources_digest()
