r"""The step map of IsoMP is a Poisson map for the Lie–Poisson structure; RK4 is not.

With an orthonormal basis ``e_a`` of ``g = so(n)`` (identified with ``g*`` by the Frobenius
pairing) the Lie–Poisson tensor in coordinates is ``P_ab(W) = <W, [e_a, e_b]>``. A map ``Phi``
is Poisson iff ``D Phi(W) P(W) D Phi(W)^T = P(Phi(W))``. (The overall sign and scale of ``P``
drop out of this identity.) ``D Phi`` is computed by central finite differences.
"""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso


def _poisson_tensor(alg, W: np.ndarray) -> np.ndarray:
    basis = alg.from_coords(np.eye(alg.dim))
    br = basis[:, None] @ basis[None, :] - basis[None, :] @ basis[:, None]
    return alg.inner(W, br)


def _jacobian(alg, step_map, W: np.ndarray, eps: float = 1e-5) -> np.ndarray:
    c0 = alg.to_coords(W)
    cols = []
    for a in range(alg.dim):
        dc = np.zeros(alg.dim)
        dc[a] = eps
        plus = alg.to_coords(step_map(alg.from_coords(c0 + dc)))
        minus = alg.to_coords(step_map(alg.from_coords(c0 - dc)))
        cols.append((plus - minus) / (2 * eps))
    return np.stack(cols, axis=-1)


def _problem(n: int) -> iso.IsospectralProblem:
    """A non-quadratic Hamiltonian on so(n): rigid body plus a quartic term."""
    alg = iso.algebras.so(n)
    rng = np.random.default_rng(n)
    d = rng.uniform(0.5, 2.0, size=n)
    D = 0.5 * (d[:, None] + d[None, :])

    def H(W):
        q = 0.5 * np.sum(D * W * W, axis=(-2, -1))
        return q + 0.25 * q**2

    def grad(W):
        q = 0.5 * np.sum(D * W * W, axis=(-2, -1))
        return (1.0 + q)[..., None, None] * D * W

    return iso.IsospectralProblem.from_hamiltonian(alg, H, grad)


def _defect(prob: iso.IsospectralProblem, method: iso.Method, h: float) -> float:
    alg = prob.algebra
    W0 = alg.random(3)
    W0 *= 1.0 / alg.norm(W0)

    def step_map(W):
        return iso.step(prob, method, W, h, validate=False)

    J = _jacobian(alg, step_map, W0)
    lhs = J @ _poisson_tensor(alg, W0) @ J.T
    rhs = _poisson_tensor(alg, step_map(W0))
    return float(np.max(np.abs(lhs - rhs)))


@pytest.mark.parametrize("n", [3, 4])
def test_isomp_is_lie_poisson_rk4_and_midpoint_are_not(n: int) -> None:
    prob = _problem(n)
    h = 0.5  # large enough that RK4's O(h^5) defect is far above finite-difference noise
    tight = iso.IsoMP(solver=iso.FixedPoint(rtol=1e-15, stall_rtol=1e-13))
    assert _defect(prob, tight, h) <= 1e-9  # measured ~1e-11 (finite differences)
    assert _defect(prob, iso.RK4(), h) >= 1e-7  # measured 6e-7 (so(3)), 3e-5 (so(4))
    assert _defect(prob, iso.ClassicalMidpoint(solver=iso.FixedPoint(rtol=1e-15)), h) >= 1e-6
