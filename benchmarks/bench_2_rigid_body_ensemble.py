"""Benchmark 2: ensemble of 10^4 so(10) rigid bodies, time per system-step.

IsoMP's compiled loop on the ensemble (blocked, members over numba threads) against the same
iteration on the stacked ensemble with batched ``numpy.matmul`` (benchmark 1's baseline).
Target: speed-up >= 2. Run alone: ``python benchmarks/bench_2_rigid_body_ensemble.py``.
"""

from __future__ import annotations

import sys
from typing import Any

from bench_1_rigid_body_single import paper_iteration_numpy
from suite import StepTimer, benchmark, paired_best_times, record


@benchmark(2, "ensemble of 10^4 so(10) rigid bodies: time per system-step against stacked NumPy")
def run(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso
    from isoflow.threads import available_cores, thread_limits

    M = 10_000 if not quick else 2_000
    prob, _ = iso.models.rigid_body(10)
    c = prob.parameters["inverse_inertia"]
    W = iso.algebras.so(10).random(seed=0, batch=(M,), scale=0.1)
    h = 0.1
    n_fast, n_base = (20, 4) if not quick else (5, 2)
    cores = available_cores()
    its: dict[str, int] = {}
    with thread_limits(blas=1, numba=cores):
        fast = StepTimer(prob, iso.IsoMP(), W, h)

        def compiled() -> None:
            its["fast"] = fast.advance(n_fast)

        def base() -> None:
            Y = W
            for _ in range(n_base):
                Y, _ = paper_iteration_numpy(Y, c, h, 1e-14)

        t_fast, t_base = paired_best_times(compiled, base, repeats=3)
    t_fast /= n_fast * M
    t_base /= n_base * M
    it_fast = its["fast"] / (n_fast * M)
    return [
        record(
            2, f"ensemble of {M} so(10) rigid bodies: time per system-step",
            fast_us_per_system_step=t_fast * 1e6, baseline_us_per_system_step=t_base * 1e6,
            fast_us_per_system_iteration=t_fast / it_fast * 1e6,
            threads={"numba": cores, "blas": 1}, runner=fast.label,
            metric="speed-up (stacked numpy / fast)", value=t_base / t_fast, target=">= 2",
            met=t_base / t_fast >= 2.0,
        )
    ]  # fmt: skip


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "2", *sys.argv[1:]]))
