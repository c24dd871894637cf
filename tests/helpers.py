"""Helpers shared by the tests: seeded random problems on every algebra and order fits."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

import isoflow as iso
from isoflow.algebras import Algebra
from isoflow.methods._base import AdvanceResult, Method
from isoflow.nonlinear import STATUS_CONVERGED

Array = NDArray[Any]

ALGEBRA_FACTORIES: dict[str, Callable[[], Algebra]] = {
    "so4": lambda: iso.algebras.so(4),
    "u3": lambda: iso.algebras.u(3),
    "su3": lambda: iso.algebras.su(3),
    "sym4": lambda: iso.algebras.sym(4),
    "herm3": lambda: iso.algebras.herm(3),
    "sp4": lambda: iso.algebras.sp(4),
    "sl2": lambda: iso.algebras.sl2(),
    "glR3": lambda: iso.algebras.gl(3),
    "glC3": lambda: iso.algebras.gl(3, complex=True),
}
#: Spaces that are their own normalizer (Lie algebras closed under the conjugate transpose).
LIE_KEYS = ("so4", "u3", "su3", "sp4", "sl2", "glR3", "glC3")


def loglog_slope(hs: Array, errors: Array) -> float:
    """Least-squares slope of ``log(error)`` against ``log(h)``."""
    return float(np.polyfit(np.log(np.asarray(hs)), np.log(np.asarray(errors)), 1)[0])


def _spd(dim: int, rng: np.random.Generator) -> Array:
    """Random SPD matrix with spectrum in about [0.5, 2.5]."""
    A = rng.standard_normal((dim, dim))
    return 0.5 * (A @ A.T / dim + np.eye(dim))


def hamiltonian_problem(
    alg: Algebra, seed: int = 0, nonlinear: bool = False
) -> iso.IsospectralProblem:
    r"""Lie–Poisson problem ``B = (grad H)^dagger`` on a Lie algebra, seeded.

    ``H = q/2`` (linear ``B``) or ``H = q/2 + q^2/8`` (nonlinear ``B``) with
    ``q = <W, S W>`` for a random SPD ``S`` in coordinates, so that level sets of ``H``
    are compact and the flow stays bounded even on non-compact algebras.
    """
    rng = np.random.default_rng(seed)
    S = _spd(alg.dim, rng)

    def q_and_grad(W: Array) -> tuple[Array, Array]:
        c = alg.to_coords(W)
        Sc = c @ S.T
        return np.einsum("...i,...i->...", c, Sc), alg.from_coords(Sc)

    def H(W: Array) -> Array:
        q, _ = q_and_grad(W)
        return 0.5 * q + (0.125 * q**2 if nonlinear else 0.0)

    def grad(W: Array) -> Array:
        q, g = q_and_grad(W)
        return g * (1.0 + 0.5 * q)[..., None, None] if nonlinear else g

    return iso.IsospectralProblem.from_hamiltonian(
        alg, H, grad, name=f"{'nonlinear' if nonlinear else 'linear'} LP on {alg.name}"
    )


def generic_problem(alg: Algebra, seed: int = 0, nonlinear: bool = False) -> iso.IsospectralProblem:
    """A non-Hamiltonian ``B`` into the normalizer: ``Pi_N(A W A^T) + K``, plus ``Pi_N(W^2 A)``."""
    norm_alg = alg.normalizer
    rng = np.random.default_rng(seed)
    n = alg.shape[-1]
    A = rng.standard_normal((n, n)) / np.sqrt(n)
    K = norm_alg.random(rng, scale=0.3)

    def B(W: Array) -> Array:
        M = A @ W @ A.T
        if nonlinear:
            M = M + W @ W @ A + np.sin(W)
        if not norm_alg.is_complex:
            M = np.real(M)
        return norm_alg.project(M) + K

    return iso.IsospectralProblem(B=B, algebra=alg, name=f"generic B on {alg.name}")


def random_problem(key: str, seed: int = 0, nonlinear: bool = False) -> iso.IsospectralProblem:
    """Hamiltonian problem on Lie algebras, generic ``B`` on sym(n) / herm(n)."""
    alg = ALGEBRA_FACTORIES[key]()
    if key in LIE_KEYS:
        return hamiltonian_problem(alg, seed, nonlinear)
    return generic_problem(alg, seed, nonlinear)


def initial_state(alg: Algebra, seed: int, norm: float = 0.8) -> Array:
    """A seeded random element of Frobenius norm ``norm``."""
    W = alg.random(seed)
    return W * (norm / float(alg.norm(W)))


def spectrum_backward_error(W0: Array, W1: Array) -> float:
    r"""Eigenvalue change of ``W1`` against ``W0``, each divided by its condition number.

    Eigenvalues are matched optimally; ``|lambda_i(W1) - lambda_i(W0)| / kappa_i`` with
    :math:`\kappa_i = \|x_i\| \|y_i\| / |y_i^H x_i|` is the size of the perturbation of
    ``W0`` that explains the change to first order (``kappa = 1`` for normal matrices), so a
    non-normal matrix is not blamed for LAPACK's conditioning.
    """
    from scipy.linalg import eig
    from scipy.optimize import linear_sum_assignment

    e0, vl, vr = eig(W0, left=True, right=True)
    kappa = np.linalg.norm(vl, axis=0) * np.linalg.norm(vr, axis=0)
    kappa /= np.abs(np.einsum("ij,ij->j", np.conj(vl), vr))
    e1 = np.linalg.eigvals(W1)
    cost = np.abs(e0[:, None] - e1[None, :])
    r, c = linear_sum_assignment(cost)
    return float(np.max(cost[r, c] / kappa[r]))


def numpy_advance(method, problem, y, h, n, state=None) -> AdvanceResult:
    """The reference of the fast-path tests: the generic Python loop over ``step`` on the
    problem without its compiled kernel."""
    return Method.advance(method, dataclasses.replace(problem, kernel=None), y, h, n, state)


#: Agreement of a fast path with the NumPy path, relative to ``max(1, max |y|)``.
FAST_TOL = 1e-13


def assert_same(a: AdvanceResult, b: AdvanceResult, iters_exact: bool = True) -> None:
    """A fast path's result ``a`` equals the NumPy path's ``b``: same accepted steps, states
    and stored offsets to :data:`FAST_TOL`, same failure (status, iterations and, for the
    members that converged, the rejected step's state) and iteration counts (exact, or within
    1% when a residual may land on the tolerance and cost one iteration more or less)."""
    assert a.n_done == b.n_done
    scale = max(1.0, float(np.max(np.abs(b.y))))
    assert a.y.shape == b.y.shape
    assert np.max(np.abs(a.y - b.y)) <= FAST_TOL * scale
    if iters_exact:
        assert a.iterations_total == b.iterations_total
        assert a.iterations_max == b.iterations_max
    else:
        assert abs(a.iterations_total - b.iterations_total) <= max(2, b.iterations_total // 100)
    assert (a.failure is None) == (b.failure is None)
    if a.failure is not None and b.failure is not None:
        np.testing.assert_array_equal(a.failure.status, b.failure.status)
        np.testing.assert_array_equal(a.failure.iterations, b.failure.iterations)
        ok = np.asarray(b.failure.status == STATUS_CONVERGED)
        if ok.any():  # the members that converged took the same step
            assert np.max(np.abs(a.failure.y[ok] - b.failure.y[ok])) <= FAST_TOL * scale
    if b.state is None:
        assert a.state is None
    else:
        assert len(a.state) == len(b.state) and a.state[0] == b.state[0]
        for x, y in zip(a.state[1:], b.state[1:], strict=True):
            assert x.shape == y.shape
            assert np.max(np.abs(x - y)) <= FAST_TOL * scale
