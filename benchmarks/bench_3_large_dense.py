"""Benchmark 3: dense so(n), u(n), n = 256, 512, 1024: time per fixed-point iteration.

IsoMP's compiled loop for large dense states (BLAS products) against the bare time of two
``n x n`` matrix products into preallocated outputs, through the same BLAS library as the
compiled loop (:func:`suite.two_products`), BLAS on every core.
Target: ratio <= 1.15. Run alone: ``python benchmarks/bench_3_large_dense.py``.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np

from suite import (
    StepTimer,
    benchmark,
    combining_pass_seconds,
    paired_best_times,
    record,
    two_products,
)


@benchmark(3, "dense so(n), u(n), n = 256..1024: time per iteration against two products")
def run(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso
    from isoflow.threads import available_cores, thread_limits

    sizes = (256, 512, 1024) if not quick else (256,)
    out = []
    cores = available_cores()
    with thread_limits(blas=cores, numba=1):
        for space in ("so", "u"):
            for n in sizes:
                alg = getattr(iso.algebras, space)(n)
                d = np.linspace(0.5, 1.5, n)
                C = -(d[:, None] + d[None, :]) / 2
                prob = iso.IsospectralProblem(algebra=alg, kernel=iso.ElementwiseLinear(C))
                W0 = alg.random(seed=1, scale=1.0 / n)
                steps = {256: 8, 512: 4}.get(n, 2)  # one advance call, amortized
                fast = StepTimer(prob, iso.IsoMP(), W0, 0.1)
                its: dict[str, int] = {}
                per_it: list[float] = []  # each call by its own iteration count

                def compiled(
                    fast: StepTimer = fast, steps: int = steps, its: dict = its,
                    per_it: list = per_it,
                ) -> None:  # fmt: skip
                    t = time.perf_counter()
                    its["n"] = fast.advance(steps)
                    per_it.append((time.perf_counter() - t) / max(its["n"], 1))

                A = np.ascontiguousarray(alg.random(seed=2))
                Bm = np.ascontiguousarray(alg.random(seed=3))
                P = np.empty_like(A)
                T = np.empty_like(A)

                def two(A: Any = A, Bm: Any = Bm, P: Any = P, T: Any = T) -> None:
                    two_products(Bm, A, P, T)

                _, t_two = paired_best_times(compiled, two, repeats=3)
                t_it = min(per_it)
                ratio = t_it / t_two
                t_pass = combining_pass_seconds(alg, A, Bm)
                why = {} if ratio <= 1.15 else {
                    "why": f"the combining pass (bracket, iterate, residual, mirror into V) "
                           f"takes {t_pass / t_two:.2f} of two products on one thread; B, the "
                           "driver's per-iteration work and BLAS's lower efficiency on the "
                           "smaller blocks of the triangular product make up the rest"
                }  # fmt: skip
                out.append(
                    record(
                        3, f"dense {space}({n}): time per iteration / two products",
                        ms_per_iteration=t_it * 1e3, ms_two_products=t_two * 1e3,
                        iterations=its["n"], threads={"blas": cores, "numba": 1},
                        runner=fast.label, combining_pass_over_two_products=t_pass / t_two,
                        metric="ratio (iteration / two products)", value=ratio,
                        target="<= 1.15", met=ratio <= 1.15, **why,
                    )
                )  # fmt: skip
    return out


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "3", *sys.argv[1:]]))
