"""Benchmark 4: Heisenberg spin chain, N = 100 .. 10^7: time per iteration / memory bound.

The bound is the memory traffic of one iteration, ``72 N`` bytes (read ``x`` and ``w``, write
``G``), over the triad bandwidth ``a = b + s c`` measured in the same run (the best of one and
of all threads). Target: ratio <= 2 for ``N >= 10^6``. The time per iteration is that of whole
steps over their iterations, so it carries a share of the step's update: IsoMP's default
compensated update (a TwoSum per entry; the compensation read, written and kept for a failed
step's undo; a finiteness pass) moves about 190 bytes a spin against the plain update's 72,
which made a step's time per iteration 11-25 % longer at N = 1e4 and 1e6 on one thread
(paired runs of both, 2026-11-26); ``ratio_uncompensated`` is the same measurement with
``compensated=False``.

The sweeps write states without reassociation (2026-11-26: a loop compiled in a run's process
and one loaded from numba's cache must agree to the last bit, see ``docs/architecture.rst``);
the squared changes go through a 16 KiB buffer and are summed apart. Cost, alternating
processes against the code before: the interior sweep alone 8.2-8.6 -> 9.8-9.9 ns a spin at
N = 100, 1.5-1.6 -> 1.7-1.8 at 1e4 and 1e5, within the noise at 1e6; whole IsoMP steps at
N = 1e5 within the noise (medians of five runs, 37.0 and 35.6 ns a spin-step). This
benchmark's ratios in alternating runs (N = 1e2, 1e4, 1e6, 1e7), before: 2.10 1.01 1.69 2.27,
2.01 0.79 1.18 1.70, 2.35 0.94 1.69 1.92; after: 2.34 0.96 1.48 2.08, 3.41 1.11 1.71 2.09,
3.90 1.21 2.10 2.48 (2 cores shared with other work: the spread of one code is as wide as the
difference). Run alone: ``python benchmarks/bench_4_spin_chain_bandwidth.py``.

Since each spin's stage is solved in closed form (2026-11-27, ``docs/user_guide/solvers.rst``)
a step takes fewer iterations (10.3 against 14.35 at N = 1e6), each of which carries a larger
share of the step's own work (the start, the compensated finish: about 2.35 ms at N = 1e5 on
one thread, fitted from runs at three tolerances, in the code before and after alike; the
iteration itself 320-344 against 317-322 us). Idle machine, the same hour, this host's triad
bandwidth 27 GB/s (37 in earlier runs): 1.62 and 2.41 at N = 1e6, 1e7, the commit before 1.33
and 2.10, while a step took 0.86-0.88 of its time (64.5 against 75.0 ns a spin-step at 1e6,
126-128 against 141-145 at 1e7, alternating processes).
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from suite import StepTimer, benchmark, best_time, record


def _triads() -> tuple[Any, Any]:
    import numba

    def triad(a, b, c, s):  # type: ignore[no-untyped-def]
        for i in range(a.size):
            a[i] = b[i] + s * c[i]

    def triad_par(a, b, c, s):  # type: ignore[no-untyped-def]
        for i in numba.prange(a.size):
            a[i] = b[i] + s * c[i]

    return numba.njit(cache=False)(triad), numba.njit(cache=False, parallel=True)(triad_par)


def triad_bandwidth(n: int = 20_000_000, parallel: bool = False) -> float:
    """Bytes per second of ``a = b + s c`` (numba, ``n`` doubles, 24 bytes per element)."""
    ser, par = _triads()
    f = par if parallel else ser
    a = np.zeros(n)
    b = np.random.default_rng(0).random(n)
    c = np.random.default_rng(1).random(n)
    t = best_time(lambda: f(a, b, c, 3.0), repeats=7)
    return 24.0 * n / t


def random_chain(N: int, seed: int = 0) -> tuple[Any, np.ndarray]:
    """The Heisenberg chain with ``N`` random unit spins (its compiled kernel attached)."""
    import isoflow as iso

    prob, w0 = iso.models.heisenberg_chain(N, initial="random", seed=seed)
    if prob.kernel is None:  # pragma: no cover - the model attaches it
        raise RuntimeError("the spin chain has no compiled kernel")
    return prob, w0


@benchmark(4, "spin chain, N = 100..1e7: time per iteration against the memory-traffic bound")
def run(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso
    from isoflow.threads import available_cores, thread_limits

    Ns = (100, 10_000, 1_000_000, 10_000_000) if not quick else (100, 10_000, 1_000_000)
    out = []
    cores = available_cores()
    bw = {1: triad_bandwidth(parallel=False)}
    if cores > 1:
        with thread_limits(blas=1, numba=cores):
            bw[cores] = triad_bandwidth(parallel=True)
    for N in Ns:
        prob, w0 = random_chain(N)
        steps = max(20, min(200, int(3e8 // (N * 15))))
        best: dict[str, Any] | None = None
        for threads in sorted(bw):
            with thread_limits(blas=1, numba=threads):
                timer = StepTimer(prob, iso.IsoMP(), w0, 0.1)
                timer.advance(3)  # a running warm start
                its: dict[str, int] = {}

                def compiled(timer: StepTimer = timer, steps: int = steps, its: dict = its) -> None:
                    its["n"] = timer.advance(steps)

                t = best_time(compiled, repeats=3 if N < 10**7 else 1)
            per_it = t / its["n"]
            bound = 72.0 * N / max(bw.values())  # the strictest: the best bandwidth measured
            cand = {
                "threads": threads,
                "ns_per_spin_iteration": per_it / N * 1e9,
                "bound_ns_per_spin": bound / N * 1e9,
                "triad_GBps": max(bw.values()) / 1e9,
                "triad_GBps_per_threads": {str(k): v / 1e9 for k, v in bw.items()},
                "ratio": per_it / bound,
                "runner": timer.label,
            }
            if best is None or cand["ns_per_spin_iteration"] < best["ns_per_spin_iteration"]:
                best = cand
        assert best is not None
        with thread_limits(blas=1, numba=best["threads"]):  # the update without compensation
            plain = StepTimer(prob, iso.IsoMP(compensated=False), w0, 0.1)
            plain.advance(3)
            its_plain: dict[str, int] = {}

            def uncompensated(t: StepTimer = plain, steps: int = steps,
                              its: dict = its_plain) -> None:  # fmt: skip
                its["n"] = t.advance(steps)

            tp = best_time(uncompensated, repeats=3 if N < 10**7 else 1)
        best["ratio_uncompensated"] = tp / its_plain["n"] / (72.0 * N / max(bw.values()))
        out.append(
            record(
                4, f"spin chain N = {N:.0e}: time per iteration / memory bound", **best,
                metric="ratio (iteration / (72 N bytes / triad bandwidth))", value=best["ratio"],
                target="<= 2 for N >= 1e6" if N >= 10**6 else "(no target, N < 1e6)",
                met=best["ratio"] <= 2.0 if N >= 10**6 else None,
            )
        )  # fmt: skip
    return out


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "4", *sys.argv[1:]]))
