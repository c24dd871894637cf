"""Section 3.4 of the paper (Fig. 7): momentum and Hamiltonian of the vortex runs."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from .._figures import new_figure, plot_variation
from ._base import Experiment, ExperimentResult, check, header
from ._vortices import paper_runs, runs_parameters

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["VorticesInvariants", "vortices_invariants"]


class VorticesInvariants(Experiment):
    """Momentum and Hamiltonian variation in time for the two vortex runs."""

    name = "vortices-invariants"
    description = (
        "the same vortex runs: momentum conserved, Hamiltonian nearly conserved (Sec. 3.4, Fig. 7)"
    )

    def run(
        self, *, rtol: float = 1e-14, quick: bool = False, progress: bool | None = None
    ) -> ExperimentResult:
        """Run the experiment.

        Paper, Sec. 3.4 (Fig. 7). Claims checked: the momentum ``M = sum Gamma_i w_i``
        conserved to rounding; the Hamiltonian nearly conserved (relative variation below
        ``1e-2``).

        Returns
        -------
        ExperimentResult
            ``data["runs"]``: per configuration ``config, h, T, ts, momentum_variation``
            ``(n_save, 3)``, ``hamiltonian_variation`` ``(n_save,)``.
        """
        start = time.perf_counter()
        runs = paper_runs(progress, rtol)
        per_run, checks = {}, {}
        for r in runs:
            key = f"config{r['config']}"
            per_run[key] = {
                "h": r["h"],
                "T": r["T"],
                "steps": r["steps"],
                "solve_time": r["wall"],
                "drifts": r["drifts"],
            }
            checks[f"{key}_momentum_rounding"] = check(
                r["drifts"]["momentum_drift"], 1e-12, "momentum conserved to rounding"
            )
            checks[f"{key}_hamiltonian_bounded"] = check(
                r["drifts"]["hamiltonian_relative_drift"], 1e-2, "Hamiltonian nearly conserved"
            )
        keys = ("config", "h", "T", "ts", "momentum_variation", "hamiltonian_variation")
        data_runs = [{k: r[k] for k in keys} for r in runs]
        summary = header(self.name, runs_parameters(rtol), quick) | {
            "runs": per_run,
            "checks": checks,
        }
        return self._result({"runs": data_runs}, summary, start)

    def figure(self, result: ExperimentResult) -> Figure:
        self._check_result(result)
        runs = result.data["runs"]
        fig = new_figure(figsize=(10, 6.2))
        axes = np.asarray(fig.subplots(2, len(runs))).reshape(2, len(runs))
        for j, r in enumerate(runs):
            what = f"config {r['config']} (h = {r['h']:g}, T = {r['T']:g})"
            ax = axes[0, j]
            plot_variation(ax, r["ts"], r["momentum_variation"], lw=0.8,
                           ylabel=r"$M(t) - M(0)$", labels=["$M_x$", "$M_y$", "$M_z$"],
                           legend_columns=3)  # fmt: skip
            ax.set_title(f"{what}: momentum")
            ax = axes[1, j]
            plot_variation(ax, r["ts"], r["hamiltonian_variation"], lw=0.8, color="C3",
                           ylabel=r"$H(t) - H(0)$", labels=["Hamiltonian"])  # fmt: skip
            ax.set_title(f"{what}: Hamiltonian")
            ax.set_xlabel("t")
        fig.suptitle("Point vortices on the hyperbolic plane (hyperbolic midpoint): invariants")
        return fig


#: The experiment (call it to run it).
vortices_invariants = VorticesInvariants()
