"""The spherical midpoint method (McLachlan–Modin–Verdier) on (R^3, x)^N."""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso
from isoflow.methods.spherical_midpoint import _spherical_point_jvp, spherical_point

TIGHT = iso.FixedPoint(rtol=1e-16)


def _rigid_body(N: int = 1):
    """N uncoupled free rigid bodies, H = 1/2 sum w_i . I^{-1} w_i (quadratic, per particle)."""
    alg = iso.algebras.so3_vectors(N)
    inv_inertia = np.array([1.0, 0.5, 1.0 / 3.0])

    def H(W):
        return 0.5 * np.sum(inv_inertia * W * W, axis=(-2, -1))

    return iso.IsospectralProblem.from_hamiltonian(alg, H, lambda W: inv_inertia * W)


def _quartic_problem(N: int = 4):
    """A non-quadratic Hamiltonian coupling the particles, with its exact B_jvp."""
    alg = iso.algebras.so3_vectors(N)
    A = np.random.default_rng(0).standard_normal((3, 3))
    A = (A + A.T) / (2.0 * N * np.linalg.norm(A))  # keeps h ||B|| moderate for |w_i| ~ 1

    def H(W):
        S = np.sum(W, axis=-2)
        return 0.25 * np.einsum("...i,ij,...j->...", S, A, S) ** 2 + np.sum(W[..., 2] ** 3, -1)

    def grad(W):
        S = np.sum(W, axis=-2)
        q = np.einsum("...i,ij,...j->...", S, A, S)
        g = (q[..., None] * (S @ A))[..., None, :] * np.ones_like(W)
        g[..., 2] += 3 * W[..., 2] ** 2
        return g

    def B_jvp(W, dW):  # B = -grad
        S, dS = np.sum(W, axis=-2), np.sum(dW, axis=-2)
        q = np.einsum("...i,ij,...j->...", S, A, S)
        dq = 2 * np.einsum("...i,ij,...j->...", dS, A, S)
        dg = (dq[..., None] * (S @ A) + q[..., None] * (dS @ A))[..., None, :] * np.ones_like(W)
        dg[..., 2] += 6 * W[..., 2] * dW[..., 2]
        return -dg

    return iso.IsospectralProblem.from_hamiltonian(alg, H, grad, B_jvp=B_jvp)


def test_rejects_other_spaces():
    for alg in (iso.algebras.sl2_vectors(2), iso.algebras.so(3)):
        prob = iso.IsospectralProblem(B=lambda W: -W, algebra=alg)
        W0 = alg.random(seed=0)
        with pytest.raises(iso.UnsupportedAlgebraError, match="so3_vectors"):
            iso.step(prob, iso.SphericalMidpoint(), W0, 0.1)
        with pytest.raises(TypeError):
            iso.solve(prob, iso.SphericalMidpoint(), W0, dt=0.1, n_steps=1)
        with pytest.raises(iso.IsoflowError):
            iso.solve(prob, iso.SphericalMidpoint(), W0, dt=0.1, n_steps=1)
    with pytest.raises(ValueError):
        iso.SphericalMidpoint(initial_guess="zero")


def test_the_step_satisfies_the_defining_equations():
    prob = _quartic_problem()
    w0 = prob.algebra.random(seed=1)
    h = 0.05
    w1 = iso.step(prob, iso.SphericalMidpoint(solver=TIGHT), w0, h)
    n0, n1 = np.linalg.norm(w0, axis=-1), np.linalg.norm(w1, axis=-1)
    s = w0 + w1
    m = np.sqrt(n0 * n1)[:, None] * s / np.linalg.norm(s, axis=-1)[:, None]
    assert np.abs(w1 - (w0 + h * np.cross(prob.B(m), m))).max() <= 1e-14
    assert np.abs(n1 - n0).max() <= 1e-14


def test_conserves_every_per_particle_quadratic_invariant():
    """The rigid-body energy w^T A w is conserved exactly by SMM, only nearly by IsoMP."""
    prob = _rigid_body(3)
    w0 = prob.algebra.random(seed=2)
    smm = iso.solve(prob, iso.SphericalMidpoint(), y0=w0, dt=0.1, t1=100.0)
    isomp = iso.solve(prob, iso.IsoMP(), y0=w0, dt=0.1, t1=100.0)
    assert smm.diagnostics.hamiltonian_relative_drift <= 1e-12  # measured 2e-13
    assert isomp.diagnostics.hamiltonian_relative_drift >= 1e-6  # measured ~1e-4
    assert smm.diagnostics.casimir_drift.max() <= 1e-12


def test_equals_classical_midpoint_for_hamiltonians_constant_on_rays():
    """Paper's remark: SMM = classical midpoint when H is constant on rays (B(w) . w = 0), and
    so is IsoMP (the h^2 term vanishes)."""
    alg = iso.algebras.so3_vectors(3)
    a = np.array([0.3, -1.0, 0.6])

    def H(W):
        return np.sum((W @ a) ** 2 / np.sum(W * W, axis=-1), axis=-1)

    def grad(W):
        r2 = np.sum(W * W, axis=-1)[..., None]
        p = (W @ a)[..., None]
        return 2 * p * a / r2 - 2 * p**2 * W / r2**2

    prob = iso.IsospectralProblem.from_hamiltonian(alg, H, grad)
    w0 = alg.random(seed=3)
    assert np.abs(np.sum(prob.B(w0) * w0, axis=-1)).max() <= 1e-15
    steps = {
        m.name: iso.step(prob, m, w0, 0.2)
        for m in (
            iso.SphericalMidpoint(solver=TIGHT),
            iso.ClassicalMidpoint(solver=TIGHT),
            iso.IsoMP(solver=TIGHT),
        )
    }
    cm = steps["classical midpoint"]
    assert np.abs(steps["spherical midpoint"] - cm).max() <= 1e-14
    assert np.abs(steps["IsoMP"] - cm).max() <= 1e-14


def test_symmetric():
    prob = _quartic_problem()
    w0 = prob.algebra.random(seed=4)
    m = iso.SphericalMidpoint(solver=TIGHT, initial_guess="state")
    w1 = iso.step(prob, m, w0, 0.1)
    assert np.abs(iso.step(prob, m, w1, -0.1) - w0).max() <= 1e-14


def test_newton_with_exact_jacobian_agrees_with_fixed_point():
    prob = _quartic_problem()
    w0 = prob.algebra.random(seed=5)
    a = iso.step(prob, iso.SphericalMidpoint(solver=TIGHT), w0, 0.1)
    b, info = iso.step(prob, iso.SphericalMidpoint(solver=iso.Newton()), w0, 0.1, return_info=True)
    assert np.abs(a - b).max() <= 1e-14
    assert int(info.iterations) <= 6
    # the exact derivative of m(M) against central differences
    rng = np.random.default_rng(6)
    W = rng.standard_normal((5, 3))
    M = W + 0.1 * rng.standard_normal((5, 3))
    dM = rng.standard_normal((5, 3))
    m, dm = _spherical_point_jvp(W, M, dM)
    eps = 1e-6
    fd = (spherical_point(W, M + eps * dM) - spherical_point(W, M - eps * dM)) / (2 * eps)
    assert np.array_equal(m, spherical_point(W, M))
    assert np.abs(dm - fd).max() <= 1e-8


def test_particle_at_the_origin_stays_there():
    prob = _quartic_problem(3)
    w0 = prob.algebra.random(seed=7)
    w0[1] = 0.0
    sol = iso.solve(prob, iso.SphericalMidpoint(), y0=w0, dt=0.05, n_steps=20)
    assert np.all(np.isfinite(sol.ys))
    assert np.array_equal(sol.y_final[1], np.zeros(3))


def test_ensemble_matches_single_runs():
    prob = _quartic_problem(3)
    W0 = prob.algebra.random(seed=8, batch=(3,))
    sol = iso.solve(prob, iso.SphericalMidpoint(), W0, dt=0.05, n_steps=10, diagnostics=False)
    for k in range(3):
        one = iso.solve(prob, iso.SphericalMidpoint(), W0[k], dt=0.05, n_steps=10)
        assert np.abs(sol.y_final[k] - one.y_final).max() <= 1e-13
