r"""Thread policy: BLAS threads times numba threads never exceed the cores.

isoflow runs two kinds of parallel code: BLAS (NumPy's matrix products, large dense states)
and its own compiled numba loops (ensembles, spin chains). Each defaults to one thread per
core, so nesting them (a numba thread calling a multithreaded BLAS) or running both pools at
once oversubscribes the machine and is slower than either alone. The policy:

* compiled fast paths (numba ``prange`` over ensemble members or particles) do not call BLAS;
  they run with ``numba_threads`` threads;
* large dense states use BLAS and no numba threads;
* :func:`thread_limits` caps both pools so that ``blas * numba <= cores`` and is what the
  benchmarks use; the test suite pins BLAS to one thread (``tests/conftest.py``) so that
  timings stay sane on a busy CI machine.

Examples
--------
>>> import isoflow as iso
>>> with iso.threads.thread_limits(blas=1):     # numba gets all cores, BLAS one
...     pass
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["available_cores", "current_threads", "thread_limits"]


def available_cores() -> int:
    """Cores this process may run on (``os.sched_getaffinity`` where available)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # pragma: no cover - not on Linux
        return max(os.cpu_count() or 1, 1)


def current_threads() -> dict[str, int]:
    """Current thread counts: ``{"cores", "numba", "blas"}`` (``blas`` the largest pool)."""
    import numba
    from threadpoolctl import threadpool_info

    blas = [p["num_threads"] for p in threadpool_info() if p.get("user_api") == "blas"]
    return {
        "cores": available_cores(),
        "numba": int(numba.get_num_threads()),
        "blas": max(blas) if blas else 1,
    }


@contextmanager
def thread_limits(blas: int | None = None, numba: int | None = None) -> Iterator[dict[str, int]]:
    """Limit BLAS and numba threads inside a ``with`` block, so that ``blas * numba <= cores``.

    Parameters
    ----------
    blas, numba : int or None
        Requested threads. ``None`` for one of them gives it what the other leaves
        (``cores // other``); both ``None``: numba gets all cores and BLAS one (the compiled
        fast paths never call BLAS, the large-dense path never uses numba threads, so
        callers running large dense problems should pass ``blas=cores``).

    Yields
    ------
    dict
        The limits in force, ``{"cores", "numba", "blas"}``.

    Raises
    ------
    ValueError
        A request below 1, or a combination exceeding the cores.
    """
    import numba as nb
    from threadpoolctl import threadpool_limits

    cores = available_cores()
    max_numba = int(nb.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
    if blas is None and numba is None:
        blas = 1
    if blas is None:
        assert numba is not None
        blas = max(cores // numba, 1)
    if numba is None:
        numba = max(cores // blas, 1)
    if blas < 1 or numba < 1:
        raise ValueError(f"thread counts must be >= 1, got blas={blas}, numba={numba}")
    if blas * numba > cores:
        raise ValueError(
            f"blas * numba threads = {blas * numba} exceeds the {cores} available cores"
        )
    numba = min(numba, max_numba)
    old = nb.get_num_threads()
    nb.set_num_threads(numba)
    try:
        with threadpool_limits(limits=blas, user_api="blas"):
            yield {"cores": cores, "numba": numba, "blas": blas}
    finally:
        nb.set_num_threads(old)
