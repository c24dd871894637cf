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
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import models, sphere
from .._errors import ParameterError
from .._solve import solve
from ..methods import IsoMP
from ..nonlinear import FixedPoint
from ._common import ExperimentResult, check, header

__all__ = ["euler_sphere"]

Array = NDArray[Any]

#: Degrees whose energy counts as "large scale" in the condensation check.
LARGE_SCALE_LMAX = 3


def euler_sphere(
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
    r"""Long IsoMP run of the Euler equations on the sphere from random data: condensation.

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
        prob, IsoMP(solver=FixedPoint(rtol=rtol)), Q0, dt=dt, n_steps=n_steps,
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
        "euler-sphere",
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
    return ExperimentResult("euler-sphere", data, summary)
