"""Algebra operations: structure, projections, bases, products (property-based where it helps)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import isoflow as iso
from helpers import ALGEBRA_FACTORIES, LIE_KEYS
from isoflow.algebras import Algebra

ALGEBRAS = ALGEBRA_FACTORIES
LIE = list(LIE_KEYS)

EXPECTED_DIM = {
    "so4": 6,
    "u3": 9,
    "su3": 8,
    "sym4": 10,
    "herm3": 9,
    "sp4": 10,
    "sl2": 3,
    "glR3": 9,
    "glC3": 18,
}

seeds = st.integers(min_value=0, max_value=2**32 - 1)
TOL = 1e-13


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


@pytest.mark.parametrize("key", ALGEBRAS)
def test_dimension_and_orthonormal_basis(key: str) -> None:
    alg = ALGEBRAS[key]()
    assert alg.dim == EXPECTED_DIM[key]
    basis = alg.from_coords(np.eye(alg.dim))  # (dim, n, n)
    gram = alg.inner(basis[:, None], basis[None, :])
    np.testing.assert_allclose(gram, np.eye(alg.dim), atol=1e-15)
    assert np.all(alg.distance(basis) <= 1e-15)


@pytest.mark.parametrize("key", ALGEBRAS)
@given(seed=seeds)
def test_projection_is_idempotent_and_orthogonal(key: str, seed: int) -> None:
    alg = ALGEBRAS[key]()
    rng = np.random.default_rng(seed)
    Y = rng.standard_normal((2, *alg.shape))
    if alg.is_complex:
        Y = Y + 1j * rng.standard_normal((2, *alg.shape))
    P = alg.project(Y)
    assert _rel(alg.project(P), P) <= TOL
    # the residual is orthogonal to V: <Y - P, e_a> = 0 for every basis element
    basis = alg.from_coords(np.eye(alg.dim))
    assert np.max(np.abs(alg.inner(basis[None], (Y - P)[:, None]))) <= 1e-13
    np.testing.assert_allclose(alg.to_coords(Y), alg.to_coords(P), atol=1e-13)


@pytest.mark.parametrize("key", ALGEBRAS)
@given(seed=seeds)
def test_distance_and_norm_are_those_of_the_projection(key: str, seed: int) -> None:
    """``distance(Y) = |Y - P(Y)|`` and ``norm(Y) = |Y|`` (Frobenius) for any ``Y``, whatever
    arithmetic a space uses for them (the matrix spaces' one-temporary forms)."""
    alg = ALGEBRAS[key]()
    rng = np.random.default_rng(seed)
    Y = rng.standard_normal((3, 2, *alg.shape))
    if alg.is_complex:
        Y = Y + 1j * rng.standard_normal((3, 2, *alg.shape))
    R = (Y - alg.project(Y)).reshape(3, 2, -1)
    want = np.sqrt(np.sum(np.abs(R) ** 2, axis=-1))
    assert np.max(np.abs(alg.distance(Y) - want)) <= 1e-14 * np.max(np.abs(Y))
    norm = np.sqrt(np.sum(np.abs(Y.reshape(3, 2, -1)) ** 2, axis=-1))
    assert np.max(np.abs(alg.norm(Y) - norm)) <= 1e-14 * np.max(np.abs(Y))


@pytest.mark.parametrize("name", ["so", "sym", "u", "herm", "su"])
def test_compiled_distance_of_large_arrays_is_that_of_the_projection(name: str) -> None:
    """From ``_COMPILED_DISTANCE_SIZE`` entries a member on, the matrix spaces sum the distance
    in one compiled pass: the same ``|Y - P(Y)|`` (to 1e-14 of it) for every member,
    also for members exactly in the space (distance 0) and a traceless space's trace part."""
    from isoflow.algebras import _base

    n = int(np.ceil(np.sqrt(_base._COMPILED_DISTANCE_SIZE)))
    alg = getattr(iso.algebras, name)(n)
    assert alg.transpose_sign is not None
    rng = np.random.default_rng(7)
    M = 8
    Y = rng.standard_normal((M, *alg.shape))
    if alg.is_complex:
        Y = Y + 1j * rng.standard_normal((M, *alg.shape))
    Y[:3] = alg.project(Y[:3])  # in the space
    Y[3] += 2.5 * np.eye(n)  # off su's trace only (su) or in the space's direction
    want = np.sqrt(np.sum(np.abs((Y - alg.project(Y)).reshape(M, -1)) ** 2, axis=-1))
    got = alg.distance(Y.reshape(M // 4, 4, *alg.shape))  # leading axes kept
    assert got.shape == (M // 4, 4)
    assert np.max(np.abs(got.reshape(-1) - want)) <= 1e-14 * (np.max(want) + np.max(np.abs(Y)))
    assert np.all(got.reshape(-1)[:3] <= 1e-15 * np.max(np.abs(Y)))


@pytest.mark.parametrize("key", ALGEBRAS)
@given(seed=seeds)
def test_coordinates_round_trip_and_membership(key: str, seed: int) -> None:
    alg = ALGEBRAS[key]()
    W = alg.random(seed, batch=(3,))
    assert np.all(alg.contains(W))
    np.testing.assert_allclose(alg.from_coords(alg.to_coords(W)), W, atol=1e-14)
    # a generic perturbation off V is detected
    off = np.zeros(alg.shape)
    off[0, 0] = off[0, 1] = 0.1  # neither (skew-)symmetric, (skew-)Hermitian, traceless nor in sp
    if key in ("glR3", "glC3"):
        return  # everything is in gl(n)
    assert not np.any(alg.contains(W + off))


@pytest.mark.parametrize("key", LIE)
@given(seed=seeds)
def test_bracket_antisymmetry_jacobi_closure(key: str, seed: int) -> None:
    alg = ALGEBRAS[key]()
    rng = np.random.default_rng(seed)
    A, B, C = (alg.random(rng) for _ in range(3))
    AB = alg.bracket(A, B)
    assert _rel(AB, -alg.bracket(B, A)) <= TOL
    jacobi = (
        alg.bracket(A, alg.bracket(B, C))
        + alg.bracket(B, alg.bracket(C, A))
        + alg.bracket(C, alg.bracket(A, B))
    )
    assert np.max(np.abs(jacobi)) <= 1e-12 * max(1.0, float(np.max(np.abs(A))) ** 3)
    assert alg.distance(AB) <= 1e-13 * max(1.0, float(alg.norm(AB)))


@pytest.mark.parametrize("key", ALGEBRAS)
@given(seed=seeds)
def test_normalizer_acts_on_V_and_fast_products_match(key: str, seed: int) -> None:
    """``[N(V), V] in V``, ``B X B`` in the stage space, and the one-product bracket is exact."""
    alg = ALGEBRAS[key]()
    rng = np.random.default_rng(seed)
    X = alg.random(rng, batch=(2,))
    B = alg.normalizer.random(rng, batch=(2,))
    C, T = alg.bracket_and_triple(B, X)
    assert _rel(C, B @ X - X @ B) <= TOL
    assert _rel(T, B @ X @ B) <= TOL
    assert np.all(alg.distance(C) <= 1e-13)
    assert np.all(alg.stage_algebra.distance(T) <= 1e-13 * np.maximum(1, alg.norm(T)))


def test_su_stage_lives_in_u_not_su() -> None:
    """``Tr(B X B) != 0`` on su(n): the IsoMP stage needs u(n) (not stated in the paper)."""
    alg = iso.algebras.su(3)
    X = alg.random(1)
    B = alg.normalizer.random(2)
    _, T = alg.bracket_and_triple(B, X)
    assert abs(np.trace(T)) > 1e-3
    assert alg.stage_algebra.name == "u(3)"


@pytest.mark.parametrize("key", ALGEBRAS)
@given(seed=seeds)
def test_inner_product_is_real_frobenius(key: str, seed: int) -> None:
    alg = ALGEBRAS[key]()
    rng = np.random.default_rng(seed)
    A, X = alg.random(rng), alg.random(rng)
    expected = np.real(np.trace(np.conj(A).T @ X))
    assert abs(alg.inner(A, X) - expected) <= 1e-13 * max(1.0, abs(expected))
    assert abs(alg.norm(A) ** 2 - alg.inner(A, A)) <= 1e-12 * alg.inner(A, A)


@pytest.mark.parametrize("key", ALGEBRAS)
def test_casimirs_invariant_under_similarity_flow(key: str) -> None:
    """Casimirs do not change along the exact flow of ``[B, W]`` for constant ``B``."""
    from scipy.linalg import expm

    alg = ALGEBRAS[key]()
    W = alg.random(3)
    B = alg.normalizer.random(4)
    g = expm(0.7 * B)
    W1 = alg.project(g @ W @ np.linalg.inv(g))
    c0, c1 = alg.casimirs(W), alg.casimirs(W1)
    scale = alg.casimir_scale(W)
    assert np.max(np.abs(c1 - c0) / scale) <= 1e-12


@pytest.mark.parametrize("key", ALGEBRAS)
def test_random_is_seeded_and_batched(key: str) -> None:
    alg: Algebra = ALGEBRAS[key]()
    a = alg.random(7, batch=(4, 2))
    b = alg.random(7, batch=(4, 2))
    assert a.shape == (4, 2, *alg.shape) and a.dtype == alg.dtype
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, alg.random(8, batch=(4, 2)))


def test_sp_involution_is_J_transpose_J() -> None:
    alg = iso.algebras.sp(6)
    Y = np.random.default_rng(0).standard_normal((6, 6))
    np.testing.assert_array_equal(alg.sigma(Y), alg.J @ Y.T @ alg.J)
    W = alg.random(1)
    assert np.max(np.abs(W.T @ alg.J + alg.J @ W)) <= 1e-14


@pytest.mark.parametrize(
    ("factory", "arg"),
    [(iso.algebras.so, 0), (iso.algebras.so, 2.5), (iso.algebras.sp, 3), (iso.algebras.sp, 0)],
)
def test_bad_sizes_raise(factory, arg) -> None:
    with pytest.raises(iso.ParameterError, match=r"size|positive integer"):
        factory(arg)


def _skew(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    A = rng.standard_normal(shape)
    return A - np.swapaxes(A, -1, -2)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 10, 11, 40, 192, 193])
def test_so_casimirs_in_real_arithmetic_match_the_complex_hermitian_route(n: int) -> None:
    """so(n)'s Casimirs (a real Householder reduction to a symmetric tridiagonal matrix, up to
    SKEW_MAX) agree with LAPACK's eigenvalues of the Hermitian iW to 8 eps |W|."""
    from isoflow._eig import SKEW_MAX

    rng = np.random.default_rng(n)
    W = _skew(rng, (3 if n > 40 else 50, n, n))
    W[0] *= 1e-150  # scaled by a power of two: neither overflow nor underflow
    W[1] *= 1e150
    got = iso.algebras.so(n).casimirs(W)
    want = np.linalg.eigvalsh(1j * W)
    norm = np.linalg.norm(W, axis=(-2, -1))[:, None]
    assert got.shape == want.shape
    assert np.all(np.abs(got - want) <= 8 * np.finfo(float).eps * norm)
    assert np.all(np.diff(got, axis=-1) >= 0)  # ascending
    assert (n > SKEW_MAX) == (n == 193)


def test_so_casimirs_of_degenerate_spectra() -> None:
    """Zero, rank-two, repeated blocks and an odd size's zero eigenvalue."""
    rng = np.random.default_rng(1)
    block = _skew(rng, (3, 3))
    W = np.zeros((4, 9, 9))
    W[1, 0, 4], W[1, 4, 0] = 2.5, -2.5  # rank two
    for k in range(3):  # one block three times: every eigenvalue thrice
        W[2, 3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = block
    W[3] = _skew(rng, (9, 9))
    got = iso.algebras.so(9).casimirs(W)
    want = np.linalg.eigvalsh(1j * W)
    norm = np.maximum(np.linalg.norm(W, axis=(-2, -1)), 1.0)[:, None]
    assert np.all(np.abs(got - want) <= 8 * np.finfo(float).eps * norm)
    assert np.all(got[0] == 0.0)
    assert np.abs(got[3, 4]) <= 8 * np.finfo(float).eps * norm[3, 0]  # odd n: a zero


def test_so_casimirs_of_non_finite_states_raise_like_lapack() -> None:
    W = np.zeros((2, 4, 4))
    W[1, 0, 1], W[1, 1, 0] = np.nan, np.nan
    with pytest.raises(np.linalg.LinAlgError, match="infs or NaNs"):
        iso.algebras.so(4).casimirs(W)
