"""Shared test configuration: pin BLAS to one thread so timings stay sane on a busy 2-core box,
and keep numba's on-disk cache (``.numba_cache``) true to the sources.

numba's cache checks only the file that defines a function: a compiled loop that inlines a
block from another module (every stage inlines its layout's blocks) is loaded stale from the
cache after that block changes. So the cache is emptied whenever the compiled layer's sources
differ from those it was filled from (:func:`isoflow._numba_cache.refresh`), once per test
session (by the controlling process, before any worker starts).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings
from threadpoolctl import threadpool_limits

from isoflow._numba_cache import refresh

#: Whether the cache is this repository's own (a cache the user chose is left alone).
_OWN_CACHE = "NUMBA_CACHE_DIR" not in os.environ
os.environ.setdefault(
    "NUMBA_CACHE_DIR", os.path.join(os.path.dirname(__file__), "..", ".numba_cache")
)


def pytest_configure(config: pytest.Config) -> None:
    if not _OWN_CACHE or os.environ.get("PYTEST_XDIST_WORKER"):  # the controller did it
        return
    refresh(Path(os.environ["NUMBA_CACHE_DIR"]))


_limits = threadpool_limits(limits=1)

settings.register_profile(
    "ci", max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("ci")


from slow_cases import SLOW  # noqa: E402  (the tests' own directory)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    used: set[str] = set()
    for item in items:
        if item.nodeid.startswith(SLOW):
            item.add_marker(pytest.mark.slow)
            used.update(e for e in SLOW if item.nodeid.startswith(e))
    here = Path(__file__).resolve().parent
    collected = {item.nodeid.split("::")[0] for item in items}
    if collected >= {f"tests/{p.name}" for p in here.glob("test_*.py")}:  # the whole suite
        stale = [e for e in SLOW if e not in used]
        if stale:
            raise pytest.UsageError(
                f"tests/slow_cases.py names {len(stale)} test(s) that do not exist: {stale[:3]}"
            )


@pytest.fixture
def rng():
    import numpy as np

    return np.random.default_rng(12345)
