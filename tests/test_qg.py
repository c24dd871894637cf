"""The quasi-geostrophic model on the sphere (issue 21, item 3): the elliptic operator and its
solve, the limits F -> 0 (Euler), the sign and scale of F and kappa, and the conservation laws.
The solve's O(N^2) time is measured by benchmark 16 (speed is not asserted in tests)."""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso
from isoflow import sphere
from isoflow.models._qg_sphere import qg_operator, quantized_z2


@pytest.mark.parametrize(("N", "lamb", "kappa"), [(9, 30.0, 0.0), (32, 100.0, 2.0), (17, 0.0, 0.5)])
def test_the_solve_inverts_the_operator_to_rounding(N: int, lamb: float, kappa: float) -> None:
    op = qg_operator(N, lamb, kappa)
    W = iso.algebras.u(N).random(seed=N)
    P = op.solve(W)
    assert float(np.abs(op.apply(P) - W).max()) <= 1e-13 * float(np.abs(W).max())


def test_quantized_z2_is_the_projection_of_z2() -> None:
    """``T(z^2)``: trace ``N/3`` (the mean of ``z^2`` on the sphere is ``1/3``), symmetric about
    the equator, and close to :math:`(\\hbar J_3)^2` for large ``N``."""
    N = 40
    z2 = quantized_z2(N)
    assert z2.sum() == pytest.approx(N / 3.0, rel=1e-13)
    assert np.allclose(z2, z2[::-1], rtol=0, atol=1e-14)
    X3 = sphere.hbar(N) * (np.arange(N) - 0.5 * (N - 1))
    assert float(np.abs(z2 - X3**2).max()) < 0.1


@pytest.mark.parametrize("lamb", [3.0, 20.0])
def test_operator_converges_to_laplacian_minus_F_z2(lamb: float) -> None:
    """:math:`A\\,T(\\psi) \\to T(\\Delta\\psi - F z^2\\psi)` for :math:`\\psi = z^3`
    (colatitude :math:`\\theta`, :math:`z = \\cos\\theta`): the sign and the scale of ``F``."""

    def psi(th: np.ndarray, ph: np.ndarray) -> np.ndarray:
        return np.cos(th) ** 3

    def target(th: np.ndarray, ph: np.ndarray) -> np.ndarray:
        z = np.cos(th)
        return 6 * z - 12 * z**3 - lamb * z**5  # Delta z^3 = 6z - 12z^3

    errs = []
    for N in (16, 32, 64):
        op = qg_operator(N, lamb)
        got = op.apply(sphere.vorticity_from_function(psi, N))
        want = sphere.vorticity_from_function(target, N)
        errs.append(float(np.linalg.norm(got - want)) / float(np.linalg.norm(want)))
    assert errs[-1] < 0.02
    assert errs[0] / errs[-1] > 3.0  # converging


def test_helmholtz_rossby_waves_travel_at_2_omega_over_lambda_plus_kappa2() -> None:
    """``F = 0``, ``kappa > 0``: a pure degree-``l`` wave is exact, its pattern turns westward
    at :math:`2\\Omega/(l(l+1) + \\kappa^2)` (Euler's speed with :math:`\\lambda + \\kappa^2`);
    IsoMP's O(h^2) error is removed by Richardson extrapolation."""
    N, deg, m, Om, kappa = 12, 4, 3, 1.0, 1.5
    nu = -2 * Om / (deg * (deg + 1) + kappa**2)
    c = np.zeros(N * N - 1)
    c[sphere.lm_index(deg, m)] = 0.8
    c[sphere.lm_index(deg, -m)] = -0.5
    prob, Q0 = iso.models.qg_sphere(N=N, omega=Om, initial=c, deformation_radius=1 / kappa)
    F = iso.models.coriolis_matrix(N, Om)
    a0 = 0.8 + 0.5j
    speeds = []
    for h in (0.02, 0.01):
        sol = iso.solve(prob, iso.IsoMP(), Q0, dt=h, t1=1.0, save_every=1)
        co = sphere.to_coefficients(sol.ys - F, lmax=deg)
        a = co[:, sphere.lm_index(deg, m)] - 1j * co[:, sphere.lm_index(deg, -m)]
        phase = np.unwrap(np.angle(a / a0))
        speeds.append(-np.polyfit(sol.ts, phase, 1)[0] / m)
    extrapolated = (4 * speeds[1] - speeds[0]) / 3
    assert abs(extrapolated - nu) <= 2e-5 * abs(nu)


def test_F_zero_is_euler_bit_for_bit_and_small_F_tends_to_it() -> None:
    pe, Qe = iso.models.euler_sphere(N=12, omega=1.0, seed=1)
    a = iso.solve(pe, iso.IsoMP(), Qe, dt=0.05, n_steps=10)
    pq, Qq = iso.models.qg_sphere(N=12, omega=1.0, seed=1)
    b = iso.solve(pq, iso.IsoMP(), Qq, dt=0.05, n_steps=10)
    assert a.ys.tobytes() == b.ys.tobytes()
    gaps = []
    for lamb in (1e-6, 1e-4):
        pf, Qf = iso.models.qg_sphere(N=12, omega=1.0, seed=1, lamb=lamb)
        c = iso.solve(pf, iso.IsoMP(), Qf, dt=0.05, n_steps=10)
        gaps.append(float(np.abs(c.ys - a.ys).max()))
    assert gaps[0] < 1e-6 and gaps[1] / gaps[0] == pytest.approx(100.0, rel=0.05)  # O(F)


def test_casimirs_of_the_potential_vorticity_at_rounding_and_energy_bounded() -> None:
    prob, Q0 = iso.models.qg_sphere(N=24, lamb=50.0, omega=2.0, seed=3, deformation_radius=2.0)
    sol = iso.solve(prob, iso.IsoMP(), Q0, dt=0.02, n_steps=2000, save_every=100)
    assert "compiled" in sol.stats.runner
    assert float(np.max(sol.diagnostics.casimir_drift)) < 1e-12
    assert sol.diagnostics.hamiltonian_relative_drift is not None
    assert float(np.max(sol.diagnostics.hamiltonian_relative_drift)) < 1e-3
    u = sol.diagnostics.observables["zonal_wind"]
    assert u.shape == (21, 65)


def test_zonal_wind_of_a_solid_body_rotation() -> None:
    """:math:`\\psi = -U z` is a solid-body rotation with eastward wind
    :math:`\\partial_\\theta\\psi = U\\sin\\theta`."""
    N, U = 10, 0.7
    P = sphere.vorticity_from_function(lambda th, ph: -U * np.cos(th), N)
    theta = np.linspace(0.1, 3.0, 7)
    assert np.allclose(_zonal(P, theta), U * np.sin(theta), rtol=0, atol=1e-13)


def _zonal(P: np.ndarray, theta: np.ndarray) -> np.ndarray:
    from isoflow.models._qg_sphere import zonal_wind

    return zonal_wind(P, theta)


def test_bad_parameters_are_refused_in_one_line() -> None:
    with pytest.raises(iso.ParameterError, match="lamb must be >= 0"):
        iso.models.qg_sphere(N=8, lamb=-1.0)
    with pytest.raises(iso.ParameterError, match="deformation_radius must be > 0"):
        iso.models.qg_sphere(N=8, deformation_radius=0.0)
    with pytest.raises(iso.ParameterError, match="lamb must be finite"):
        iso.models.qg_sphere(N=8, lamb=float("inf"))


def test_qg_energy_budget_closes_with_dissipation_and_forcing() -> None:
    """The split step on the QG model (rotating, ``F > 0``): dissipation and forcing act on the
    relative potential vorticity, and ``E(T) - E(0) = int (injection - dissipation) dt`` to the
    splitting and quadrature error, ``O(h^2)`` (a quarter when ``h`` halves)."""
    F = 0.3 * iso.algebras.su(8).random(seed=6)
    prob, Q0 = iso.models.qg_sphere(
        N=8, lamb=20.0, omega=1.5, seed=7, viscosity=0.02, drag=0.1, forcing=F
    )
    T = 2.0

    def residual(n: int) -> float:
        sol = iso.solve(prob, iso.Strang(), Q0, dt=T / n, n_steps=n, progress=False)
        assert "compiled" in sol.stats.runner
        d = sol.diagnostics
        assert d.hamiltonian is not None
        rate = d.observables["energy_injection"] - d.observables["energy_dissipation"]
        gained = float(np.trapezoid(rate, sol.ts))
        return abs(float(d.hamiltonian[-1] - d.hamiltonian[0]) - gained) / abs(gained)

    r1, r2 = residual(40), residual(80)
    assert r1 < 1e-3
    assert 3.0 < r1 / r2 < 5.0


def test_qg_drag_relaxes_to_rest_not_to_zero_potential_vorticity() -> None:
    r"""Drag alone on the rotating QG model acts on the relative potential vorticity
    :math:`Q_r = Q - F_\Omega`, not on :math:`Q`: the flow has :math:`\frac{d}{dt}\|Q_r\|^2 =
    2\langle A\Psi, [\Psi, F_\Omega]\rangle/\hbar - 2\alpha\|Q_r\|^2` and the first term vanishes
    (``A`` is self-adjoint and commutes with :math:`\mathrm{ad}_{J_3}`, it keeps each diagonal),
    so :math:`\|Q_r\|` decays exactly as :math:`e^{-\alpha t}` (to the step's error) and the
    state relaxes to rest. Dragging ``Q`` itself would fail this by far."""
    prob, Q0 = iso.models.qg_sphere(N=8, lamb=20.0, omega=1.5, seed=2, drag=0.5)
    Fo = iso.models.coriolis_matrix(8, 1.5)
    sol = iso.solve(prob, iso.Strang(), Q0, dt=0.05, n_steps=200, save_every=200, progress=False)
    rel0 = float(np.linalg.norm(Q0 - Fo))
    rel = float(np.linalg.norm(sol.ys[-1] - Fo))
    assert rel == pytest.approx(rel0 * np.exp(-0.5 * 10.0), rel=1e-6)


def test_qg_band_forcing_injects_the_requested_rate_of_qg_energy() -> None:
    """``energy_rate`` is the mean injection of the model's own energy: the QG energy of a
    unit harmonic is :math:`-\\langle e, A^{-1}e\\rangle < 1/\\lambda_l` (the stretching term),
    so the QG model's band amplitude is larger than Euler's for the same rate."""
    kw = {"N": 8, "omega": 1.0, "drag": 0.1, "forcing_band": (3, 1), "energy_rate": 0.1}
    pq, Qq = iso.models.qg_sphere(lamb=50.0, **kw)
    pe, We = iso.models.euler_sphere(**kw)
    assert float(pq.observables["energy_injection"](Qq)) == pytest.approx(0.1, rel=1e-12)
    assert float(pe.observables["energy_injection"](We)) == pytest.approx(0.1, rel=1e-12)
    sigma_q = pq.parameters["forcing"][0]["sigma_rms"]
    sigma_e = pe.parameters["forcing"][0]["sigma_rms"]
    assert sigma_q > 1.3 * sigma_e
