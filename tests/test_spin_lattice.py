"""The spin-lattice model: its compiled field against independent formulas and the flow's
invariants, on the compiled path and the NumPy path."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import isoflow as iso
from helpers import assert_same_run, compiled_and_numpy


def _dense_gradient(w: np.ndarray, L: tuple[int, int], J: float, delta: float, h: np.ndarray):
    """grad H by brute force over the bond list (an independent statement of the model)."""
    L1, L2 = L
    D = np.array([1.0, 1.0, 1.0 + delta])
    g = np.zeros_like(w)
    for a in range(L1):
        for b in range(L2):
            i = a * L2 + b
            for j in (((a + 1) % L1) * L2 + b, a * L2 + (b + 1) % L2):  # each bond once
                g[i] += J * D * w[j]
                g[j] += J * D * w[i]
    return g - h


def test_field_is_minus_the_gradient_of_H() -> None:
    L, J, delta, h = (3, 4), -0.7, 0.4, np.array([0.1, -0.2, 0.3])
    prob, w = iso.models.spin_lattice(L, J=J, anisotropy=delta, field=h, seed=3)
    grad = _dense_gradient(w, L, J, delta, h)
    assert np.max(np.abs(prob.B(w) + grad)) <= 1e-14
    # and grad H is the derivative of the Hamiltonian (central differences)
    eps = 1e-6
    for i, a in ((0, 0), (5, 2), (11, 1)):
        dw = np.zeros_like(w)
        dw[i, a] = eps
        fd = (prob.hamiltonian(w + dw) - prob.hamiltonian(w - dw)) / (2 * eps)
        assert fd == pytest.approx(grad[i, a], abs=1e-8)


@pytest.mark.parametrize("method", [iso.IsoMP(), iso.SphericalMidpoint()], ids=["isomp", "smm"])
def test_compiled_path_equals_numpy_path(method: iso.Method) -> None:
    prob, w0 = iso.models.spin_lattice((4, 5), J=1.0, anisotropy=0.3, field=(0, 0, 0.5), seed=1)
    a, b = compiled_and_numpy(prob, method, w0, 0.05, 30, 5, chunks=(10, 20))
    assert a.label.startswith("compiled")
    assert_same_run(a, b)


@pytest.mark.parametrize("method", [iso.IsoMP(), iso.SphericalMidpoint()], ids=["isomp", "smm"])
def test_invariants(method: iso.Method) -> None:
    """|w_i| and the total spin (isotropic, no field) to the solver's tolerance; H bounded,
    O(h^2)."""
    prob, w0 = iso.models.spin_lattice((6, 6), J=-1.0, seed=2)
    n = 2000
    sol = iso.solve(prob, method, w0, dt=0.05, n_steps=n, save_every=20)
    d = sol.diagnostics
    assert sol.stats.runner.startswith("compiled")
    # each step keeps |w_i| up to the fixed point's tolerance (rtol = 1e-14 of ||W||): the
    # errors add up like a random walk, sqrt(n) * 1e-14 * ||W|| / |w_i| ~ 3e-12 at most
    assert float(np.max(d.casimir_drift)) <= np.sqrt(n) * 1e-14 * np.sqrt(36)
    assert float(np.max(d.invariant_drift["total_spin"])) <= 1e-12
    assert float(np.max(d.hamiltonian_relative_drift)) <= 1e-2
    # second order: the energy error shrinks by ~4 when h halves
    errs = []
    for h in (0.1, 0.05):
        s = iso.solve(prob, method, w0, dt=h, t1=5.0, save_every=10)
        errs.append(float(np.max(s.diagnostics.hamiltonian_drift)))
    assert 3.0 <= errs[0] / errs[1] <= 5.5


def test_field_and_anisotropy_keep_only_Sz() -> None:
    prob, w0 = iso.models.spin_lattice((5, 5), anisotropy=0.8, field=(0, 0, 0.7), seed=4)
    assert set(prob.invariants) == {"total_spin_z"} and set(prob.observables) == {"total_spin"}
    sol = iso.solve(prob, iso.IsoMP(), w0, dt=0.05, n_steps=400, save_every=10)
    S = sol.diagnostics.observables["total_spin"]
    assert np.max(np.abs(S[:, 2] - S[0, 2])) <= 1e-12  # S_z conserved
    assert np.max(np.abs(S[:, :2] - S[0, :2])) > 1e-3  # S_x, S_y precess
    assert float(np.max(sol.diagnostics.invariant_drift["total_spin_z"])) <= 1e-12
    assert np.array_equal(sol.diagnostics.invariants["total_spin_z"], S[:, 2])


def test_isotropic_coupling_in_a_field_keeps_S_along_the_field() -> None:
    """Delta = 0, h oblique: dS/dt = -S x h turns S about h, keeping S . h (to rounding) and
    moving its other components."""
    h = np.array([0.6, -0.3, 0.5])
    prob, w0 = iso.models.spin_lattice((4, 5), field=h, seed=5)
    assert set(prob.invariants) == {"total_spin_along_field"}
    assert not prob.energy_changes
    sol = iso.solve(prob, iso.IsoMP(), w0, dt=0.05, n_steps=400, save_every=10)
    d = sol.diagnostics
    S = d.observables["total_spin"]
    assert float(np.max(d.invariant_drift["total_spin_along_field"])) <= 1e-12
    assert np.allclose(d.invariants["total_spin_along_field"], S @ h / np.linalg.norm(h),
                       rtol=0, atol=1e-13)  # fmt: skip
    across = S - np.outer(S @ h, h) / (h @ h)
    assert np.max(np.abs(across - across[0])) > 1e-2  # the rest precesses
    # and an anisotropy with an oblique field keeps no part of S
    prob, _ = iso.models.spin_lattice((4, 5), field=h, anisotropy=0.4, seed=5)
    assert not prob.invariants and set(prob.observables) == {"total_spin"}


def test_damping_lowers_the_energy_and_keeps_the_lengths() -> None:
    """Gilbert damping at T = 0: H is a Lyapunov function (never rises, checked step by saved
    step), the |w_i| stay at rounding, the total spin is an observable, and the diagnostics
    say the energy changes by design."""
    prob, w0 = iso.models.spin_lattice((4, 4), J=-1.0, field=(0, 0, 0.3), damping=0.2, seed=3)
    assert prob.energy_changes and not prob.forced_or_dissipative
    assert not prob.invariants and set(prob.observables) == {"total_spin"}
    sol = iso.solve(prob, iso.IsoMP(), w0, dt=0.05, n_steps=400, save_every=5)
    d = sol.diagnostics
    assert d.energy_changes
    H = np.asarray(d.hamiltonian)
    assert H[-1] < H[0] - 1.0  # the damping removes energy
    assert float(np.max(d.lyapunov_max_decrease)) <= 1e-12 * abs(H[0])
    assert float(np.max(d.casimir_drift)) <= 1e-12


def test_ensemble_and_bad_parameters() -> None:
    prob, w0 = iso.models.spin_lattice((3, 3), seed=0)
    ens = np.stack([w0, np.roll(w0, 1, axis=0)])
    sol = iso.solve(prob, iso.IsoMP(), ens, dt=0.1, n_steps=20)
    one = iso.solve(prob, iso.IsoMP(), ens[1], dt=0.1, n_steps=20)
    assert np.array_equal(sol.ys[-1, 1], one.ys[-1])
    plain = dataclasses.replace(prob, kernel=None)
    assert iso.solve(plain, iso.IsoMP(), w0, dt=0.1, n_steps=2).stats.runner == "NumPy"
    with pytest.raises(iso.ParameterError, match="shape"):
        iso.models.spin_lattice((2, 5))
    with pytest.raises(iso.ShapeError, match="field"):
        iso.models.spin_lattice((3, 3), field=(1.0, 2.0))
    with pytest.raises(iso.NonFiniteError):
        iso.models.spin_lattice((3, 3), J=np.nan)
    with pytest.raises(iso.ParameterError, match="initial"):
        iso.models.spin_lattice((3, 3), initial="striped")
