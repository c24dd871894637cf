"""Benchmark 3's measurement in a form that older commits of isoflow can run too.

Benchmark 3 (:mod:`bench_3_large_dense`) imports the suite's harness, which follows the
compiled runner's current call; comparing it with the code of an older commit then mixes two
harnesses. This script times the same thing with the runner's call of either era: the dense
so(n) or u(n) run of benchmark 3 (IsoMP, ``h = 0.1``, two BLAS threads, one numba thread),
``reps`` calls of a few steps each, alternated with two bare ``n x n`` products, and prints one
JSON line: the best time per iteration and per step, the iterations per step and the ratios to
two products. ``variant`` ``cubic-plain`` runs IsoMP with the cubic extrapolated start and
no compensated update (the per-step work of the method before the quartic start and the
compensation).

Side by side with an older commit (a ``git worktree`` at ``OLD``, its own numba cache),
alternating processes::

    for i in 1 2 3 4 5 6; do for case in "so 256" "so 512" "u 256" "u 512"; do
      PYTHONPATH=OLD/src NUMBA_CACHE_DIR=/tmp/nc python benchmarks/side_by_side_dense.py $case 10
      python benchmarks/side_by_side_dense.py $case 10
    done; done

and compare the medians of the ratios.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import numba
import numpy as np


@numba.njit(cache=True)
def _two_products(B, X, P, T):  # type: ignore[no-untyped-def]
    np.dot(B, X, P)
    np.dot(P, B, T)


def _advance_call(runner: Any, steps: int) -> tuple[Any, ...]:
    """The runner's ``advance`` arguments after ``steps``, saving only the last state, in the
    call of the installed isoflow (a save grid since the compiled layer was rewritten, two
    integers before)."""
    try:
        from isoflow._save_grid import SaveGrid
    except ImportError:
        return (steps, 2**62, runner.k + steps)
    return (steps, SaveGrid(2**62, runner.k + steps))


def measure(space: str, n: int, reps: int, variant: str = "default") -> dict[str, Any]:
    """Best times per iteration and per step of benchmark 3's run against two products."""
    import isoflow as iso
    from isoflow._compiled import compiled_runner
    from isoflow.threads import thread_limits

    with thread_limits(blas=2, numba=1):
        alg = getattr(iso.algebras, space)(n)
        d = np.linspace(0.5, 1.5, n)
        C = -(d[:, None] + d[None, :]) / 2
        prob = iso.IsospectralProblem(algebra=alg, kernel=iso.ElementwiseLinear(C))
        W0 = np.asarray(alg.random(seed=1, scale=1.0 / n), dtype=alg.dtype)
        if variant == "default":
            method = iso.IsoMP()
        elif variant == "cubic-plain":
            method = iso.IsoMP(extrapolation_order=3, compensated=False)
        else:
            raise SystemExit(f"unknown variant {variant!r} (default, cubic-plain)")
        runner = compiled_runner(prob, method, W0, 0.1)
        steps = {256: 8, 512: 4}.get(n, 2)

        def advance(k: int) -> int:
            before = runner.iterations_total
            out = np.empty((1, runner.M, *runner.core), dtype=alg.dtype)
            runner.advance(*_advance_call(runner, k), out)
            return int(runner.iterations_total - before)

        A = np.ascontiguousarray(alg.random(seed=2))
        Bm = np.ascontiguousarray(alg.random(seed=3))
        P = np.empty_like(A)
        T = np.empty_like(A)
        advance(3)  # compiled, and the extrapolation running
        _two_products(Bm, A, P, T)
        calls, iterations, two = [], [], []
        for _ in range(reps):
            t = time.perf_counter()
            iterations.append(advance(steps))
            calls.append(time.perf_counter() - t)
            t = time.perf_counter()
            _two_products(Bm, A, P, T)
            two.append(time.perf_counter() - t)
    per_iteration = min(t / i for t, i in zip(calls, iterations, strict=True))
    per_step = min(calls) / steps
    t_two = min(two)
    return dict(
        variant=variant, space=space, n=n, ms_per_iteration=per_iteration * 1e3,
        ms_per_step=per_step * 1e3, iterations_per_step=sum(iterations) / (reps * steps),
        ms_two_products=t_two * 1e3, iteration_over_two_products=per_iteration / t_two,
        step_over_two_products=per_step / t_two,
    )  # fmt: skip


if __name__ == "__main__":
    if len(sys.argv) not in (4, 5):
        raise SystemExit(__doc__)
    print(json.dumps(measure(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), *sys.argv[4:])))
