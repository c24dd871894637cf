"""Benchmark 7: point vortices, one system: IsoMP per step, compiled loop against NumPy path.

The paper's hyperbolic configuration 1 (``h = 0.01``) and ``N = 3`` and ``N = 100`` vortices on
the sphere (``h = 0.01``): the compiled loop (``PairwiseVortex`` kernel) against the method's
own NumPy steps on the same problem without its kernel. No target; the speed-up is reported.
Run alone: ``python benchmarks/bench_7_vortices.py``.
"""

from __future__ import annotations

import sys
import time
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
            # the same steps for both paths; for tiny systems enough steps per call that the
            # call itself (about 0.1 ms: numba unboxes the driver's function arguments) is
            # under 5 % of it
            n = 20_000 if N <= 10 else 100
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
            tiny = {}
            if N <= 10:  # how much of a tiny system's step is the generic driver
                t_stage = _stage_only_seconds(fast.runner, round(it_fast), h, n)
                t_call = _call_seconds(fast)
                tiny = {"stage_only_us_per_step": t_stage * 1e6,
                        "call_overhead_us": t_call * 1e6}  # fmt: skip
                if t_stage < t_fast:
                    tiny["driver_us_per_step"] = (t_fast - t_stage) * 1e6
                else:  # the loop calls the stage through the same function pointers
                    tiny["why"] = ("the stage alone, called through function pointers from a "
                                   "loop of its own, took as long as the whole step: the "
                                   "driver's share is below what this measures")  # fmt: skip
            out.append(
                record(
                    7, f"{label}: IsoMP time per step, compiled / NumPy path",
                    N=N, h=h, steps=n, fast_us_per_step=t_fast * 1e6,
                    numpy_us_per_step=t_base * 1e6,
                    fast_us_per_iteration=t_fast / it_fast * 1e6,
                    numpy_us_per_iteration=t_base / it_base * 1e6,
                    iterations_per_step={"fast": it_fast, "numpy": it_base},
                    **tiny,
                    threads={"blas": 1, "numba": 1}, runner=fast.label,
                    metric="speed-up (NumPy path / compiled)", value=t_base / t_fast,
                    target="(none)", met=None,
                )
            )  # fmt: skip
    return out


def _call_seconds(timer: Any) -> float:
    """Best time of a call that takes one step: the fixed cost of a call of the compiled loop."""
    best = np.inf
    for _ in range(20):
        t = time.perf_counter()
        timer.advance(1)
        best = min(best, time.perf_counter() - t)
    return float(best)


def _stage_loop_py(iterate, finish, f, fargs, lay, mp, W, X, G, aux, work, E, Wn, h, its, n):  # type: ignore[no-untyped-def]
    """``n`` steps of ``its`` iterations of the stage from ``X = W``, then the new state
    (compensated by ``E`` unless it is empty, as the driver does)."""
    sd = np.empty((1, 0))
    rr = np.zeros(1)
    fin = np.ones(1, dtype=np.bool_)
    for _ in range(n):
        X[:] = W
        for _ in range(its):
            iterate(f, fargs, lay, mp, sd, W, X, G, aux, work, h, rr)
            X, G = G, X
        finish(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin)
        W[:] = Wn


def _stage_loop(runner: Any, args: tuple[Any, ...]) -> Any:
    """:func:`_stage_loop_py` compiled for the exact types of ``runner``'s stage and field,
    passed as first-class function types (as the driver is: a dispatcher argument would be
    typed from whichever of its overloads another benchmark compiled first)."""
    import numba
    from numba import types

    from isoflow._compiled.signatures import DriverTypes

    dt = DriverTypes(runner.f, runner.fargs, runner.layout.record, runner.mp, runner.W.dtype,
                     len(runner.core))  # fmt: skip
    dt.compile_stage(runner.begin, runner.impl.iterate, runner.impl.finish, runner.mix,
                     runner.start)  # fmt: skip
    sig = types.none(dt.iterate, dt.finish, dt.f, dt.fargs,
                     *(numba.typeof(a) for a in args[4:]), types.int64)  # fmt: skip
    return numba.njit(sig)(_stage_loop_py)


def _stage_only_seconds(runner: Any, its: int, h: float, n: int) -> float:
    """Per step, the work no driver can avoid: the layout's own stage functions (``its``
    iterations, then the new state) called directly in a compiled loop, from ``X = W``.

    The difference to the compiled step is the driver's share of a step: the extrapolated
    guess, the stopping rule, the ring of offsets, saving, and the calls of the stage and the
    kernel through numba's first-class function types (what lets one compiled driver serve
    every kernel without compiling per kernel).
    """
    impl = runner.impl
    W = runner.W[0].copy()
    X, G, aux, Wn = (np.empty_like(W) for _ in range(4))
    work = np.empty((max(impl.nwork, 1), W.shape[0]), dtype=W.dtype)
    compensated = runner.stage.compensated(runner.method)  # IsoMP's default: compensated
    E = np.zeros_like(W) if compensated else np.empty(0, dtype=W.dtype)
    args = (impl.iterate, impl.finish, runner.f, runner.fargs, runner.layout.record, runner.mp,
            W, X, G, aux, work, E, Wn, h, its)  # fmt: skip
    loop = _stage_loop(runner, args)
    loop(*args, 1)
    best = np.inf
    for _ in range(5):
        W[:] = runner.W[0]
        t = time.perf_counter()
        loop(*args, n)
        best = min(best, time.perf_counter() - t)
    return float(best / n)


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "7", *sys.argv[1:]]))
