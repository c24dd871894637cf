"""Section 3.3 of the paper (Fig. 5): error against step size on the spin chain."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import models, registry
from .._figures import new_figure
from .._solve import Solution, solve
from ._base import Experiment, ExperimentResult, check, fit_order, header
from ._spin_chain import LABELS, METHODS, method

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["SpinChainError", "spin_chain_error"]


def _run_error(
    problem: Any, key: str, w0: Any, h: float, T: float, save_every: int
) -> tuple[Solution, str]:
    """Fixed-point first; Newton where the fixed point does not converge (large ``h``)."""
    for name in ("fixed-point", "newton"):
        sol = solve(
            problem,
            method(key, registry.make_solver(name)),
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


class SpinChainError(Experiment):
    r"""Error against a DOP853 reference for ``h = 0.5^k``, both methods, with ``h^2``."""

    name = "spin-chain-error"
    description = (
        "N = 100, T = 1, h = 1, 0.5^2 .. 0.5^17: both methods are second order, no significant "
        "difference (Sec. 3.3, Fig. 5)"
    )

    def run(
        self,
        *,
        N: int = 100,
        T: float = 1.0,
        exponents: tuple[int, ...] = (0, *range(2, 18)),
        grid: float = 2.0**-6,
        rtol: float = 1e-13,
        quick: bool = False,
        progress: bool | None = None,
    ) -> ExperimentResult:
        r"""Run the experiment.

        Paper, Sec. 3.3 (Fig. 5): ``h = 1, 0.5^2, ..., 0.5^17``, ``T = 1``, ``N = 100``. The
        error is :math:`\max_t \|w(t) - w_t\|` (Euclidean norm of the whole ``(N, 3)`` state)
        over the times ``t`` of the grid of spacing ``max(h, grid)``; the reference is DOP853
        with ``rtol = atol = 1e-13``. The fitted order uses ``h <= 0.5^3``. ``quick``:
        ``k = 2..9``. Claim checked: both methods are of order 2.

        Returns
        -------
        ExperimentResult
            ``data``: ``hs`` and ``errors`` (dict method -> array; NaN where a solve failed).
        """
        from tqdm.auto import tqdm

        from ..reference import reference_solution

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
        errors = {k: np.full(len(hs), np.nan) for k in METHODS}
        solvers: dict[str, list[str]] = {k: [] for k in METHODS}
        run_times: dict[str, list[float]] = {k: [] for k in METHODS}
        disable = None if progress is None else not progress
        with tqdm(
            total=len(hs) * 2, desc=self.name, disable=disable, leave=False, delay=1.0
        ) as bar:
            for i, h in enumerate(hs):
                stride = max(h, grid)
                save_every = max(1, round(stride / h))
                ref_every = max(1, round(stride / grid))
                for key in METHODS:
                    sol, used = _run_error(problem, key, w0, float(h), T, save_every)
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
        summary = header(self.name, params, quick) | {
            "errors": {
                k: [None if not np.isfinite(e) else e for e in v.tolist()]
                for k, v in errors.items()
            },
            "solvers": solvers,
            "observed_order": orders,
            "timings": timings,
            "checks": {
                f"{k}_order_2": check(abs(orders[k] - 2.0), 0.2, f"{k}: second order (|p - 2|)")
                for k in METHODS
            },
        }
        return self._result({"hs": hs, "errors": errors}, summary, start)

    def figure(self, result: ExperimentResult) -> Figure:
        self._check_result(result)
        d, p = result.data, result.summary["parameters"]
        fig = new_figure(figsize=(6.5, 4.8))
        ax = fig.subplots()
        hs = d["hs"]
        ax.loglog(hs, d["errors"]["isomp"], "o-.", label=LABELS["isomp"])
        ax.loglog(hs, d["errors"]["spherical"], "s--", label=LABELS["spherical"])
        ax.loglog(hs, hs**2, "k-", lw=0.8, label=r"$h^2$")
        orders = result.summary["observed_order"]
        ax.set_title(
            f"Heisenberg chain, N = {p['N']}, T = {p['T']:g}: error against DOP853\n"
            f"(observed orders {orders['isomp']:.2f} and {orders['spherical']:.2f})"
        )
        ax.set_xlabel("time step h")
        ax.set_ylabel(r"error $\max_k \|w(kh) - w_k\|$")
        ax.legend()
        return fig


#: The experiment (call it to run it).
spin_chain_error = SpinChainError()
