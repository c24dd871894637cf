"""Section 3.3 of the paper (Fig. 4): Hamiltonian variation on the spin chain."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import models
from .._figures import new_figure, plot_variation
from .._solve import solve
from ._base import Experiment, ExperimentResult, check, header
from ._spin_chain import LABELS, METHODS, method

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["SpinChainEnergy", "spin_chain_energy"]


class SpinChainEnergy(Experiment):
    """``|H(kh) - H(0)|`` for ``N`` spins, IsoMP and the spherical midpoint."""

    name = "spin-chain-energy"
    description = (
        "N = 100, h = 0.1, T = 1000: both methods nearly conserve H, the spherical midpoint "
        "slightly better (Sec. 3.3, Fig. 4)"
    )

    def run(
        self,
        *,
        N: int = 100,
        h: float = 0.1,
        T: float = 1000.0,
        save_every: int = 1,
        quick: bool = False,
        progress: bool | None = None,
    ) -> ExperimentResult:
        """Run the experiment.

        Paper, Sec. 3.3 (Fig. 4), the paper's closed curve as initial data. ``quick``:
        ``T = 20``. Claims checked: ``|w_i|`` (Casimirs) and the total spin (linear invariant)
        conserved to rounding by both; the Hamiltonian nearly conserved (bounded) by both.

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
        for key in METHODS:
            sol = solve(
                problem, method(key), w0, dt=h, t1=T, save_every=save_every, progress=progress
            )
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
        summary = header(self.name, params, quick) | {
            "drifts": drifts,
            "timings": timings,
            "checks": checks,
        }
        return self._result({"ts": ts, "hamiltonian_variation": var}, summary, start)

    def figure(self, result: ExperimentResult) -> Figure:
        self._check_result(result)
        d, p = result.data, result.summary["parameters"]
        fig = new_figure(figsize=(7.5, 6))
        axes = fig.subplots(2, 1, sharex=True)
        for ax, key, color in zip(axes, ("isomp", "spherical"), ("C0", "C1"), strict=True):
            plot_variation(ax, d["ts"], d["hamiltonian_variation"][key], lw=0.6, color=color,
                           ylabel=r"$|H(kh) - H(0)|$", labels=[LABELS[key]])  # fmt: skip
            ax.set_title(LABELS[key])
        axes[-1].set_xlabel("t")
        fig.suptitle(
            f"Heisenberg spin chain, N = {p['N']}, the paper's closed curve,\n"
            f"h = {p['h']:g}, T = {p['T']:g}: Hamiltonian variation"
        )
        return fig


#: The experiment (call it to run it).
spin_chain_energy = SpinChainEnergy()
