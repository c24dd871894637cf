"""Benchmark 17: compensated summation in IsoMP's update, on against off, time per step.

``iso.IsoMP(compensated=True)`` (the default) carries the rounding error of
``W_{k+1} = W_k + h C`` to the next step (an exact TwoSum per entry and a compensation buffer
of the state's size, :mod:`isoflow.methods.isomp`); ``compensated=False`` is the plain update.
Both runs take the same steps (the same solves to rounding), timed alternately in the compiled
loop: the so(10) rigid body (the written-out dense layout, one system), Euler on the sphere
at ``N = 256`` (the BLAS layout with its fused finish), an ensemble of 10^4 so(10) rigid bodies
(SIMD lanes) and a spin chain of 10^5 spins (the fused sweeps). Target: ratio <= 1.05 (the
issue's bound above which the compensation would have to be opt-in). Run alone:
``python benchmarks/bench_17_compensated.py [--quick]``.

**How far and why** (idle machine, ``python benchmarks/run_all.py --only 4,5,17``, after the
compiled loop stopped copying a single system's state and compensation every step): so(10)
1.02, the ensemble 1.04-1.09, the chain 1.03-1.16 over four runs (1.12-1.22 before). The
chain and the ensemble are bound by memory traffic, not by flops: a step there is a dozen
sweeps of a few arrays, and the compensated update reads and writes the compensation buffer
once more (48 bytes a spin against about 70 an iteration), which no arrangement of the
arithmetic removes. The sphere's ratio at ``N = 256`` (1.03 committed) is within its
run-to-run noise (0.78-1.03). The plain update stays one keyword away
(``iso.IsoMP(compensated=False)``); the solvers guide says when a run may take it.
Since IsoMP's start takes the offsets from ``G(X)`` (two iterations a step on the so(10) rigid
body instead of three) the plain step is cheaper and the same buffer weighs more: two runs on
the idle machine (2026-11-26, 23:44 and 23:51 UTC) read 0.98 / 1.01 (so(10)), 1.03 / 0.98
(sphere), 1.09 / 1.16 (ensemble), 1.08 / 1.09 (chain). The ensemble's lanes then tested each
entry of the update for finiteness with a branch, which kept the compensated loop from
vectorizing; with a branch-free test (``c47802c``) the row read 1.04 (00:07-00:08 UTC), the chain's
1.16.
"""

from __future__ import annotations

import sys
from typing import Any

from suite import StepTimer, benchmark, paired_best_times, record

#: The issue's bound on the cost of the compensation per step.
TARGET = 1.05


def _ratio(prob: Any, W0: Any, h: float, n: int) -> tuple[float, float, str]:
    """``(t_on, t_off, runner)``: best seconds per step with and without compensation."""
    import isoflow as iso

    on = StepTimer(prob, iso.IsoMP(compensated=True), W0, h)
    off = StepTimer(prob, iso.IsoMP(compensated=False), W0, h)
    t_on, t_off = paired_best_times(lambda: on.advance(n), lambda: off.advance(n))
    return t_on / n, t_off / n, on.label


def _ensemble(M: int) -> tuple[Any, Any]:
    """The so(10) rigid body and ``M`` random members of benchmark 2's size."""
    import numpy as np

    import isoflow as iso

    prob, W0 = iso.models.rigid_body(10)
    alg = prob.algebra
    W = alg.random(0, batch=(M,)) * float(alg.norm(W0) / np.sqrt(alg.dim))
    return prob, W


@benchmark(17, "compensated summation on / off, per step: so(10), the sphere, an ensemble, a chain")
def run(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso

    cases = [
        ("so(10) rigid body, one system", *iso.models.rigid_body(10), 0.1, 500 if quick else 4000),
        (
            "Euler on the sphere, N = 256",
            *iso.models.euler_sphere(N=128 if quick else 256, seed=1),
            0.05,
            2 if quick else 5,
        ),
        (
            "ensemble of 10^4 so(10) rigid bodies",
            *_ensemble(2_000 if quick else 10_000),
            0.1,
            20 if quick else 50,
        ),
        (
            "spin chain, N = 10^5",
            *iso.models.heisenberg_chain(10_000 if quick else 100_000, initial="random", seed=0),
            0.1,
            20 if quick else 50,
        ),
    ]
    out = []
    for what, prob, W0, h, n in cases:
        t_on, t_off, label = _ratio(prob, W0, h, n)
        ratio = t_on / t_off
        out.append(
            record(
                17, f"{what}: compensated / plain update, per step",
                compensated_us_per_step=t_on * 1e6, plain_us_per_step=t_off * 1e6,
                runner=label, metric="time ratio (compensated / plain)", value=ratio,
                target=f"<= {TARGET}", met=ratio <= TARGET,
            )
        )  # fmt: skip
    return out


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "17", *sys.argv[1:]]))
