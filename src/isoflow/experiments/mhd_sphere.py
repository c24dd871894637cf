r"""Two fields, one structure: MHD on the sphere and the heavy top with the dual-number IsoMP.

Part 1, magnetohydrodynamics on the sphere (:func:`isoflow.models.mhd_sphere`, Zeitlin's model
on :math:`\mathfrak{su}(N)\ltimes\mathfrak{su}(N)^*`): a random smooth vorticity and current
(band ``1 <= l <= 10``, kinetic and magnetic energy 0.25 each) integrated with IsoMP on the
dual-number pairs for a long time, as in the MHD runs of Modin and Roop (IMA J. Numer. Anal.
2025, arXiv:2311.16045; their run parameters are not reproduced here). Claims: both Casimir
families, :math:`\int\theta^k` and :math:`\int\omega\theta^k`, and the angular momentum are
conserved to rounding; the energy is bounded (it oscillates, exchanging kinetic and magnetic
energy, with no drift); the kinetic and magnetic spectra at the start and the end.

Part 2, the heavy top (:func:`isoflow.models.heavy_top`), the smallest system of the same
structure: the Lagrange and the Kovalevskaya top against a tight DOP853 reference (errors at four
step sizes, observed order 2) and a long run that keeps :math:`|\Gamma|^2` and
:math:`M\cdot\Gamma` to rounding and the top's fourth integral bounded.
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
from ..reference import reference_solution
from ._base import Experiment, ExperimentResult, check, fit_order, header

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["MHDSphere", "mhd_sphere"]

Array = NDArray[Any]

#: The tops of part 2 and the name of each one's fourth integral.
TOPS = {"lagrange": "M3", "kovalevskaya": "kovalevskaya"}


def _isomp(rtol: float) -> Any:
    return registry.make_method("isomp", registry.make_solver("fixed-point", rtol=rtol))


def _relative_drift(C: Array) -> float:
    """``max |C(t) - C(0)| / max |C(0)|`` over the components (time first)."""
    C = np.asarray(C, dtype=float).reshape(len(C), -1)
    return float(np.max(np.abs(C - C[0])) / max(float(np.max(np.abs(C[0]))), 1e-300))


def _mhd_run(N: int, h: float, T: float, seed: int, rtol: float, progress: Any) -> dict[str, Any]:
    prob, y0 = models.mhd_sphere(N=N, seed=seed)
    n_steps = max(1, round(T / h))
    sol = solve(prob, _isomp(rtol), y0, dt=T / n_steps, n_steps=n_steps,
                save_every=max(1, n_steps // 200), progress=progress)  # fmt: skip
    d = sol.diagnostics
    assert d is not None and d.hamiltonian is not None
    theta, w = prob.algebra.split(sol.ys)
    c_theta, c_w = sphere.to_coefficients(theta), sphere.to_coefficients(w)
    return {
        "dt": T / n_steps, "n_steps": n_steps, "ts": sol.ts, "drifts": d.summary(),
        "kinetic": sphere.energy(w), "magnetic": sphere.magnetic_energy(theta),
        "energy": d.hamiltonian, "theta_casimirs": d.invariants["theta_casimirs"],
        "cross_casimirs": d.invariants["cross_casimirs"],
        "c_theta": c_theta[[0, -1]], "c_w": c_w[[0, -1]],
        "kinetic_spectra": sphere.energy_spectrum(c_w[[0, -1]]),
        "magnetic_spectra": sphere.magnetic_energy_spectrum(c_theta[[0, -1]]),
        "iterations_mean": float(sol.stats.iterations_mean),
        "solve_time": float(sol.stats.wall_time),
    }  # fmt: skip


def _top_runs(hs: Array, T: float, T_long: float, rtol: float) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for top, integral in TOPS.items():
        prob, y0 = models.heavy_top(top)
        ref = reference_solution(prob, y0, [T], rtol=1e-13, atol=1e-13)[0]
        errors = []
        for h in hs:
            sol = solve(prob, _isomp(rtol), y0, dt=float(h), t1=T, save_every=10**9)
            errors.append(float(np.max(np.abs(sol.ys[-1] - ref))))
        long = solve(prob, _isomp(rtol), y0, dt=float(hs[-2]), t1=T_long,
                     save_every=max(1, round(T_long / hs[-2]) // 500))  # fmt: skip
        d = long.diagnostics
        assert d is not None and d.hamiltonian is not None
        I0 = d.invariants[integral]
        out[top] = {
            "errors": errors, "order": fit_order(hs, np.array(errors)), "drifts": d.summary(),
            "ts": long.ts, "energy_variation": d.hamiltonian - d.hamiltonian[0],
            "integral": integral, "integral_variation": float(np.max(np.abs(I0 - I0[0]))),
            "casimirs": d.casimirs, "dt_long": float(hs[-2]),
        }  # fmt: skip
    return out


class MHDSphere(Experiment):
    """Long IsoMP runs of MHD on the sphere and of the heavy top (two fields, one structure)."""

    name = "mhd-sphere"
    description = (
        "MHD on su(64) x| su(64)*, random vorticity and current, h = 0.025, T = 100: both Casimir "
        "families conserved, energy bounded, spectra; heavy tops against DOP853: order 2"
    )

    def run(
        self,
        *,
        N: int | None = None,
        seed: int = 0,
        h: float | None = None,
        T: float | None = None,
        rtol: float = 1e-14,
        quick: bool = False,
        progress: bool | None = None,
    ) -> ExperimentResult:
        r"""Run the experiment.

        Parameters
        ----------
        N : int, optional
            Matrix size of the MHD run (default 64; 16 with ``quick``).
        seed : int
            Seed of the random initial vorticity and current.
        h : float, optional
            Time step of the MHD run (default :math:`1.6/N`: the fixed-point iteration
            contracts while :math:`h\|B\|` is well below one, and :math:`\|B\|` grows like
            ``N``).
        T : float, optional
            Final time of the MHD run (default 100; 20 with ``quick``).
        rtol : float
            Tolerance of the fixed-point iterations.

        Claims checked: the spectrum of :math:`\Theta` and the cross family (the algebra's
        Casimirs), the normalized :math:`\int\theta^k` (``k = 2..6``) and
        :math:`\int\omega\theta^k` (``k = 1..5``) and the angular momentum conserved to
        rounding (relative :math:`10^{-11}`); the energy's relative variation below 1% while
        kinetic and magnetic energy each change by more than ten times as much (exchange,
        not drift); for both heavy tops the observed order :math:`2 \pm 0.05` against DOP853
        and the Casimirs conserved to rounding over :math:`10^5` steps.

        Returns
        -------
        ExperimentResult
            ``data``: the MHD series (``ts``, ``kinetic``, ``magnetic``, ``energy``, the
            Casimirs), the first and last states' coefficients and spectra, and per top the
            errors, the step sizes and the long run's energy variation.
        """
        start = time.perf_counter()
        N = (16 if quick else 64) if N is None else int(N)
        h = 1.6 / N if h is None else float(h)
        T = (20.0 if quick else 100.0) if T is None else float(T)
        if not (np.isfinite(h) and h > 0 and np.isfinite(T) and T > 0):
            raise ParameterError(f"mhd-sphere: h and T must be positive, got h={h}, T={T}")
        mhd = _mhd_run(N, h, T, seed, rtol, progress)
        hs = np.array([0.04, 0.02, 0.01, 0.005])
        tops = _top_runs(hs, T=5.0, T_long=100.0 if quick else 1000.0, rtol=rtol)
        dr = mhd["drifts"]
        H = np.asarray(mhd["energy"])
        energy_rel = float(np.max(np.abs(H - H[0])) / abs(H[0]))
        exchange = min(float(np.ptp(mhd["kinetic"])), float(np.ptp(mhd["magnetic"]))) / max(
            float(np.ptp(H)), 1e-300
        )
        checks = {
            "casimirs_rounding": check(
                dr["casimir_drift"], 1e-11,
                "spectrum of Theta and Tr(iW (i Theta/rho)^k) conserved to rounding",
            ),
            "theta_casimirs_rounding": check(
                _relative_drift(mhd["theta_casimirs"]), 1e-11,
                "int theta^k dA, k = 2..6, conserved to rounding",
            ),
            "cross_casimirs_rounding": check(
                _relative_drift(mhd["cross_casimirs"]), 1e-11,
                "int omega theta^k dA, k = 1..5, conserved to rounding",
            ),
            "angular_momentum_rounding": check(
                dr["angular_momentum_drift"], 1e-11, "angular momentum conserved to rounding"
            ),
            "energy_bounded": check(energy_rel, 1e-2, "energy relative variation below 1%"),
            "energy_exchanged": check(
                exchange, 10.0,
                "kinetic and magnetic energy each vary 10x more than their sum", below=False,
            ),
        }  # fmt: skip
        for top, r in tops.items():
            checks[f"{top}_order"] = check(
                abs(r["order"] - 2.0), 0.05, f"{top} top: observed order 2 against DOP853"
            )
            checks[f"{top}_casimirs_rounding"] = check(
                r["drifts"]["casimir_drift"], 1e-11,
                f"{top} top: |Gamma|^2 and M.Gamma conserved to rounding",
            )  # fmt: skip
        summary = header(
            self.name,
            {"N": N, "seed": seed, "h": mhd["dt"], "T": T, "n_steps": mhd["n_steps"],
             "rtol": rtol, "initial": "random, 1 <= l <= 10, E_K = E_M = 0.25",
             "top_step_sizes": hs.tolist(), "top_T": 5.0,
             "top_T_long": float(tops["lagrange"]["ts"][-1])},
            quick,
        ) | {
            "drifts": dr,
            "energy_relative_variation": energy_rel,
            "energy_exchange_ratio": exchange,
            "iterations_mean": mhd["iterations_mean"],
            "solve_time": mhd["solve_time"],
            "tops": {
                top: {"errors": r["errors"], "observed_order": r["order"], "drifts": r["drifts"],
                      f"{r['integral']}_variation": r["integral_variation"]}
                for top, r in tops.items()
            },
            "checks": checks,
        }  # fmt: skip
        data = {"mhd": mhd, "tops": tops, "hs": hs}
        return self._result(data, summary, start)

    def figure(self, result: ExperimentResult) -> Figure:
        from ..sphere import degree_order
        from ..sphere.figures import draw_field_lines, draw_map

        self._check_result(result)
        d, p = result.data, result.summary["parameters"]
        mhd = d["mhd"]
        fig = new_figure(figsize=(11, 6.6))
        axes = fig.subplots(2, 3)
        lmax = int(np.sqrt(mhd["c_w"].shape[-1] + 1)) - 1
        # two points per wavelength, shown as cells: small PNG files for noisy fields
        grid: dict[str, Any] = {"ntheta": 2 * lmax + 2, "nphi": 4 * lmax + 4}
        cells = {**grid, "interpolation": "nearest"}
        t_end = float(mhd["ts"][-1])
        im = draw_map(axes[0, 0], mhd["c_w"][-1], **cells)
        axes[0, 0].set_title(f"vorticity $\\omega$, t = {t_end:g}")
        fig.colorbar(im, ax=axes[0, 0], shrink=0.8, label=r"$\omega$")
        ls, _ = degree_order(lmax)
        im = draw_map(axes[0, 1], -ls * (ls + 1.0) * mhd["c_theta"][-1], cmap="PuOr_r", **cells)
        draw_field_lines(axes[0, 1], mhd["c_theta"][-1], **grid)
        axes[0, 1].set_title(f"current $j$ and field lines, t = {t_end:g}")
        fig.colorbar(im, ax=axes[0, 1], shrink=0.8, label=r"$j = \Delta\theta$")
        ax = axes[0, 2]
        top = max(float(np.max(mhd["kinetic_spectra"])), float(np.max(mhd["magnetic_spectra"])))
        for name, spectra, style in (("kinetic", mhd["kinetic_spectra"], "-"),
                                     ("magnetic", mhd["magnetic_spectra"], "--")):  # fmt: skip
            for k, when in ((0, "t = 0"), (-1, f"t = {t_end:g}")):
                E = np.asarray(spectra[k])
                ls_ = np.arange(1, len(E) + 1)
                ax.loglog(ls_, np.where(E > 1e-14 * top, E, np.nan), style,
                          color="C0" if k == 0 else "C3", label=f"{name}, {when}")  # fmt: skip
        ax.set_ylim(top * 1e-10, top * 3)
        ax.set_xlabel("degree $l$")
        ax.set_ylabel("$E_l$")
        ax.set_title("energy spectra")
        ax.legend(fontsize=7)
        ax = axes[1, 0]
        ts = mhd["ts"]
        ax.plot(ts, mhd["kinetic"], label="kinetic $E_K$")
        ax.plot(ts, mhd["magnetic"], label="magnetic $E_M$")
        ax.plot(ts, mhd["energy"], "k", label="total $H$")
        ax.set_xlabel("time $t$")
        ax.set_ylabel("energy")
        ax.set_title("energies: exchanged, total bounded")
        ax.legend(fontsize=8)
        ax = axes[1, 1]
        H = np.asarray(mhd["energy"])
        for name, C in (("$\\int\\theta^k$", mhd["theta_casimirs"]),
                        ("$\\int\\omega\\theta^k$", mhd["cross_casimirs"])):  # fmt: skip
            C = np.asarray(C)
            ax.semilogy(ts, floor(np.max(np.abs(C - C[0]), axis=-1)) / np.max(np.abs(C[0])),
                        lw=0.8, label=name)  # fmt: skip
        ax.semilogy(ts, floor(H - H[0]) / abs(H[0]), "k", lw=1.0, label="energy $H$")
        ax.set_ylim(1e-17, 1)
        ax.set_xlabel("time $t$")
        ax.set_ylabel("relative variation")
        ax.set_title("Casimir families and energy")
        ax.legend(fontsize=8)
        ax = axes[1, 2]
        hs = np.asarray(d["hs"])
        for k, (top_name, r) in enumerate(d["tops"].items()):
            ax.loglog(hs, r["errors"], "o-", color=f"C{k}",
                      label=f"{top_name} (order {r['order']:.2f})")  # fmt: skip
        e0 = max(r["errors"][0] for r in d["tops"].values())
        ax.loglog(hs, e0 * (hs / hs[0]) ** 2, "k--", lw=0.7, label="$h^2$")
        ax.set_xticks(hs, labels=[f"{v:g}" for v in hs])
        ax.set_xticks([], minor=True)
        ax.set_xlabel("step $h$")
        ax.set_ylabel("error at t = 5 (max norm)")
        ax.set_title("heavy tops against DOP853")
        ax.legend(fontsize=8)
        fig.suptitle(
            f"Two fields, one structure: MHD on su({p['N']}) x| su({p['N']})*, IsoMP, "
            f"h = {p['h']:.3g}, T = {p['T']:g} (seed {p['seed']}); heavy tops"
        )
        return fig


#: The experiment (call it to run it).
mhd_sphere = MHDSphere()
