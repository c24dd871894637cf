"""The semidirect products g x| g* as dual numbers: products, the Lie–Poisson structure, the
Casimirs, IsoMP as a Cayley conjugation and a Poisson map, the compiled pair layouts, errors.

Expected values come from independent computations: block matrices ``[[X0, X1], [0, X0]]`` with
plain matrix products, traces of matrix powers, the Lie–Poisson tensor of ``se(3)*`` written out
by hand, and finite-difference Jacobians of the step map.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

import isoflow as iso
from helpers import assert_same_run, compiled_and_numpy
from isoflow.algebras.spin import hat

PAIRS = {
    "so4": lambda: iso.algebras.semidirect(iso.algebras.so(4)),
    "su3": lambda: iso.algebras.semidirect(iso.algebras.su(3)),
    "u3": lambda: iso.algebras.semidirect(iso.algebras.u(3)),
    "se3": iso.algebras.se3_vectors,
}


def _blocks(alg, Y: np.ndarray) -> np.ndarray:
    """``[[X0, X1], [0, X0]]`` built here, not by the algebra (for the vectors: hat blocks)."""
    X0, X1 = Y[0], Y[1]  # one element
    if isinstance(alg, iso.algebras.SE3Vectors):
        X0, X1 = hat(X0), hat(X1)
    Z = np.zeros_like(X0)
    return np.block([[X0, X1], [Z, X0]])


@pytest.mark.parametrize("key", list(PAIRS))
def test_bracket_and_triple_are_the_block_matrix_products(key: str) -> None:
    alg = PAIRS[key]()
    X = alg.random(1)
    B = alg.normalizer.random(2)
    C, T = alg.bracket_and_triple(B, X)
    Bm, Xm = _blocks(alg, B), _blocks(alg, X)
    scale = np.max(np.abs(Bm)) ** 2 * np.max(np.abs(Xm))
    assert np.max(np.abs(_blocks(alg, C) - (Bm @ Xm - Xm @ Bm))) <= 1e-14 * scale
    assert np.max(np.abs(_blocks(alg, T) - Bm @ Xm @ Bm)) <= 1e-14 * scale
    assert np.max(np.abs(alg.bracket(B, X) - C)) <= 1e-14 * scale
    assert float(alg.distance(C)) <= 1e-15 * scale  # the bracket stays in V
    assert np.max(np.abs(alg.to_matrix(X) - Xm)) == 0.0
    assert np.array_equal(alg.from_matrix(alg.to_matrix(X)), X)


@pytest.mark.parametrize("key", ["so4", "su3", "u3"])
def test_coordinates_and_projection(key: str) -> None:
    alg = PAIRS[key]()
    base = alg.base
    assert alg.dim == 2 * base.dim and alg.shape == (2, *base.shape)
    X = alg.random(3, batch=(2,))
    assert np.max(np.abs(alg.from_coords(alg.to_coords(X)) - X)) <= 1e-15
    Y = X + (1 + 1j if alg.is_complex else 1.0) * np.ones(alg.shape)  # leaves V
    assert float(np.max(alg.distance(Y))) > 0.1
    P = alg.project(Y)
    assert float(np.max(alg.distance(P))) <= 1e-15
    assert np.array_equal(P[..., 1, :, :], base.project(Y[..., 1, :, :]))
    # split gives views of the two fields (as documented): writing one writes the pair
    th, w = alg.split(X)
    assert np.array_equal(th, X[..., 0, :, :]) and np.array_equal(w, X[..., 1, :, :])
    assert np.shares_memory(th, X) and np.shares_memory(w, X)
    w[...] = 0
    assert not np.any(X[..., 1, :, :]) and np.any(X[..., 0, :, :])


def test_from_hamiltonian_gives_the_semidirect_lie_poisson_equations() -> None:
    r"""With the field-wise gradient: Theta' = [P, Theta], W' = [P, W] + [J, Theta],
    P = (dH/dW)^T, J = (dH/dTheta)^T; for the vectors the heavy top's equations."""
    alg = iso.algebras.semidirect(iso.algebras.so(4))
    rng = np.random.default_rng(0)
    S = rng.standard_normal((4, 4))

    def grad(Y):
        th, w = alg.split(Y)
        return alg.pair(S.T @ th @ S, w * (1 + np.sum(w * w)))

    prob = iso.IsospectralProblem.from_hamiltonian(alg, lambda Y: 0.0, grad)
    Y = alg.random(4)
    th, w = alg.split(Y)
    g_th, g_w = alg.split(grad(Y))
    P, J = g_w.T, g_th.T
    want = alg.pair(P @ th - th @ P, P @ w - w @ P + J @ th - th @ J)
    assert np.max(np.abs(prob.vector_field(Y) - want)) <= 1e-14 * np.max(np.abs(want))
    top = iso.algebras.se3_vectors()
    Ii = np.array([1.0, 0.6, 0.4])
    chi = np.array([0.2, -0.4, 0.9])
    p = iso.IsospectralProblem.from_hamiltonian(
        top,
        lambda Y: 0.0,
        lambda Y: top.pair(np.broadcast_to(chi, (*Y.shape[:-2], 3)), Ii * Y[..., 1, :]),
    )
    G, M = rng.standard_normal(3), rng.standard_normal(3)
    Om = Ii * M
    f = p.vector_field(top.pair(G, M))
    assert np.allclose(f[0], np.cross(G, Om), rtol=0, atol=1e-15)
    assert np.allclose(f[1], np.cross(M, Om) + np.cross(G, chi), rtol=0, atol=1e-15)


@pytest.mark.parametrize("key", ["so4", "su3", "u3"])
def test_casimirs_are_the_spectrum_and_the_cross_traces(key: str) -> None:
    alg = PAIRS[key]()
    n = alg.base.n
    Y = alg.random(5, batch=(3,))
    th, w = alg.split(Y)
    C = alg.casimirs(Y)
    assert C.shape == (3, 2 * n)
    lam = np.linalg.eigvalsh(1j * th)
    assert np.max(np.abs(C[:, :n] - lam)) <= 1e-14 * np.max(np.abs(lam))
    rho = np.max(np.abs(lam), axis=-1)[:, None, None]
    ref = [
        np.trace(1j * w @ np.linalg.matrix_power(1j * th / rho, k), axis1=-2, axis2=-1).real
        for k in range(n)
    ]
    assert np.max(np.abs(C[:, n:] - np.stack(ref, -1))) <= 1e-14 * float(np.max(alg.norm(Y)))
    zero_theta = alg.pair(np.zeros_like(th[0]), w[0])  # Theta = 0: no spectrum, Tr(iW) only
    Cz = alg.casimirs(zero_theta)
    assert np.all(Cz[:n] == 0.0) and np.all(Cz[n + 1 :] == 0.0)
    assert Cz[n] == pytest.approx(np.trace(1j * w[0]).real, abs=1e-15)
    top = iso.algebras.se3_vectors()
    G, M = np.array([0.0, 0.6, 0.8]), np.array([1.0, 2.0, 3.0])
    assert np.allclose(top.casimirs(top.pair(G, M)), [1.0, 3.6], rtol=0, atol=1e-15)


def _step_map(prob, h: float):
    tight = iso.IsoMP(solver=iso.FixedPoint(rtol=1e-15, stall_rtol=1e-13), initial_guess="state")
    return lambda Y: iso.step(prob, tight, Y, h, validate=False)


def test_isomp_step_is_the_cayley_conjugation_of_the_dual_numbers() -> None:
    """M_{k+1} = C M_k C^{-1}, C = (I + h/2 B)(I - h/2 B)^{-1} with B = B(X) of the stage X, in
    block matrices: both Casimir families are those of a similar matrix."""
    alg = iso.algebras.semidirect(iso.algebras.su(3))
    rng = np.random.default_rng(1)
    A = rng.standard_normal((3, 3))

    def B(Y):
        th, w = alg.split(Y)
        return alg.pair(w + A @ w @ A.T - (A @ w @ A.T).conj().T, 0.5 * th @ th - th)

    prob = iso.IsospectralProblem(B=lambda Y: alg.normalizer.project(B(Y)), algebra=alg)
    Y0 = alg.random(2) * 0.8
    h = 0.2
    Y1 = _step_map(prob, h)(Y0)
    # the stage from the first half of the step: Y0 = (I - h/2 B) X (I + h/2 B)
    X = iso.IsoMP().stage_problem(prob, Y0, h)
    sol = iso.FixedPoint(rtol=1e-15, stall_rtol=1e-13).solve(X, Y0)
    Bm = alg.to_matrix(prob.evaluate_B(sol.x))
    eye = np.eye(6)
    Cay = (eye + 0.5 * h * Bm) @ np.linalg.inv(eye - 0.5 * h * Bm)
    conj = Cay @ alg.to_matrix(Y0) @ np.linalg.inv(Cay)
    assert np.max(np.abs(alg.to_matrix(Y1) - conj)) <= 1e-13
    assert float(np.max(np.abs(Y1 - Y0))) > 0.05  # a real step


def _poisson_tensor_se3(Y: np.ndarray) -> np.ndarray:
    """The Lie–Poisson tensor of se(3)* in the coordinates (Gamma, M), by hand:
    Gamma' = Gamma x dH/dM, M' = Gamma x dH/dGamma + M x dH/dM."""
    G, M = hat(Y[0]), hat(Y[1])
    Z = np.zeros((3, 3))
    return np.block([[Z, G], [G, M]])


def _jacobian(step, Y: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    c = Y.ravel()
    cols = []
    for a in range(c.size):
        d = np.zeros_like(c)
        d[a] = eps
        plus = step((c + d).reshape(Y.shape)).ravel()
        minus = step((c - d).reshape(Y.shape)).ravel()
        cols.append((plus - minus) / (2 * eps))
    return np.stack(cols, axis=-1)


def test_isomp_on_se3_is_a_poisson_map_and_the_classical_midpoint_is_not() -> None:
    """D Phi Pi(Y) D Phi^T = Pi(Phi(Y)) for a non-quadratic Hamiltonian coupling both fields."""
    top = iso.algebras.se3_vectors()
    K = np.diag([0.7, 1.1, 0.4])
    A = np.array([[0.3, 0.1, 0.0], [0.1, -0.2, 0.4], [0.0, 0.4, 0.5]])
    Ii = np.array([1.0, 1 / 1.5, 1 / 2.2])

    def grad(Y):
        G, M = top.split(Y)
        q = np.einsum("...i,ij,...j->...", G, K, G)[..., None]
        mm = np.sum(M * M, axis=-1, keepdims=True)
        return top.pair(q * (G @ K) + M @ A, Ii * M + G @ A.T + 0.5 * mm * M)

    prob = iso.IsospectralProblem.from_hamiltonian(top, lambda Y: 0.0, grad)
    Y = 0.7 * np.random.default_rng(1).standard_normal((2, 3))
    h = 0.3
    for method, small in (
        (iso.IsoMP(solver=iso.FixedPoint(rtol=1e-15, stall_rtol=1e-13)), True),
        (iso.ClassicalMidpoint(solver=iso.FixedPoint(rtol=1e-15, stall_rtol=1e-13)), False),
    ):
        step = lambda Z, m=method: iso.step(prob, m, Z, h, validate=False)  # noqa: E731
        J = _jacobian(step, Y)
        defect = np.max(np.abs(J @ _poisson_tensor_se3(Y) @ J.T - _poisson_tensor_se3(step(Y))))
        if small:
            assert defect <= 1e-9  # measured 7e-11 (finite differences)
        else:
            assert defect >= 1e-5  # measured 4e-4


def test_isomp_on_matrix_pairs_is_a_poisson_map() -> None:
    """The same identity on so(3) x| so(3)*: in the coordinates of an orthonormal basis
    ``e_a``, P_ab(Y) = <Y, [s e_a, s e_b]>_eps with the eps-pairing of the dual numbers
    <X, Z>_eps = <s X, Z> (Frobenius), ``s`` the swap of the fields: the gradient of the
    eps-pairing is the swapped Frobenius gradient."""
    alg = iso.algebras.semidirect(iso.algebras.so(3))
    swapped = alg.from_coords(np.eye(alg.dim))[:, ::-1]  # s e_a
    br = alg.bracket(swapped[:, None], swapped[None, :])

    def tensor(Y):
        return np.sum(Y[::-1] * br, axis=(-3, -2, -1))

    def H(Y):
        th, w = alg.split(Y)
        return 0.5 * np.sum(w * w * np.array([1.0, 2.0, 3.0]), (-2, -1)) + np.sum(th**3, (-2, -1))

    def grad(Y):
        th, w = alg.split(Y)
        return alg.project(alg.pair(3 * th**2, w * np.array([1.0, 2.0, 3.0])))

    prob = iso.IsospectralProblem.from_hamiltonian(alg, H, grad)
    Y = alg.random(2) * 0.6
    step = _step_map(prob, 0.3)

    def coords_step(c):
        return alg.to_coords(step(alg.from_coords(c)))

    J = _jacobian(coords_step, alg.to_coords(Y))
    defect = np.max(np.abs(J @ tensor(Y) @ J.T - tensor(step(Y))))
    assert defect <= 1e-9  # measured ~1e-11


# ---- the compiled pair layouts ---------------------------------------------------------------


@numba.njit(cache=True)
def pair_field(W, out, K, c):  # type: ignore[no-untyped-def]
    """``B = (-c W1 (1 + |W1|^2), -K)`` entrywise on a pair of matrices: a nonlinear field that
    couples the fields through the triple product (in the normalizer for a symmetric ``c``)."""
    n = W.shape[1]
    for i in range(n):
        for j in range(n):
            w = W[1, i, j]
            out[0, i, j] = -c[i, j] * w * (1.0 + (w.real * w.real + w.imag * w.imag))
            out[1, i, j] = -K[i, j]


def _pair_problem(base, seed: int = 0) -> iso.IsospectralProblem:
    alg = iso.algebras.semidirect(base)
    n = base.n
    rng = np.random.default_rng(seed)
    c = rng.uniform(0.5, 1.5, (n, n))
    c = 0.5 * (c + c.T)
    K = np.ascontiguousarray(base.random(rng).astype(base.dtype))

    def B(Y):
        w = alg.split(Y)[1]
        return alg.pair(-c * w * (1 + np.abs(w) ** 2), np.broadcast_to(-K, w.shape))

    return iso.IsospectralProblem(B=B, algebra=alg, kernel=iso.CompiledB(pair_field, (K, c)))


@pytest.mark.parametrize(
    ("base", "label"),
    [
        (lambda: iso.algebras.so(4), "written-out"),
        (lambda: iso.algebras.su(3), "written-out"),
        (lambda: iso.algebras.u(3), "written-out"),
        (lambda: iso.algebras.su(20), "BLAS"),
    ],
    ids=["so4", "su3", "u3", "su20-blas"],
)
def test_compiled_pairs_equal_the_numpy_path(base, label: str) -> None:
    b = base()
    prob = _pair_problem(b)
    alg = prob.algebra
    Y = np.stack([alg.random(s, scale=0.6 / np.sqrt(b.n)) for s in range(3)])  # an ensemble
    a, n = compiled_and_numpy(prob, iso.IsoMP(), Y, 0.05, 24, 6, chunks=(10, 14))
    assert "dual pairs" in a.label and label in a.label
    assert a.iterations > 3 * 24
    assert_same_run(a, n)


def test_compiled_pairs_with_anderson_and_the_heavy_top_equal_the_numpy_path() -> None:
    prob = _pair_problem(iso.algebras.so(5), seed=2)
    Y = prob.algebra.random(1, scale=0.3)
    method = iso.IsoMP(solver=iso.FixedPoint(anderson=2))
    a, n = compiled_and_numpy(prob, method, Y, 0.1, 12, 4)
    assert_same_run(a, n, iters_exact=False)
    top, y0 = iso.models.heavy_top("general")
    ens = np.stack([y0, y0 * 1.1, y0 * 0.9])
    a, n = compiled_and_numpy(top, iso.IsoMP(), ens, 0.02, 30, 10)
    assert "se(3) pairs" in a.label
    assert_same_run(a, n)


def test_a_hopeless_pair_step_freezes_that_member_on_the_compiled_path() -> None:
    prob = _pair_problem(iso.algebras.su(3), seed=4)
    alg = prob.algebra
    good = alg.project(alg.random(1, scale=0.2))
    bad = alg.project(alg.random(2, scale=40.0))
    sol = iso.solve(prob, iso.IsoMP(), np.stack([good, bad]), dt=0.1, n_steps=5, throw=False)
    assert sol.stats.runner.startswith("compiled")
    assert list(sol.failed_step) == [-1, 0] and np.array_equal(sol.ys[-1, 1], bad)
    with pytest.raises(iso.ConvergenceError, match=r"did not converge \((max_iter|diverged)\)"):
        iso.solve(prob, iso.IsoMP(), bad, dt=0.1, n_steps=5)


# ---- bad input ---------------------------------------------------------------------------------


def _one_line(exc: BaseException) -> str:
    text = str(exc)
    assert "\n" not in text
    return text


def test_bad_input_gives_one_line_typed_errors() -> None:
    alg = iso.algebras.semidirect(iso.algebras.su(3))
    base = alg.base
    with pytest.raises(iso.ShapeError) as err:
        alg.pair(base.random(1), iso.algebras.su(4).random(1))
    assert _one_line(err.value) == (
        "the fields of su(3) x| su(3)* must have one shape: Theta has (3, 3), W has (4, 4)"
    )
    with pytest.raises(iso.ShapeError, match=r"have shape \(\*batch, 3, 3\), got \(2, 2\)"):
        alg.pair(np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(iso.ShapeError) as err:
        alg.validate(base.random(1))
    assert "must have shape (*batch, 2, 3, 3)" in _one_line(err.value)
    outside = alg.pair(base.random(1), base.random(2) + np.eye(3))  # W has a trace
    with pytest.raises(iso.NotInSpaceError) as err:
        alg.validate(outside)
    assert _one_line(err.value).startswith(
        "state is not in su(3) x| su(3)*: its field W (index 1) is "
    )
    hermitian = alg.pair(1j * base.random(1), base.random(2))  # Theta Hermitian
    with pytest.raises(iso.NotInSpaceError, match="its field Theta"):
        alg.validate(hermitian)
    with pytest.raises(iso.DtypeError):
        iso.algebras.semidirect(iso.algebras.so(3)).validate(alg.pair(base.random(1), base.zeros()))
    with pytest.raises(iso.ParameterError) as err:
        iso.algebras.semidirect(iso.algebras.sym(3))
    assert _one_line(err.value) == (
        "semidirect: the base must be so(n), u(n) or su(n), got <algebra sym(3)>"
    )
    top = iso.algebras.se3_vectors()
    with pytest.raises(iso.ShapeError, match="Gamma has \\(3,\\), M has \\(2,\\)"):
        top.pair(np.zeros(3), np.zeros(2))
