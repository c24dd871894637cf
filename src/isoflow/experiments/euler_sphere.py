r"""Vortex condensation in Zeitlin's Euler equations on the sphere (Modin & Viviani, JFM 2020).

A random smooth vorticity (coefficients in the band ``1 <= l <= 10``, root-mean-square 1) is
integrated with IsoMP on :math:`\mathfrak{su}(N)` for a long time. The known outcome
(K. Modin, M. Viviani, *A Casimir preserving scheme for long-time simulation of spherical
ideal hydrodynamics*, J. Fluid Mech. 884 (2020) A22): while enstrophy cascades to the
smallest resolved scales, the energy gathers in the lowest degrees and the large-scale
vorticity condenses into a few (2 to 4) big vortices that persist, with every Casimir kept
to rounding by the isospectral scheme and the energy bounded.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .. import models, registry, sphere
from .._errors import ParameterError
from .._figures import floor, new_figure
from .._solve import solve
from ._base import Experiment, ExperimentResult, check, header

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["EulerSphere", "euler_sphere"]

Array = NDArray[Any]

#: Degrees whose energy counts as "large scale" in the condensation check.
LARGE_SCALE_LMAX = 3


class EulerSphere(Experiment):
    """Long IsoMP run of the Euler equations on the sphere from random data: condensation."""

    name = "euler-sphere"
    description = (
        "su(128), random vorticity (1 <= l <= 10), h = 0.025, T = 150: Casimirs conserved; the "
        "vorticity condenses into a few large vortices (Modin & Viviani, JFM 2020)"
    )

    def run(
        self,
        *,
        N: int | None = None,
        omega: float = 0.0,
        seed: int = 0,
        h: float | None = None,
        T: float = 150.0,
        rtol: float = 1e-14,
        quick: bool = False,
        progress: bool | None = None,
    ) -> ExperimentResult:
        r"""Run the experiment: a long IsoMP run from random data.

        Parameters
        ----------
        N : int, optional
            Matrix size (default 128; 32 with ``quick``).
        omega : float
            Rotation of the sphere (default 0, as in the paper's condensation runs).
        seed : int
            Seed of the random initial vorticity (band ``1 <= l <= 10``, rms 1).
        h : float, optional
            Time step (default :math:`3.2/N`: the fixed-point iteration of IsoMP contracts when
            :math:`h\|B\|` is well below one, and :math:`\|B\| \approx N\max|\psi|/2` grows like
            ``N``).
        T : float
            Final time (default 150: many eddy turnovers; condensation sets in by ``t ~ 50``).
        rtol : float
            Tolerance of the fixed-point iteration.

        Claims checked: all Casimirs conserved to rounding (eigenvalues of the vorticity, and the
        angular momentum); energy bounded (relative variation below 2%, an ``O(h^2)`` effect that
        grows as the vorticity develops fine scales); condensation: the fraction of the energy in
        degrees ``l <= 3`` rises by at least 0.2 and ends (mean over the last quarter) at 0.75 or
        more.

        Returns
        -------
        ExperimentResult
            ``data``: ``ts``, ``coefficients`` of the relative vorticity ``(n_save, N^2 - 1)``,
            ``energy``, ``enstrophy``, ``casimirs`` ``(n_save, 5)`` (:math:`C_2..C_6`),
            ``large_scale_fraction`` (energy in ``l <= 3`` over the total), ``spectra``
            (:math:`E_l` at the first and last state).
        """
        start = time.perf_counter()
        N = (32 if quick else 128) if N is None else N
        prob, Q0 = models.euler_sphere(N=N, omega=omega, seed=seed)
        h = 3.2 / N if h is None else float(h)
        if not (np.isfinite(h) and h > 0 and np.isfinite(T) and T > 0):
            raise ParameterError(f"euler-sphere: h and T must be positive, got h={h}, T={T}")
        n_steps = max(1, round(T / h))
        dt = T / n_steps
        save_every = max(1, n_steps // 150)
        sol = solve(
            prob, registry.make_method("isomp", registry.make_solver("fixed-point", rtol=rtol)),
            Q0, dt=dt, n_steps=n_steps,
            save_every=save_every, progress=progress,
        )  # fmt: skip
        d = sol.diagnostics
        assert d is not None and d.hamiltonian is not None
        F = models.coriolis_matrix(N, omega)
        W = sol.ys - F
        coeffs = sphere.to_coefficients(W)
        E = sphere.energy_spectrum(coeffs)
        fraction = E[:, :LARGE_SCALE_LMAX].sum(-1) / E.sum(-1)
        C = sphere.casimirs(sol.ys)
        lam = float(np.max(np.abs(sphere.vorticity_levels(sol.ys[0]))))
        casimir_rel = float(np.max(np.abs(C - C[0]) / (4 * np.pi * lam ** np.arange(2, 7))))
        H = d.hamiltonian
        energy_rel = float(np.max(np.abs(H - H[0])) / abs(H[0]))
        Z = sphere.enstrophy_spectrum(coeffs)
        small = float(Z[-1, 10:].sum() / Z[-1].sum()) if Z.shape[-1] > 10 else 0.0
        tail = fraction[len(fraction) * 3 // 4 :]
        drifts = d.summary()
        mom_key = "angular_momentum_drift" if omega == 0 else "angular_momentum_z_drift"
        checks = {
            "casimirs_rounding": check(
                drifts["casimir_drift"], 1e-11, "eigenvalues of the vorticity conserved to rounding"
            ),
            "casimir_traces_rounding": check(
                casimir_rel, 1e-11, "C_2..C_6 = (4 pi/N) Tr((-iW)^k) conserved to rounding"
            ),
            "angular_momentum_rounding": check(
                drifts[mom_key], 1e-11, "angular momentum (the momentum map) conserved to rounding"
            ),
            "energy_bounded": check(energy_rel, 2e-2, "energy relative variation stays small"),
            "energy_moves_to_large_scales": check(
                float(np.mean(tail) - fraction[0]), 0.2,
                f"energy fraction in l <= {LARGE_SCALE_LMAX} rises by 0.2 or more", below=False,
            ),
            "condensed": check(
                float(np.mean(tail)), 0.75,
                f"energy fraction in l <= {LARGE_SCALE_LMAX} ends at 0.75 or more (last quarter)",
                below=False,
            ),
        }  # fmt: skip
        summary = header(
            self.name,
            {"N": N, "omega": omega, "seed": seed, "h": dt, "T": T, "n_steps": n_steps,
             "rtol": rtol, "initial": "random, 1 <= l <= 10, rms 1"},
            quick,
        ) | {
            "drifts": drifts,
            "casimir_traces_relative_drift": casimir_rel,
            "energy_relative_variation": energy_rel,
            "large_scale_energy_fraction": {
                "initial": float(fraction[0]), "final_mean": float(np.mean(tail)),
            },
            "enstrophy_fraction_above_l10_final": small,
            "iterations_mean": float(sol.stats.iterations_mean),
            "solve_time": float(sol.stats.wall_time),
            "checks": checks,
        }  # fmt: skip
        summary["wall_time"] = time.perf_counter() - start
        data = {
            "ts": sol.ts,
            "coefficients": coeffs,
            "energy": H,
            "enstrophy": sphere.enstrophy(W),
            "casimirs": C,
            "large_scale_fraction": fraction,
            "spectra": {"t = 0": E[0], f"t = {sol.ts[-1]:g}": E[-1]},
        }
        return ExperimentResult(self.name, data, summary)

    def figure(self, result: ExperimentResult) -> Figure:
        from ..sphere import degree_order
        from ..sphere.figures import draw_energy_spectrum, draw_map

        self._check_result(result)
        d, p = result.data, result.summary["parameters"]
        ts, coeffs = d["ts"], d["coefficients"]
        fig = new_figure(figsize=(11, 6.6))
        axes = fig.subplots(2, 3)
        lmax = int(np.sqrt(coeffs.shape[-1] + 1)) - 1
        # two points per wavelength, shown as cells: smaller PNG files for noisy fields
        grid: dict[str, Any] = {
            "ntheta": 2 * lmax + 2,
            "nphi": 4 * lmax + 4,
            "interpolation": "nearest",
        }
        for ax, k, what in ((axes[0, 0], 0, "initial"), (axes[0, 1], -1, "final")):
            im = draw_map(ax, coeffs[k], **grid)  # each with its own colour scale
            ax.set_title(f"{what} vorticity $\\omega$, t = {ts[k]:g}")
            fig.colorbar(im, ax=ax, shrink=0.8, label=r"$\omega$")
        ls, _ = degree_order(lmax)
        psi = -coeffs[-1] / (ls * (ls + 1.0))
        im = draw_map(axes[0, 2], psi, cmap="PuOr_r", **grid)
        axes[0, 2].set_title(
            f"final stream function $\\psi = \\Delta^{{-1}}\\omega$, t = {ts[-1]:g}"
        )
        fig.colorbar(im, ax=axes[0, 2], shrink=0.8, label=r"$\psi$")
        ax = axes[1, 0]
        draw_energy_spectrum(ax, d["spectra"])
        ax.set_title("energy spectrum")
        ax = axes[1, 1]
        ax.plot(ts, d["large_scale_fraction"], color="C2", label=f"$l \\leq {LARGE_SCALE_LMAX}$")
        ax.set_ylim(0, 1)
        ax.set_xlabel("time $t$")
        ax.set_ylabel("energy fraction")
        ax.set_title(f"condensation: energy in $l \\leq {LARGE_SCALE_LMAX}$")
        ax.legend(fontsize=8, loc="lower right")
        ax = axes[1, 2]
        C = np.asarray(d["casimirs"])
        lam = np.max(np.abs(C[0]) ** (1.0 / np.arange(2, 2 + C.shape[1])))
        for j in range(C.shape[1]):
            k = j + 2
            ax.semilogy(ts, floor(C[:, j] - C[0, j]) / (4 * np.pi * lam**k), lw=0.8,
                        label=f"$C_{{{k}}}$")  # fmt: skip
        H = np.asarray(d["energy"])
        ax.semilogy(ts, floor(H - H[0]) / abs(H[0]), "k", lw=1.0, label="energy $H$")
        ax.set_ylim(1e-17, 1)
        ax.set_xlabel("time $t$")
        ax.set_ylabel("relative variation")
        ax.set_title("Casimirs and energy")
        ax.legend(fontsize=7, ncol=2)
        rot = f", $\\Omega$ = {p['omega']:g}" if p.get("omega") else ""
        fig.suptitle(
            f"Euler equations on the sphere (Zeitlin, su({p['N']})){rot}: IsoMP, "
            f"h = {p['h']:.3g}, T = {p['T']:g}, random initial vorticity (seed {p['seed']})"
        )
        return fig


#: The experiment (call it to run it).
euler_sphere = EulerSphere()
