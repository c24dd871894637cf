r"""The compact vector forms (R^3, x)^N and (R^3, x_L)^N against their matrix algebras.

Every identity the vector forms rely on is checked against the hat / phi matrices, and one step
of IsoMP on the vector forms is compared with one step of the *matrix* IsoMP on so(3) (so(3N)
block-diagonal for coupled problems) and sl(2,R) (sp(2N) for coupled problems) to 1e-14. These
would catch the misprints listed in the corrections to the paper (``docs/theory/method.rst``: the
sign of the h^2 term, the printed M(a, b, c), the anti-isomorphism phi).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import isoflow as iso
from isoflow.algebras.sl2_vectors import L_DIAG, cross_L, dot_L, phi, phi_inv
from isoflow.algebras.spin import cross, hat, vee

LM = np.diag(L_DIAG)

vec = arrays(np.float64, (3,), elements=st.floats(-10, 10, allow_nan=False))
vecs = arrays(np.float64, (4, 3), elements=st.floats(-10, 10, allow_nan=False))


def _scale(*arrs: np.ndarray) -> float:
    return max(1.0, *(float(np.max(np.abs(a))) for a in arrs))


# ---- identities, so(3) ---------------------------------------------------------------------------
@given(vecs, vecs)
def test_so3_bracket_is_hat_commutator(a, b):
    alg = iso.algebras.so3_vectors(4)
    A, B = hat(a), hat(b)
    assert np.allclose(hat(alg.bracket(a, b)), A @ B - B @ A, atol=1e-12 * _scale(a, b) ** 2)
    assert np.allclose(cross(a, b), np.cross(a, b), atol=1e-12 * _scale(a, b) ** 2)


@given(vecs, vecs)
def test_so3_triple_product_is_hat_bxb(b, x):
    alg = iso.algebras.so3_vectors(4)
    C, T = alg.bracket_and_triple(b, x)
    Bm, Xm = hat(b), hat(x)
    tol = 1e-12 * _scale(b, x) ** 3
    assert np.allclose(hat(T), Bm @ Xm @ Bm, atol=tol)
    assert np.allclose(hat(C), Bm @ Xm - Xm @ Bm, atol=tol)
    # hat(b) hat(x) hat(b) = -(b.x) hat(b): the sign the printed R^3 form gets wrong
    bx = np.sum(b * x, axis=-1)
    assert np.allclose(Bm @ Xm @ Bm, -bx[:, None, None] * Bm, atol=tol)


@given(vecs, vecs)
def test_so3_pairing_dagger_casimir(a, b):
    alg = iso.algebras.so3_vectors(4)
    tol = 1e-12 * _scale(a, b) ** 2
    # Euclidean pairing = half the Frobenius pairing of the hat matrices
    frob = np.sum(hat(a) * hat(b))
    assert np.isclose(2.0 * alg.inner(a, b), frob, atol=tol)
    # dagger is the vector form of the transpose
    assert np.array_equal(hat(alg.dagger(a)), np.swapaxes(hat(a), -1, -2))
    # Casimirs |w_i|^2 = -Tr(hat(w)^2)/2, the spectrum of hat(w) is {0, +-i|w|}
    assert np.allclose(alg.casimirs(a), -0.5 * np.trace(hat(a) @ hat(a), axis1=-2, axis2=-1))
    assert np.array_equal(vee(hat(a)), a)


# ---- identities, sl(2,R) -------------------------------------------------------------------------
@given(vecs, vecs)
def test_phi_is_an_anti_isomorphism(a, b):
    alg = iso.algebras.sl2_vectors(4)
    A, B = phi(a), phi(b)
    tol = 1e-12 * _scale(a, b) ** 2
    # [phi(a), phi(b)] = -phi(a x_L b), a x_L b = 2 L (a x b)
    assert np.allclose(A @ B - B @ A, -phi(cross_L(a, b)), atol=tol)
    assert np.allclose(cross_L(a, b), 2.0 * np.cross(a, b) @ LM, atol=tol)
    assert np.allclose(phi(alg.bracket(a, b)), A @ B - B @ A, atol=tol)
    assert np.allclose(phi_inv(phi(a)), a, rtol=0, atol=4e-16 * _scale(a))


@given(vecs, vecs)
def test_sl2_triple_product_and_pairings(b, x):
    alg = iso.algebras.sl2_vectors(4)
    Bm, Xm = phi(b), phi(x)
    C, T = alg.bracket_and_triple(b, x)
    tol = 1e-12 * _scale(b, x) ** 3
    assert np.allclose(phi(T), Bm @ Xm @ Bm, atol=tol)
    assert np.allclose(phi(C), Bm @ Xm - Xm @ Bm, atol=tol)
    # M(b, x, b) = 2 (b._L x) b - (b._L b) x = phi^{-1}(phi(b) phi(x) phi(b))
    assert np.allclose(phi_inv(Bm @ Xm @ Bm), T, atol=tol)
    tol2 = 1e-12 * _scale(b, x) ** 2
    assert np.allclose(np.trace(Bm @ Xm, axis1=-2, axis2=-1), 2.0 * dot_L(b, x), atol=tol2)
    assert np.isclose(np.sum(Bm * Xm), 2.0 * alg.inner(b, x), atol=8 * tol2)
    det = Xm[..., 0, 0] * Xm[..., 1, 1] - Xm[..., 0, 1] * Xm[..., 1, 0]  # (LU det warns on
    assert np.allclose(det, -alg.casimirs(x), atol=tol2)  # hypothesis' subnormal inputs)
    assert np.array_equal(phi(alg.dagger(b)), np.swapaxes(Bm, -1, -2))


def _printed_M(a, b, c):
    """The paper's printed M(a, b, c) (raw entries Q11, Q12, Q21 of phi(a) phi(b) phi(c))."""
    a1, a2, a3 = a
    b1, b2, b3 = b
    c1, c2, c3 = c
    return np.array(
        [
            c1 * (a1 * b1 + (b2 - b3) * (a2 + a3)) - (c2 - c3) * (b1 * (a2 + a3) - a1 * (b2 + b3)),
            c1 * (b1 * (a2 + a3) - a1 * (b2 + b3)) + (c2 + c3) * (a1 * b1 + (b2 - b3) * (a2 + a3)),
            c1 * (b1 * (a2 - a3) - a1 * (b2 - b3)) + (c2 - c3) * (a1 * b1 + (b2 + b3) * (a2 - a3)),
        ]
    )


def test_printed_M_is_not_the_triple_product_coordinates():
    rng = np.random.default_rng(0)
    b, x = rng.standard_normal((2, 3))
    alg = iso.algebras.sl2_vectors(1)
    Q = phi(b) @ phi(x) @ phi(b)
    _, T = alg.bracket_and_triple(b[None], x[None])
    printed = _printed_M(b, x, b)
    # the printed formula returns raw entries (Q11, Q12, Q21), not coordinates
    assert np.allclose(printed, [Q[0, 0], Q[0, 1], Q[1, 0]], atol=1e-13)
    assert np.abs(printed - T[0]).max() > 1e-2


# ---- the Algebra interface ----------------------------------------------------------------------
@pytest.mark.parametrize("make", [iso.algebras.so3_vectors, iso.algebras.sl2_vectors])
def test_vector_algebra_interface(make):
    alg = make(5)
    assert alg.shape == (5, 3) and alg.dtype == np.float64 and alg.dim == 15
    assert alg.normalizer is alg and alg.stage_algebra is alg
    W = alg.random(seed=1, batch=(2,))
    assert W.shape == (2, 5, 3)
    assert np.array_equal(alg.project(W), W)
    assert alg.project(np.ones((5, 3), dtype=np.int64)).dtype == np.float64
    assert np.all(alg.contains(W)) and np.all(alg.distance(W) == 0)
    assert np.array_equal(alg.from_coords(alg.to_coords(W)), W)
    assert alg.casimirs(W).shape == (2, 5)
    scale = alg.casimir_scale(W[0])
    assert scale.shape == (5,) and np.all(scale > 0)
    assert np.allclose(scale, np.sum(W[0] ** 2, axis=-1))
    assert np.allclose(alg.inner(W, W), alg.norm(W) ** 2)
    with pytest.raises(iso.ShapeError):
        alg.validate(np.zeros((5, 2)))
    with pytest.raises(iso.DtypeError):
        alg.validate(np.zeros((5, 3), dtype=complex))
    with pytest.raises(iso.NonFiniteError):
        alg.validate(np.full((5, 3), np.nan))
    with pytest.raises(ValueError):
        make(0)


def test_casimir_scale_handles_a_particle_at_the_origin():
    alg = iso.algebras.so3_vectors(3)
    W = np.array([[0.0, 0, 0], [0, 2.0, 0], [1.0, 0, 0]])
    assert np.array_equal(alg.casimir_scale(W), [4.0, 4.0, 1.0])


# ---- from_hamiltonian: the pairing convention ---------------------------------------------------
def _quartic(W):
    return np.sum(W[..., 0] ** 2 * W[..., 1] + 0.5 * W[..., 2] ** 4 + W[..., 0], axis=-1)


def _quartic_grad(W):
    g = np.zeros_like(W)
    g[..., 0] = 2 * W[..., 0] * W[..., 1] + 1.0
    g[..., 1] = W[..., 0] ** 2
    g[..., 2] = 2 * W[..., 2] ** 3
    return g


def test_from_hamiltonian_so3_is_w_cross_grad_and_twice_the_frobenius_flow():
    alg = iso.algebras.so3_vectors(3)
    prob = iso.IsospectralProblem.from_hamiltonian(alg, _quartic, _quartic_grad)
    w = np.random.default_rng(2).standard_normal((3, 3))
    f = prob.vector_field(w)
    assert np.allclose(f, np.cross(w, _quartic_grad(w)), atol=1e-14)
    # the same H on 3x3 matrices, Frobenius pairing: grad_F = hat(grad/2), W' = [grad_F^T, W]
    G = hat(0.5 * _quartic_grad(w))
    Wm = hat(w)
    Bm = np.swapaxes(G, -1, -2)
    assert np.allclose(2.0 * vee(Bm @ Wm - Wm @ Bm), f, atol=1e-14)


def test_from_hamiltonian_sl2_convention():
    alg = iso.algebras.sl2_vectors(3)
    prob = iso.IsospectralProblem.from_hamiltonian(alg, _quartic, _quartic_grad)
    w = np.random.default_rng(3).standard_normal((3, 3))
    g = _quartic_grad(w)
    f = prob.vector_field(w)
    assert np.allclose(f, cross_L(w, g * L_DIAG), atol=1e-13)
    assert np.allclose(f, 2.0 * np.cross(w, g * L_DIAG) * L_DIAG, atol=1e-13)
    # Frobenius on 2x2 matrices: Tr(phi(a)^T phi(b)) = 2 a.b, so grad_F = phi(g/2)
    Gm = phi(0.5 * g)
    Bm = np.swapaxes(Gm, -1, -2)
    Wm = phi(w)
    assert np.allclose(2.0 * phi_inv(Bm @ Wm - Wm @ Bm), f, atol=1e-13)


# ---- compact IsoMP == matrix IsoMP ---------------------------------------------------------------
def _local_nonlinear_B(kind):
    """A bounded nonlinear B acting particle by particle (vector form), and its matrix image."""
    K = np.array([0.3, -0.2, 0.5])

    def B(w):
        return np.sin(w) * np.array([1.0, 2.0, 0.5]) + 0.3 * np.cos(w[..., ::-1]) + K

    if kind == "so3":
        return B, lambda M: hat(B(vee(M)))
    return B, lambda M: phi(B(phi_inv(M)))


#: Both forms solved to the rounding floor (Newton, then the stall rule), from the same start.
TIGHT = iso.IsoMP(solver=iso.Newton(rtol=1e-16), initial_guess="state")


@pytest.mark.parametrize("h", [0.05, 0.2])
def test_compact_isomp_equals_matrix_isomp_per_particle_so3(h):
    N = 6
    B, Bm = _local_nonlinear_B("so3")
    alg = iso.algebras.so3_vectors(N)
    w0 = alg.random(seed=4)
    prob = iso.IsospectralProblem(B=B, algebra=alg)
    mprob = iso.IsospectralProblem(B=Bm, algebra=iso.algebras.so(3))
    w = w0
    for _ in range(5):  # compare single steps along a trajectory
        w_next = iso.step(prob, TIGHT, w, h)
        W_next = iso.step(mprob, TIGHT, hat(w), h)  # a batch of N matrices in so(3)
        assert np.abs(vee(W_next) - w_next).max() <= 1e-14 * max(1.0, np.abs(w_next).max())
        w = w_next


@pytest.mark.parametrize("h", [0.05, 0.2])
def test_compact_isomp_equals_matrix_isomp_per_particle_sl2(h):
    N = 6
    B, Bm = _local_nonlinear_B("sl2")
    alg = iso.algebras.sl2_vectors(N)
    w0 = alg.random(seed=5)
    prob = iso.IsospectralProblem(B=B, algebra=alg)
    mprob = iso.IsospectralProblem(B=Bm, algebra=iso.algebras.sl2())
    w = w0
    for _ in range(5):
        w_next = iso.step(prob, TIGHT, w, h)
        W_next = iso.step(mprob, TIGHT, phi(w), h)
        assert np.abs(phi_inv(W_next) - w_next).max() <= 1e-14 * max(1.0, np.abs(w_next).max())
        w = w_next


def test_printed_sign_variant_differs_from_matrix_isomp():
    """The printed R^3 form (h^2 term of the wrong sign) is *not* the matrix method."""
    N = 4
    B, Bm = _local_nonlinear_B("so3")

    class Printed(iso.algebras.SpinVectors):
        def bracket_and_triple(self, B, X):
            C, T = super().bracket_and_triple(B, X)
            return C, -T

    w0 = iso.algebras.so3_vectors(N).random(seed=6)
    w_printed = iso.step(iso.IsospectralProblem(B=B, algebra=Printed(N)), TIGHT, w0, 0.3)
    W = iso.step(iso.IsospectralProblem(B=Bm, algebra=iso.algebras.so(3)), TIGHT, hat(w0), 0.3)
    assert np.abs(vee(W) - w_printed).max() > 1e-4


def test_vector_isomp_ensemble_matches_single_runs():
    B, _ = _local_nonlinear_B("so3")
    alg = iso.algebras.so3_vectors(3)
    prob = iso.IsospectralProblem(B=B, algebra=alg)
    W0 = alg.random(seed=7, batch=(4,))
    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=10, diagnostics=False)
    for k in range(4):
        single = iso.solve(prob, iso.IsoMP(), W0[k], dt=0.1, n_steps=10, diagnostics=False)
        assert np.abs(sol.y_final[k] - single.y_final).max() <= 1e-13


# ---- the closed-form stage on (R^3, x)^N ---------------------------------------------------------
@given(vecs, vecs, st.floats(0.01, 2.0))
def test_so3_closed_form_stage_solves_the_stage_equation(b, w, h):
    # X solves hat(w) = (I - h/2 hat b) hat(X) (I + h/2 hat b) for the given field, the finish
    # w + h C is IsoMP's update (I + h/2 hat b) hat(X) (I - h/2 hat b), a rotation of w
    alg = iso.algebras.so3_vectors(4)
    assert alg.closed_form_stage
    X, C = alg.solve_stage(w, b, h)
    I3 = np.eye(3)
    M = I3 - 0.5 * h * hat(b)
    tol = 1e-12 * _scale(w) * _scale(h * b) ** 2
    assert np.allclose(M @ hat(X) @ np.swapaxes(M, -1, -2), hat(w), atol=tol)
    assert np.allclose(C, np.cross(b, X), atol=1e-12 * _scale(b, X) ** 2)
    update = np.swapaxes(M, -1, -2) @ hat(X) @ M
    assert np.allclose(hat(w + h * C), update, atol=tol)
    n0, n1 = np.linalg.norm(w, axis=-1), np.linalg.norm(w + h * C, axis=-1)
    assert np.all(np.abs(n1 - n0) <= 4e-15 * _scale(w))


def test_so3_closed_form_stage_jvp_is_its_derivative():
    alg = iso.algebras.so3_vectors(5)
    rng = np.random.default_rng(3)
    W, B, dB = (rng.standard_normal((2, 5, 3)) for _ in range(3))
    h, eps = 0.7, 1e-6
    fd = (alg.solve_stage(W, B + eps * dB, h)[0] - alg.solve_stage(W, B - eps * dB, h)[0]) / (
        2 * eps
    )
    assert np.abs(alg.solve_stage_jvp(W, B, dB, h) - fd).max() <= 1e-8


def test_a_space_that_changes_the_products_keeps_the_plain_map():
    # a subclass with other products (here the printed sign) is not the space the closed form
    # is derived from; matrix spaces have none
    class Printed(iso.algebras.SpinVectors):
        def bracket_and_triple(self, B, X):
            C, T = super().bracket_and_triple(B, X)
            return C, -T

    assert not Printed(3).closed_form_stage
    assert not iso.algebras.so(3).closed_form_stage
    with pytest.raises(NotImplementedError, match="no closed-form stage"):
        iso.algebras.so(3).solve_stage(np.zeros((3, 3)), np.zeros((3, 3)), 0.1)
