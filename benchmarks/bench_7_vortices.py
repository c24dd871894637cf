"""Benchmark 7: point vortices, one system: IsoMP per step, compiled loop against NumPy path.

The paper's hyperbolic configuration 1 (``h = 0.01``) and ``N = 3`` and ``N = 100`` vortices on
the sphere (``h = 0.01``): the compiled loop (``PairwiseVortex`` kernel) against the method's
own NumPy steps on the same problem without its kernel. No target; the speed-up is reported.
Run alone: ``python benchmarks/bench_7_vortices.py``.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from suite import StepTimer, benchmark, paired_best_times, record


def vortex_cases() -> list[tuple[str, Any, np.ndarray]]:
    """The paper's hyperbolic configuration 1, and 3 and 100 vortices on the sphere.

    The sphere positions are Fibonacci points (well separated, so ``h = 0.01`` is a moderate
    step), the circulations random in ``[0.5, 1.5]`` (seeded; one sign, so that no dipole
    pairs form and run off).
    """
    import isoflow as iso

    cases: list[tuple[str, Any, np.ndarray]] = []
    prob, w0 = iso.models.hyperbolic_vortices(config=1)
    cases.append(("hyperbolic vortices, paper config 1 (N = 3)", prob, w0))
    rng = np.random.default_rng(0)
    for N in (3, 100):
        k = np.arange(N) + 0.5
        z = 1.0 - 2.0 * k / N
        phi = np.pi * (1.0 + np.sqrt(5.0)) * k
        r = np.sqrt(1.0 - z * z)
        x = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)
        circ = rng.uniform(0.5, 1.5, N)
        prob, x0 = iso.models.sphere_vortices(positions=x, circulations=circ)
        cases.append((f"sphere vortices, N = {N}", prob, x0))
    return cases


@benchmark(7, "point vortices: IsoMP time per step, compiled loop against the NumPy path")
def run(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso
    from isoflow.threads import thread_limits

    h = 0.01
    out = []
    with thread_limits(blas=1, numba=1):  # one system: the compiled loop is serial
        for label, prob, y0 in vortex_cases():
            N = y0.shape[-2]
            fast = StepTimer(prob, iso.IsoMP(), y0, h)
            slow = StepTimer(prob, iso.IsoMP(), y0, h, compiled=False)
            fast.advance(5)  # running warm starts for both
            slow.advance(5)
            n = 2000 if N <= 10 else 100  # the same steps for both paths
            if quick:
                n //= 4
            its: dict[str, int] = {}

            def compiled(t: StepTimer = fast, n: int = n, its: dict = its) -> None:
                its["fast"] = t.advance(n)

            def numpy_path(t: StepTimer = slow, n: int = n, its: dict = its) -> None:
                its["base"] = t.advance(n)

            t_fast, t_base = paired_best_times(compiled, numpy_path, repeats=5 if not quick else 3)
            t_fast /= n
            t_base /= n
            it_fast, it_base = its["fast"] / n, its["base"] / n
            out.append(
                record(
                    7, f"{label}: IsoMP time per step, compiled / NumPy path",
                    N=N, h=h, steps=n, fast_us_per_step=t_fast * 1e6,
                    numpy_us_per_step=t_base * 1e6,
                    fast_us_per_iteration=t_fast / it_fast * 1e6,
                    numpy_us_per_iteration=t_base / it_base * 1e6,
                    iterations_per_step={"fast": it_fast, "numpy": it_base},
                    threads={"blas": 1, "numba": 1}, runner=fast.label,
                    metric="speed-up (NumPy path / compiled)", value=t_base / t_fast,
                    target="(none)", met=None,
                )
            )  # fmt: skip
    return out


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "7", *sys.argv[1:]]))
