"""Benchmark 6: mean fixed-point iterations per step, the paper's guess against the default.

The paper's rigid body (so(10)) and spin chain (N = 100), ``h = 0.1``, at the default
(``rtol = 1e-14``) and the tightest (``1e-16``) tolerance: ``X_0 = W_k`` (the paper's initial
guess) against the default extrapolation of the last stage offsets; the final states must agree.
Target: at least 25% fewer iterations on the rigid body. Counts, not timings. Run alone:
``python benchmarks/bench_6_iterations_per_step.py``.
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any

import numpy as np

from suite import benchmark, record


@benchmark(6, "iterations per step: the paper's X_0 = W_k against the extrapolated guess")
def run(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso

    out = []
    n_steps = 1000 if not quick else 200
    rb, W0 = iso.models.rigid_body(10)
    sc, w0 = iso.models.heisenberg_chain(100)

    def per_step(problem: Any, method: Any, y0: Any) -> tuple[float, Any]:
        sol = iso.solve(problem, method, y0, dt=0.1, n_steps=n_steps, save_every=n_steps,
                        diagnostics=False, progress=False)  # fmt: skip
        return sol.stats.n_iterations / n_steps, sol.ys[-1]

    for label, prob, y0 in (("rigid body so(10)", rb, W0), ("spin chain N = 100", sc, w0)):
        plain = dataclasses.replace(prob, kernel=None)  # the NumPy path: the method's own code
        for rtol in (1e-14, 1e-16):
            fp = iso.FixedPoint(rtol=rtol)
            paper, y_paper = per_step(plain, iso.IsoMP(solver=fp, initial_guess="state"), y0)
            default, y_default = per_step(plain, iso.IsoMP(solver=fp), y0)
            extra: dict[str, Any] = {}
            if "spin" in label:
                extra["iterations_smm"] = per_step(plain, iso.SphericalMidpoint(solver=fp), y0)[0]
            diff = float(np.max(np.abs(y_paper - y_default)))
            saving = 1.0 - default / paper
            rigid = "rigid" in label
            out.append(
                record(
                    6, f"{label}, rtol = {rtol:.0e}: mean iterations per step",
                    iterations_paper_X0_eq_W=paper, iterations_default=default, **extra,
                    max_difference_of_answers=diff,
                    metric="iterations saved (1 - default / paper)", value=saving,
                    target=">= 0.25 (rigid body)" if rigid else "(none)",
                    met=(saving >= 0.25 and diff <= 1e-13) if rigid else None,
                )
            )  # fmt: skip
    return out


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "6", *sys.argv[1:]]))
