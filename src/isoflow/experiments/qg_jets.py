r"""Jets on a rotating sphere: the shallow-water quasi-geostrophic model at a few Lamb parameters.

After Franken, Caliaro, Cifani and Geurts (JAMES 2024, arXiv:2306.15481), at a far smaller
resolution and time: :func:`isoflow.models.qg_sphere` on :math:`\mathfrak{su}(N)` rotating at
:math:`\Omega`, from the same random relative potential vorticity (band ``2 <= l <= 12``, rms
one) at Lamb parameters :math:`F = 0` (Euler), 30 and 300, integrated by IsoMP. Claims (the
paper's, qualitatively): zonal jets form (the zonal part of the kinetic energy grows several
times from its initial share); the zonal wind decreases with latitude, the more so the larger
:math:`F` (the polar deformation radius :math:`1/\sqrt F` screens the high latitudes); the
kinetic-energy spectra; and the structure: the Casimirs of the potential vorticity are
conserved to rounding and the energy is bounded (IsoMP's :math:`O(h^2)` oscillation).

The check of jets and of the latitude profile are statistical statements about one turbulent
run each (seed 1); they hold for these parameters, and are reported with their values so a
run at other parameters says how far it is from them.
"""

from __future__ import annotations

import itertools
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

__all__ = ["QGJets", "qg_jets"]

Array = NDArray[Any]

#: Latitudes (degrees) below which the wind is "low" and above which it is "high".
LOW_LATITUDE, HIGH_LATITUDE = 30.0, 60.0


def _zonal_share(P: Array) -> Array:
    """The share of the kinetic energy in the zonal (``m = 0``) modes of stream matrices."""
    c = sphere.to_coefficients(P)
    N = P.shape[-1]
    ls, ms = sphere.degree_order(N - 1)
    kinetic = ls * (ls + 1.0) * c**2
    return np.asarray(kinetic[..., ms == 0].sum(-1) / kinetic.sum(-1))


def _run(N: int, lamb: float, omega: float, h: float, T: float, seed: int, rtol: float,
         progress: Any) -> dict[str, Any]:  # fmt: skip
    """One QG run: the zonal wind, zonal share, spectra and drifts at its saves."""
    from ..models._qg_sphere import ZONAL_LATITUDES, qg_operator

    prob, Q0 = models.qg_sphere(N=N, lamb=lamb, omega=omega, seed=seed, lmin=2,
                                lmax=min(12, N - 1))  # fmt: skip
    n_steps = max(1, round(T / h))
    method = registry.make_method("isomp", registry.make_solver("fixed-point", rtol=rtol))
    sol = solve(prob, method, Q0, dt=T / n_steps, n_steps=n_steps,
                save_every=max(1, n_steps // 100), progress=progress)  # fmt: skip
    d = sol.diagnostics
    assert d is not None and d.hamiltonian is not None
    rel = sol.ys - models.coriolis_matrix(N, omega)
    P = sphere.solve_poisson(rel) if lamb == 0.0 else qg_operator(N, lamb).solve(rel)
    u = np.asarray(d.observables["zonal_wind"])
    lat = 90.0 - np.linspace(0.0, 180.0, ZONAL_LATITUDES)
    H = np.asarray(d.hamiltonian)
    return {
        "lamb": lamb, "ts": sol.ts, "wind": u, "latitude": lat, "zonal_share": _zonal_share(P),
        "spectra": _kinetic(P[[0, -1]]), "drifts": d.summary(),
        "casimir_variation": _relative_variation(np.asarray(d.casimirs)),
        "energy_variation": (H - H[0]) / abs(H[0]),
        "iterations_mean": float(sol.stats.iterations_mean), "dt": T / n_steps,
        "n_steps": n_steps,
    }  # fmt: skip


def _relative_variation(C: Array) -> Array:
    """``max_j |C_j(t) - C_j(0)| / max_j |C_j(0)|`` at each save (time first)."""
    C = np.real(C).reshape(len(C), -1)
    return np.asarray(np.max(np.abs(C - C[0]), axis=1) / np.max(np.abs(C[0])))


def _kinetic(P: Array) -> Array:
    r"""Kinetic-energy spectra :math:`\sum_m l(l+1)\psi_{lm}^2` (degrees ``1..N-1``) of stream
    matrices ``P`` (the convention of :func:`isoflow.sphere.energy_spectrum`)."""
    c = sphere.to_coefficients(P)
    ls, _ = sphere.degree_order(P.shape[-1] - 1)
    return np.add.reduceat(ls * (ls + 1.0) * c**2, np.arange(1, P.shape[-1]) ** 2 - 1, axis=-1)


def _profile_ratio(run: dict[str, Any]) -> float:
    """RMS zonal wind over the second half at low latitudes over that at high latitudes."""
    u, lat = run["wind"], run["latitude"]
    rms = np.sqrt(np.mean(u[len(u) // 2 :] ** 2, axis=0))
    low = float(np.mean(rms[np.abs(lat) < LOW_LATITUDE]))
    high = float(np.mean(rms[np.abs(lat) > HIGH_LATITUDE]))
    return low / max(high, 1e-300)


def _jet_growth(run: dict[str, Any]) -> float:
    """The zonal share of kinetic energy over the second half over its initial value."""
    s = np.asarray(run["zonal_share"])
    return float(np.mean(s[len(s) // 2 :]) / max(float(s[0]), 1e-300))


class QGJets(Experiment):
    """Jets and latitude profiles of the quasi-geostrophic model at a few Lamb parameters."""

    name = "qg-jets"
    description = (
        "QG on the rotating sphere, su(64), Omega = 5, F = 0, 30, 300, h = 0.01, T = 200: jets, "
        "the zonal wind decreasing with latitude more as F grows, PV Casimirs to rounding"
    )

    def run(
        self,
        *,
        N: int | None = None,
        lambs: tuple[float, ...] = (0.0, 30.0, 300.0),
        omega: float = 5.0,
        seed: int = 1,
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
            Matrix size (default 64; 24 with ``quick``).
        lambs : tuple of float
            The Lamb parameters, increasing, the first 0 (Euler's model as the reference).
        omega : float
            The rotation :math:`\Omega`.
        seed : int
            Seed of the random initial relative potential vorticity (the same for every ``F``).
        h : float, optional
            Time step (default 0.01; 0.02 with ``quick``: IsoMP's energy error is
            :math:`O(h^2)` and grows with the vorticity of the smallest scales, so with ``N``).
        T : float, optional
            Final time (default 200; 100 with ``quick``).
        rtol : float
            Tolerance of the fixed-point iterations.

        Claims checked: the Casimirs (eigenvalues of the potential vorticity) conserved to
        rounding (relative :math:`10^{-11}`) and the energy's relative variation below
        :math:`10^{-3}` for every ``F``; jets: the zonal share of kinetic energy over the
        second half at least twice its initial value for every ``F``; the profile: the RMS
        zonal wind at latitudes below 30 degrees over that above 60 degrees grows with ``F``
        and exceeds 1.5 at the largest.

        Returns
        -------
        ExperimentResult
            ``data["runs"]``: per ``F`` the times, zonal wind (saves x latitudes), the
            latitudes, the zonal share, the first and last kinetic spectra and drifts.
        """
        start = time.perf_counter()
        N = (24 if quick else 64) if N is None else int(N)
        T = (100.0 if quick else 200.0) if T is None else float(T)
        h = (0.02 if quick else 0.01) if h is None else float(h)
        lambs = tuple(float(F) for F in lambs)
        if not (np.isfinite(h) and h > 0 and np.isfinite(T) and T > 0):
            raise ParameterError(f"qg-jets: h and T must be positive, got h={h}, T={T}")
        if len(lambs) < 2 or lambs[0] != 0.0 or any(b <= a for a, b in itertools.pairwise(lambs)):
            raise ParameterError(
                f"qg-jets: lambs must increase from 0 with at least two values, got {lambs}"
            )
        runs = [_run(N, F, omega, h, T, seed, rtol, progress) for F in lambs]
        ratios = [_profile_ratio(r) for r in runs]
        growth = [_jet_growth(r) for r in runs]
        checks: dict[str, Any] = {}
        for r, g in zip(runs, growth, strict=True):
            tag = f"F = {r['lamb']:g}"
            checks[f"casimirs_rounding_F{r['lamb']:g}"] = check(
                r["drifts"]["casimir_drift"], 1e-11, f"{tag}: PV Casimirs conserved to rounding"
            )
            checks[f"energy_bounded_F{r['lamb']:g}"] = check(
                r["drifts"]["hamiltonian_relative_drift"], 1e-3,
                f"{tag}: energy relative variation below 1e-3",
            )  # fmt: skip
            checks[f"jets_form_F{r['lamb']:g}"] = check(
                g, 2.0, f"{tag}: zonal share of kinetic energy at least doubles", below=False
            )
        checks["wind_decreases_with_latitude"] = check(
            ratios[-1], 1.5,
            f"F = {lambs[-1]:g}: RMS zonal wind below 30 deg over above 60 deg >= 1.5",
            below=False,
        )  # fmt: skip
        checks["more_so_as_F_grows"] = check(
            float(np.min(np.diff(ratios))), 0.0,
            "the low/high-latitude wind ratio grows with F", below=False,
        )  # fmt: skip
        summary = header(
            self.name,
            {"N": N, "lambs": list(lambs), "omega": omega, "seed": seed, "h": runs[0]["dt"],
             "T": T, "n_steps": runs[0]["n_steps"], "rtol": rtol,
             "initial": "random relative PV, 2 <= l <= 12, rms 1"},
            quick,
        ) | {
            "wind_ratio_low_over_high": dict(zip([f"{F:g}" for F in lambs], ratios, strict=True)),
            "zonal_share_growth": dict(zip([f"{F:g}" for F in lambs], growth, strict=True)),
            "drifts": {f"{r['lamb']:g}": r["drifts"] for r in runs},
            "iterations_mean": {f"{r['lamb']:g}": r["iterations_mean"] for r in runs},
            "checks": checks,
        }  # fmt: skip
        return self._result({"runs": runs}, summary, start)

    def figure(self, result: ExperimentResult) -> Figure:
        self._check_result(result)
        runs, p = result.data["runs"], result.summary["parameters"]
        fig = new_figure(figsize=(11, 7.5))
        axes = fig.subplots(2, 2)
        ax = axes[0, 0]
        for k, r in enumerate(runs):
            u = r["wind"]
            ax.plot(np.mean(u[len(u) // 2 :], axis=0), r["latitude"], color=f"C{k}",
                    label=f"F = {r['lamb']:g}")  # fmt: skip
        ax.axvline(0.0, color="k", lw=0.5, label="no wind")
        ax.set_xlabel(r"zonal-mean wind $\bar u$, mean over the second half")
        ax.set_ylabel("latitude (degrees)")
        ax.set_title("zonal wind profiles")
        ax.legend(fontsize=8)
        ax = axes[0, 1]
        r = runs[-1]
        lim = float(np.max(np.abs(r["wind"]))) or 1.0
        im = ax.pcolormesh(r["ts"], r["latitude"], r["wind"].T, cmap="RdBu_r", vmin=-lim,
                           vmax=lim, shading="nearest")  # fmt: skip
        fig.colorbar(im, ax=ax, label=r"$\bar u$")
        ax.set_xlabel("time $t$")
        ax.set_ylabel("latitude (degrees)")
        ax.set_title(f"zonal wind over time, F = {r['lamb']:g}")
        ax = axes[1, 0]
        for k, r in enumerate(runs):
            E = np.asarray(r["spectra"][-1])
            ls = np.arange(1, E.size + 1)
            ax.loglog(ls, np.where(E > 1e-14 * E.max(), E, np.nan), color=f"C{k}",
                      label=f"F = {r['lamb']:g}, t = {r['ts'][-1]:g}")  # fmt: skip
        E0 = np.asarray(runs[0]["spectra"][0])
        ls = np.arange(1, E0.size + 1)
        ax.loglog(ls, np.where(E0 > 1e-14 * E0.max(), E0, np.nan), "k:", label="F = 0, t = 0")
        ax.set_xlabel("degree $l$")
        ax.set_ylabel(r"kinetic energy $\sum_m l(l+1)\psi_{lm}^2$")
        ax.set_title("kinetic-energy spectra")
        ax.legend(fontsize=7)
        ax = axes[1, 1]
        for k, r in enumerate(runs):
            ax.semilogy(r["ts"], floor(r["casimir_variation"]), color=f"C{k}", lw=0.8,
                        label=f"Casimirs, F = {r['lamb']:g}")  # fmt: skip
            ax.semilogy(r["ts"], floor(np.abs(r["energy_variation"])), "--", color=f"C{k}",
                        lw=0.8, label=f"energy, F = {r['lamb']:g}")  # fmt: skip
        ax.set_ylim(1e-17, 1)
        ax.set_xlabel("time $t$")
        ax.set_ylabel("relative variation")
        ax.set_title("PV Casimirs (rounding) and energy")
        ax.legend(fontsize=7, ncol=2)
        fig.suptitle(
            f"Quasi-geostrophic jets on su({p['N']}), Omega = {p['omega']:g}, "
            f"h = {p['h']:.3g}, T = {p['T']:g} (seed {p['seed']})"
        )
        return fig


#: The experiment (call it to run it).
qg_jets = QGJets()
