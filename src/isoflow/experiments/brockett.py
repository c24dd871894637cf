"""Section 3.2 of the paper: Brockett's double bracket flow on herm(10)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from .. import models, registry
from .._figures import eigenvalue_figure, floor
from .._solve import solve
from ._base import Experiment, ExperimentResult, check, header

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["Brockett", "brockett"]


class Brockett(Experiment):
    """Brockett's flow on herm(n), ``N = diag(1..n)``: eigenvalues and the diagonal limit."""

    name = "brockett"
    description = (
        "herm(10), N = diag(1..10), h = 0.1, T = 1000: eigenvalues conserved; W tends to a "
        "diagonal matrix sorted like N (Sec. 3.2, Fig. 2)"
    )

    def run(
        self,
        *,
        n: int = 10,
        h: float = 0.1,
        T: float = 1000.0,
        seed: int = 0,
        save_every: int = 10,
        quick: bool = False,
        progress: bool | None = None,
    ) -> ExperimentResult:
        """Run the experiment.

        Paper, Sec. 3.2 (Fig. 2). ``quick`` integrates to ``T = 100``. Claims checked:
        eigenvalues conserved to rounding; ``Tr(WN)`` non-decreasing; ``W`` tends to a diagonal
        matrix with the eigenvalues in ascending order (the order of ``N``).

        Returns
        -------
        ExperimentResult
            ``data``: ``ts``, ``eigenvalue_variation`` ``(n_save, n)``, ``off_diagonal``
            (relative Frobenius norm of the off-diagonal part), ``diagonal`` (final diagonal),
            ``eigenvalues``.
        """
        T = 100.0 if quick else T
        params = {"n": n, "h": h, "T": T, "seed": seed, "save_every": save_every}
        problem, W0 = models.brockett(n=n, seed=seed)
        method = registry.make_method("isomp")
        start = time.perf_counter()
        sol = solve(problem, method, W0, dt=h, t1=T, save_every=save_every, progress=progress)
        wall = time.perf_counter() - start
        d = sol.diagnostics
        assert d is not None
        C = np.real(d.casimirs)
        W = sol.ys
        diag = np.real(np.einsum("tii->ti", W))
        off = np.linalg.norm(W - diag[:, :, None] * np.eye(n), axis=(1, 2)) / np.linalg.norm(
            W, axis=(1, 2)
        )
        eig = np.linalg.eigvalsh(W0)
        final_diag = diag[-1]
        s = d.summary()
        summary = header(self.name, params, quick) | {
            "drifts": s,
            "steps": sol.stats.n_steps,
            "iterations_mean": sol.stats.iterations_mean,
            "final_off_diagonal": float(off[-1]),
            "final_diagonal_minus_sorted_eigenvalues": float(np.max(np.abs(final_diag - eig))),
            "timings": {"solve": wall, "per_step": wall / max(sol.stats.n_steps, 1)},
            "checks": {
                "eigenvalues_rounding": check(
                    s["casimir_drift"], 1e-12, "eigenvalues conserved to rounding"
                ),
                "trace_WN_monotone": check(
                    s.get("lyapunov_max_decrease", 0.0), 1e-12, "Tr(WN) non-decreasing"
                ),
                "tends_to_diagonal": check(
                    float(off[-1]), 1e-3 if quick else 1e-10, "W tends to a diagonal matrix"
                ),
                "ascending_order": check(
                    float(np.max(np.abs(final_diag - eig))),
                    1e-3 if quick else 1e-10,
                    "the limit diagonal is the eigenvalues in ascending order",
                ),
            },
        }
        data = {
            "ts": sol.ts,
            "eigenvalue_variation": C - C[:1],
            "off_diagonal": off,
            "diagonal": final_diag,
            "eigenvalues": eig,
        }
        return self._result(data, summary, start)

    def figure(self, result: ExperimentResult) -> Figure:
        self._check_result(result)
        d, p = result.data, result.summary["parameters"]
        fig, ax2 = eigenvalue_figure(d["ts"], d["eigenvalue_variation"], "W")
        ax2.semilogy(d["ts"], floor(d["off_diagonal"]), color="C3", label="off-diagonal part")
        ax2.set_title("W tends to a diagonal matrix")
        ax2.set_ylabel(r"$\|W - \mathrm{diag}\,W\| / \|W\|$")
        ax2.legend(fontsize=7)
        fig.suptitle(
            f"Brockett flow on herm({p['n']}), N = diag(1..{p['n']}), IsoMP,\n"
            f"h = {p['h']:g}, T = {p['T']:g}, random W0 (seed {p['seed']})"
        )
        return fig


#: The experiment (call it to run it).
brockett = Brockett()
