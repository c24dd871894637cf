"""Section 3.1 of the paper: the generalized rigid body on so(10)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from .. import models, registry
from .._figures import eigenvalue_figure, plot_variation
from .._solve import solve
from ._base import Experiment, ExperimentResult, check, header

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["RigidBody", "rigid_body"]


class RigidBody(Experiment):
    """Generalized rigid body on so(n) with IsoMP: Casimir and Hamiltonian variation in time."""

    name = "rigid-body"
    description = (
        "so(10) rigid body, h = 0.1, T = 100: Casimirs conserved to rounding, Hamiltonian "
        "nearly conserved (Sec. 3.1, Fig. 1)"
    )

    def run(
        self,
        *,
        n: int = 10,
        h: float = 0.1,
        T: float = 100.0,
        solver: str = "fixed-point",
        rtol: float = 1e-14,
        quick: bool = False,
        progress: bool | None = None,
    ) -> ExperimentResult:
        """Run the experiment.

        Paper, Sec. 3.1 (Fig. 1), with the symmetrized inertia of the corrections. ``quick``
        integrates to ``T = 10``. ``solver`` is a name of :data:`isoflow.registry.SOLVERS`.
        Claims checked: Casimirs (eigenvalues) conserved to rounding; the Hamiltonian nearly
        conserved (bounded relative variation, ``O(h^2)``).

        Returns
        -------
        ExperimentResult
            ``data``: ``ts``, ``casimir_variation`` ``(n_save, m)`` (``C(t) - C(0)``),
            ``hamiltonian_variation`` ``(n_save,)`` (``H(t) - H(0)``).
        """
        T = 10.0 if quick else T
        params = {"n": n, "h": h, "T": T, "solver": solver, "rtol": rtol}
        problem, W0 = models.rigid_body(n=n)
        method = registry.make_method("isomp", registry.make_solver(solver, rtol=rtol))
        start = time.perf_counter()
        sol = solve(problem, method, W0, dt=h, t1=T, progress=progress)
        wall = time.perf_counter() - start
        d = sol.diagnostics
        assert d is not None and d.hamiltonian is not None
        C = np.real(d.casimirs)
        s = d.summary()
        H0 = float(d.hamiltonian[0])
        summary = header(self.name, params, quick) | {
            "drifts": s,
            "steps": sol.stats.n_steps,
            "iterations_mean": sol.stats.iterations_mean,
            "timings": {"solve": wall, "per_step": wall / max(sol.stats.n_steps, 1)},
            "checks": {
                "casimirs_rounding": check(
                    s["casimir_drift"], 1e-12, "Casimirs (eigenvalues) conserved to rounding"
                ),
                "distance_to_so_n": check(s["max_distance"], 1e-12, "the state stays in so(n)"),
                "hamiltonian_bounded": check(
                    s["hamiltonian_relative_drift"], 1e-3, "Hamiltonian nearly conserved (O(h^2))"
                ),
            },
        }
        data = {
            "ts": sol.ts,
            "casimir_variation": C - C[:1],
            "hamiltonian_variation": d.hamiltonian - H0,
            "H0": H0,
        }
        return self._result(data, summary, start)

    def figure(self, result: ExperimentResult) -> Figure:
        self._check_result(result)
        d, p = result.data, result.summary["parameters"]
        fig, ax2 = eigenvalue_figure(d["ts"], d["casimir_variation"], "iW")
        plot_variation(ax2, d["ts"], d["hamiltonian_variation"], lw=0.8, color="C3",
                       ylabel=r"$H(t) - H(0)$", labels=["Hamiltonian"])  # fmt: skip
        ax2.set_title("Hamiltonian variation (bounded, $O(h^2)$)")
        fig.suptitle(
            f"Generalized rigid body on so({p['n']}), IsoMP ({p['solver']}, rtol = "
            f"{p['rtol']:g}), h = {p['h']:g}, T = {p['T']:g}"
        )
        return fig


#: The experiment (call it to run it).
rigid_body = RigidBody()
