"""Section 3.3 of the paper: the Heisenberg spin chain, IsoMP against the spherical midpoint."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from .. import models
from .._solve import Solution, solve
from ..methods import IsoMP, Method, SphericalMidpoint
from ..nonlinear import FixedPoint, Newton
from ..reference import reference_solution
from ._common import ExperimentResult, check, fit_order, header

__all__ = ["spin_chain_cost", "spin_chain_energy", "spin_chain_error"]

_METHODS: dict[str, type[Method]] = {"isomp": IsoMP, "spherical": SphericalMidpoint}


def spin_chain_cost(
    *,
    Ns: tuple[int, ...] = (10, 20, 50, 100, 200, 500, 1000),
    h: float = 0.1,
    n_steps: int = 50,
    repeats: int = 3,
    seed: int = 0,
    quick: bool = False,
    progress: bool | None = None,
) -> ExperimentResult:
    """Average wall time per step against the number of spins ``N``, both methods (log–log).

    Paper, Sec. 3.3 (Fig. 3): random initial spins, the same fixed-point solver for both
    methods. The time per step is the best of ``repeats`` runs of ``n_steps`` steps. ``quick``:
    ``N = 10, 40, 160``, 10 steps, one run. Claims checked: the cost grows alike (fitted log–log
    slopes within 0.5 of each other) and IsoMP is at most 4 times as expensive per step.

    Returns
    -------
    ExperimentResult
        ``data``: ``Ns``, ``time_per_step`` (dict method -> array), ``iterations`` (mean per
        step, dict method -> array).
    """
    if quick:
        Ns, n_steps, repeats = (10, 40, 160), 10, 1
    params = {"Ns": list(Ns), "h": h, "n_steps": n_steps, "repeats": repeats, "seed": seed}
    start = time.perf_counter()
    times = {k: np.empty(len(Ns)) for k in _METHODS}
    iters = {k: np.empty(len(Ns)) for k in _METHODS}
    bar = tqdm(
        total=len(Ns) * len(_METHODS),
        desc="spin-chain-cost",
        disable=None if progress is None else not progress,
        leave=False,
        delay=1.0,
    )
    with bar:
        for i, N in enumerate(Ns):
            problem, w0 = models.heisenberg_chain(N=N, initial="random", seed=seed)
            for key, cls in _METHODS.items():
                # warm-up (compiled kernels, caches) outside the timing
                solve(problem, cls(), w0, dt=h, n_steps=2, diagnostics=False, progress=False)
                best = np.inf
                for _ in range(repeats):
                    sol = solve(
                        problem,
                        cls(),
                        w0,
                        dt=h,
                        n_steps=n_steps,
                        save_every=n_steps,
                        diagnostics=False,
                        progress=False,
                    )
                    best = min(best, sol.stats.wall_time / n_steps)
                times[key][i] = best
                iters[key][i] = sol.stats.iterations_mean
                bar.update()
    Na = np.asarray(Ns, dtype=float)
    slopes = {k: fit_order(Na, v) for k, v in times.items()}
    ratio = times["isomp"] / times["spherical"]
    summary = header("spin-chain-cost", params, quick) | {
        "time_per_step": {k: v.tolist() for k, v in times.items()},
        "iterations_mean": {k: v.tolist() for k, v in iters.items()},
        "loglog_slope": slopes,
        "time_ratio_isomp_over_spherical": ratio.tolist(),
        "checks": {
            "similar_growth": check(
                abs(slopes["isomp"] - slopes["spherical"]),
                0.5,
                "the cost per step grows alike with N (log-log slopes)",
            ),
            "isomp_not_costlier": check(
                float(np.max(ratio)),
                4.0,
                "IsoMP costs at most a small factor more than the spherical midpoint "
                "(max time ratio isomp/spherical)",
            ),
        },
    }
    summary["wall_time"] = time.perf_counter() - start
    return ExperimentResult(
        "spin-chain-cost", {"Ns": Na, "time_per_step": times, "iterations": iters}, summary
    )


def spin_chain_energy(
    *,
    N: int = 100,
    h: float = 0.1,
    T: float = 1000.0,
    save_every: int = 1,
    quick: bool = False,
    progress: bool | None = None,
) -> ExperimentResult:
    """Hamiltonian variation ``|H(kh) - H(0)|`` for ``N`` spins, IsoMP and spherical midpoint.

    Paper, Sec. 3.3 (Fig. 4), the paper's closed curve as initial data. ``quick``: ``T = 20``.
    Claims checked: ``|w_i|`` (Casimirs) and the total spin (linear invariant) conserved to
    rounding by both; the Hamiltonian nearly conserved (bounded) by both.

    Returns
    -------
    ExperimentResult
        ``data``: ``ts`` and ``hamiltonian_variation`` (dict method -> array).
    """
    T = 20.0 if quick else T
    params = {"N": N, "h": h, "T": T, "save_every": save_every, "initial": "curve"}
    problem, w0 = models.heisenberg_chain(N=N)
    start = time.perf_counter()
    var: dict[str, Any] = {}
    drifts: dict[str, Any] = {}
    timings: dict[str, float] = {}
    checks: dict[str, Any] = {}
    ts = np.empty(0)
    for key, cls in _METHODS.items():
        sol = solve(problem, cls(), w0, dt=h, t1=T, save_every=save_every, progress=progress)
        d = sol.diagnostics
        assert d is not None and d.hamiltonian is not None
        ts = sol.ts
        var[key] = np.abs(d.hamiltonian - d.hamiltonian[0])
        drifts[key] = d.summary()
        timings[key] = sol.stats.wall_time
        s = drifts[key]
        checks[f"{key}_casimirs_rounding"] = check(
            s["casimir_drift"], 1e-12, f"{key}: |w_i| conserved to rounding"
        )
        checks[f"{key}_momentum_rounding"] = check(
            s["momentum_drift"], 1e-11, f"{key}: total spin conserved to rounding"
        )
        checks[f"{key}_hamiltonian_bounded"] = check(
            s["hamiltonian_relative_drift"], 1e-3, f"{key}: Hamiltonian nearly conserved"
        )
    summary = header("spin-chain-energy", params, quick) | {
        "drifts": drifts,
        "timings": timings,
        "checks": checks,
    }
    summary["wall_time"] = time.perf_counter() - start
    return ExperimentResult("spin-chain-energy", {"ts": ts, "hamiltonian_variation": var}, summary)


def _run_error(
    problem: Any, cls: Any, w0: Any, h: float, T: float, save_every: int
) -> tuple[Solution, str]:
    """Fixed-point first; Newton where the fixed point does not converge (large ``h``)."""
    for name, solver in (("fixed-point", FixedPoint()), ("newton", Newton())):
        sol = solve(
            problem,
            cls(solver=solver),
            w0,
            dt=h,
            t1=T,
            save_every=save_every,
            diagnostics=False,
            progress=False,
            throw=False,
        )
        if sol.success:
            return sol, name
    return sol, "newton"


def spin_chain_error(
    *,
    N: int = 100,
    T: float = 1.0,
    exponents: tuple[int, ...] = (0, *range(2, 18)),
    grid: float = 2.0**-6,
    rtol: float = 1e-13,
    quick: bool = False,
    progress: bool | None = None,
) -> ExperimentResult:
    r"""Error against a DOP853 reference for ``h = 0.5^k``, both methods, with ``h^2``.

    Paper, Sec. 3.3 (Fig. 5): ``h = 1, 0.5^2, ..., 0.5^17``, ``T = 1``, ``N = 100``. The error
    is :math:`\max_t \|w(t) - w_t\|` (Euclidean norm of the whole ``(N, 3)`` state) over the
    times ``t`` of the grid of spacing ``max(h, grid)``; the reference is DOP853 with
    ``rtol = atol = 1e-13``. The fitted order uses ``h <= 0.5^3``. ``quick``: ``k = 2..9``.
    Claim checked: both methods are of order 2.

    Returns
    -------
    ExperimentResult
        ``data``: ``hs`` and ``errors`` (dict method -> array; NaN where a solve failed).
    """
    if quick:
        exponents = tuple(range(2, 10))
    hs = 0.5 ** np.asarray(exponents, dtype=float)
    params = {"N": N, "T": T, "hs": hs.tolist(), "grid": grid, "reference_rtol": rtol}
    problem, w0 = models.heisenberg_chain(N=N)
    start = time.perf_counter()
    n_grid = round(T / grid)
    t_ref = np.linspace(0.0, T, n_grid + 1)
    t0 = time.perf_counter()
    ref = reference_solution(problem, w0, t_ref, rtol=rtol, atol=rtol)
    timings: dict[str, Any] = {"reference": time.perf_counter() - t0}
    errors = {k: np.full(len(hs), np.nan) for k in _METHODS}
    solvers: dict[str, list[str]] = {k: [] for k in _METHODS}
    run_times: dict[str, list[float]] = {k: [] for k in _METHODS}
    disable = None if progress is None else not progress
    with tqdm(
        total=len(hs) * 2, desc="spin-chain-error", disable=disable, leave=False, delay=1.0
    ) as bar:
        for i, h in enumerate(hs):
            stride = max(h, grid)
            save_every = max(1, round(stride / h))
            ref_every = max(1, round(stride / grid))
            for key, cls in _METHODS.items():
                sol, used = _run_error(problem, cls, w0, float(h), T, save_every)
                solvers[key].append(used)
                run_times[key].append(sol.stats.wall_time)
                if sol.success:
                    diff = sol.ys - ref[::ref_every]
                    errors[key][i] = float(
                        np.max(np.linalg.norm(diff.reshape(len(diff), -1), axis=1))
                    )
                bar.update()
    fit = hs <= 0.5**3
    orders = {k: fit_order(hs[fit], v[fit]) for k, v in errors.items()}
    timings["runs"] = run_times
    summary = header("spin-chain-error", params, quick) | {
        "errors": {
            k: [None if not np.isfinite(e) else e for e in v.tolist()] for k, v in errors.items()
        },
        "solvers": solvers,
        "observed_order": orders,
        "timings": timings,
        "checks": {
            f"{k}_order_2": check(abs(orders[k] - 2.0), 0.2, f"{k}: second order (|p - 2|)")
            for k in _METHODS
        },
    }
    summary["wall_time"] = time.perf_counter() - start
    return ExperimentResult("spin-chain-error", {"hs": hs, "errors": errors}, summary)
