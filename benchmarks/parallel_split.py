"""How numba splits a parallel loop here, against a hand-out of units as threads come free.

Not part of ``run_all.py``: why the parallel driver hands its units out from an atomic counter
(:func:`isoflow._compiled.driver.drive_parallel`, :mod:`isoflow._compiled.atomics`) instead
of relying on ``numba.parallel_chunksize``.

1. *The split*: a ``prange`` of 64 iterations whose first half costs four times the second,
   on two threads, with ``numba.parallel_chunksize`` 0, 1 and 4: how many iterations each
   thread ran, and the time. With numba's ``omp`` and ``workqueue`` layers the split is 32/32
   whatever the chunk size (static).
2. *Static against a hand-out*: 2000 equal units on two threads, split by ``prange`` or taken
   one at a time from an atomic counter (each thread loops until the counter passes the end),
   idle and with a busy process on the other core (started here).

Run: ``python benchmarks/parallel_split.py``.
"""

from __future__ import annotations

import multiprocessing
import time
from typing import Any

import numba
import numpy as np
from numba.core import cgutils, types
from numba.extending import intrinsic


@intrinsic
def _fetch_add(typingctx: Any, counter: Any, value: Any) -> Any:
    """``counter[0] += value`` atomically; returns the value before (as the library's
    :func:`isoflow._compiled.atomics.take`, kept apart so that this script runs on any
    commit)."""

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = cgutils.get_item_pointer(
            context, builder, signature.args[0], ary, [context.get_constant(types.intp, 0)]
        )
        return builder.atomic_rmw("add", ptr, args[1], "monotonic")

    return types.int64(counter, types.int64), codegen


@numba.njit(cache=True)
def _work(x: Any, reps: int) -> float:
    s = 0.0
    for r in range(reps):
        for i in range(x.shape[0]):
            s += np.sin(x[i] + r)
    return s


@numba.njit(parallel=True, cache=True)
def _uneven(X: Any, who: Any, reps: int) -> None:
    n = X.shape[0]
    for u in numba.prange(n):
        who[u] = numba.get_thread_id()
        _work(X[u], 4 * reps if u < n // 2 else reps)


@numba.njit(parallel=True, cache=True)
def _static(X: Any, out: Any, reps: int) -> None:
    for u in numba.prange(X.shape[0]):
        out[u] = _work(X[u], reps)


@numba.njit(parallel=True, cache=True)
def _handout(X: Any, out: Any, reps: int, counter: Any, workers: int) -> None:
    for _ in numba.prange(workers):
        while True:
            u = _fetch_add(counter, 1)
            if u >= X.shape[0]:
                break
            out[u] = _work(X[u], reps)


def _busy() -> None:
    while True:
        pass


def _best(fn: Any, repeats: int = 7) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    numba.set_num_threads(2)
    X = np.random.default_rng(0).random((64, 100))
    who = np.zeros(64, np.int64)
    _uneven(X, who, 50)  # compiles, and starts the threading layer
    print(f"threading layer: {numba.threading_layer()}")
    for chunk in (0, 1, 4):
        with numba.parallel_chunksize(chunk):
            t = _best(lambda: _uneven(X, who, 2000), 3)
        counts = np.bincount(who, minlength=2)
        print(
            f"uneven loop, chunk size {chunk}: iterations per thread {counts.tolist()}, {t:.3f} s"
        )

    U = np.random.default_rng(1).random((2000, 100))
    a, b = np.zeros(2000), np.zeros(2000)
    counter = np.zeros(1, np.int64)

    def handout() -> None:
        counter[0] = 0
        _handout(U, b, 200, counter, 2)

    _static(U, a, 200)
    handout()
    assert np.array_equal(a, b)
    for label in ("idle", "other core busy"):
        proc = None
        if label != "idle":
            proc = multiprocessing.Process(target=_busy, daemon=True)
            proc.start()
            time.sleep(0.5)
        try:
            rows = []
            for _ in range(3):  # alternately
                rows.append((_best(lambda: _static(U, a, 200)), _best(handout)))
            ts, th = min(r[0] for r in rows), min(r[1] for r in rows)
            print(f"{label}: static {ts:.3f} s, hand-out {th:.3f} s, ratio {th / ts:.2f}")
        finally:
            if proc is not None:
                proc.terminate()
                proc.join()


if __name__ == "__main__":
    main()
