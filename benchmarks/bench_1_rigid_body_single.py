"""Benchmark 1: so(10) rigid body, one system, time per step.

IsoMP's compiled loop (``ElementwiseLinear`` kernel) against a straightforward NumPy
implementation of the paper's iteration (allocating, Python loops, ``X_0 = W_k``). Target:
speed-up >= 6. Run alone: ``python benchmarks/bench_1_rigid_body_single.py [--quick]``.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from suite import StepTimer, benchmark, paired_best_times, record


def paper_iteration_numpy(W: np.ndarray, c: np.ndarray, h: float, rtol: float) -> tuple:
    """Baseline: the paper's IsoMP step written plainly (allocating; ``X_0 = W``)."""
    X = W
    tol = rtol * np.sqrt(np.sum(W * W, axis=(-2, -1)))
    it = 0
    for it in range(1, 201):  # noqa: B007
        B = -c * X
        BX = B @ X
        G = W + 0.5 * h * (BX - X @ B) + 0.25 * h * h * (BX @ B)
        G = 0.5 * (G - np.swapaxes(G, -1, -2))
        r = np.sqrt(np.sum((G - X) ** 2, axis=(-2, -1)))
        if np.all(r <= tol):
            break
        X = G
    B = -c * X
    Wn = W + h * (B @ X - X @ B)
    return 0.5 * (Wn - np.swapaxes(Wn, -1, -2)), it


@benchmark(1, "so(10) rigid body, one system: time per step against the paper's NumPy loop")
def run(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso

    prob, W0 = iso.models.rigid_body(10)
    c = prob.parameters["inverse_inertia"]
    h = 0.1
    n_fast = 2000 if not quick else 500
    n_base = 200 if not quick else 50
    fast = StepTimer(prob, iso.IsoMP(), W0, h)
    its: dict[str, int] = {}

    def compiled() -> None:
        its["fast"] = fast.advance(n_fast)

    def base() -> None:
        W, tot = W0, 0
        for _ in range(n_base):
            W, it = paper_iteration_numpy(W, c, h, 1e-14)
            tot += it
        its["base"] = tot

    t_fast, t_base = paired_best_times(compiled, base)
    t_fast /= n_fast
    t_base /= n_base
    it_fast, it_base = its["fast"] / n_fast, its["base"] / n_base
    return [
        record(
            1, "so(10) rigid body, one system: time per step",
            fast_us_per_step=t_fast * 1e6, baseline_us_per_step=t_base * 1e6,
            fast_us_per_iteration=t_fast / it_fast * 1e6,
            baseline_us_per_iteration=t_base / it_base * 1e6,
            iterations_per_step={"fast": it_fast, "baseline": it_base}, runner=fast.label,
            metric="speed-up (baseline / fast)", value=t_base / t_fast, target=">= 6",
            met=t_base / t_fast >= 6.0,
        )
    ]  # fmt: skip


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "1", *sys.argv[1:]]))
