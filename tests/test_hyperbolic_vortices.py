r"""Point vortices on the hyperbolic plane with the hyperbolic midpoint (IsoMP on (R^3, x_L)^N).

Measured on the reference machine (asserted bounds are looser): paper runs, config 1 (h = 0.01,
T = 10) / config 2 (h = 0.001, T = 1): max |w_i ._L w_i + 1| = 1.1e-13 / 5.0e-14, momentum
drift 1.4e-15 / 7.1e-15, |H - H0| = 3.5e-16 / 1.5e-4 (flat over the run). Order: config 1,
h = 2^-1..2^-8, T = 1: slope 2.00; config 2, h = 2^-11..2^-16, T = 1/16: slope 2.00. At
h = 0.001 the config-2 error at T = 1 is 0.29 (NOTES: ~0.3), at 5e-4 0.06, at 2.5e-4 0.014.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import isoflow as iso
from helpers import loglog_slope
from isoflow.algebras.sl2_vectors import SL2Vectors, phi, phi_inv
from isoflow.algebras.spin import hat

L = np.array([1.0, 1.0, -1.0])


def _printed_rhs(w: np.ndarray, G: np.ndarray) -> np.ndarray:
    """The paper's eq. (PV_eq), written independently of the library (explicit loops)."""
    N = len(G)
    out = np.zeros_like(w)
    for i in range(N):
        for j in range(N):
            if i != j:
                d = (w[i] * L) @ w[j]
                out[i] -= G[j] / np.pi * 2.0 * L * np.cross(w[i], w[j]) / (d * d - 1.0)
    return out


def _printed_H(w: np.ndarray, G: np.ndarray) -> float:
    N = len(G)
    s = 0.0
    for i in range(N):
        for j in range(N):
            if i != j:
                d = (w[i] * L) @ w[j]
                s += G[i] * G[j] * np.log((d + 1.0) / (d - 1.0))
    return -s / (4.0 * np.pi)


# ---- the model -----------------------------------------------------------------------------------


def test_paper_configurations_are_the_exact_points():
    printed = {
        1: np.array(
            [[-0.5, -0.5, 1.0], [0.8660, -0.8660, -0.0], [1.4142, 1.4142, 1.4142]]
        ),  # columns are vortices
        2: np.array([[2.6, 4.0, 3.0], [0.1923, 0.1250, 0.1667], [2.7923, 4.1250, 3.1667]]),
    }
    circ = {1: [0.5317, 0.0761, 1.0], 2: [0.0990, 0.8091, 1.0]}
    for cfg in (1, 2):
        prob, w0 = iso.models.hyperbolic_vortices(config=cfg)
        assert isinstance(prob.algebra, SL2Vectors) and w0.shape == (3, 3)
        assert np.array_equal(np.round(w0.T, 4), np.round(printed[cfg], 4))
        assert np.abs(np.sum(w0 * w0 * L, axis=-1) + 1.0).max() <= 1e-14  # |w|^2 ~ 30
        assert np.all(w0[:, 2] > 0)
        assert np.array_equal(prob.parameters["circulations"], circ[cfg])
        assert prob.parameters["config"] == cfg
    _, w_default = iso.models.hyperbolic_vortices()
    assert np.array_equal(w_default, iso.models.hyperbolic_vortices(config=1)[1])
    _, w1 = iso.models.hyperbolic_vortices(config=1)
    assert np.allclose(w1, [[-0.5, np.sqrt(3) / 2, np.sqrt(2)], [-0.5, -np.sqrt(3) / 2, np.sqrt(2)],
                            [1.0, 0.0, np.sqrt(2)]], atol=1e-15)  # fmt: skip


def test_vector_field_B_and_hamiltonian_match_the_printed_equations():
    for cfg in (1, 2):
        prob, w0 = iso.models.hyperbolic_vortices(config=cfg)
        G = prob.parameters["circulations"]
        f = _printed_rhs(w0, G)
        # (w_i._L w_j)^2 - 1 ~ 0.02 for the close pair of config 2 amplifies rounding
        assert np.abs(prob.vector_field(w0) - f).max() <= 1e-13 * np.abs(f).max()
        assert np.isclose(prob.hamiltonian(w0), _printed_H(w0, G), rtol=1e-14)
        # B_i = -(1/G_i) L grad_i H  (central differences of the printed H)
        eps = 1e-6
        grad = np.zeros_like(w0)
        for i in range(3):
            for k in range(3):
                d = np.zeros_like(w0)
                d[i, k] = eps
                grad[i, k] = (_printed_H(w0 + d, G) - _printed_H(w0 - d, G)) / (2 * eps)
        assert np.allclose(prob.B(w0), -(grad * L) / G[:, None], rtol=1e-6, atol=1e-8)
        # exact B_jvp against central differences
        dW = np.random.default_rng(cfg).standard_normal(w0.shape)
        fd = (prob.B(w0 + eps * dW) - prob.B(w0 - eps * dW)) / (2 * eps)
        assert np.allclose(prob.B_jvp(w0, dW), fd, rtol=1e-6, atol=1e-7)


def test_printed_dynamics_is_minus_two_times_the_frobenius_lie_poisson_flow():
    """NOTES: the ODE is -2 x the Frobenius Lie–Poisson flow of H with weights 1/G_i on
    2x2 matrices: phi(w_i)' = -2 [(grad_F,i H)^T / G_i, phi(w_i)], grad_F = phi(grad H / 2)."""
    prob, w0 = iso.models.hyperbolic_vortices(config=2)
    G = prob.parameters["circulations"]
    eps = 1e-6
    grad = np.zeros_like(w0)
    for i in range(3):
        for k in range(3):
            d = np.zeros_like(w0)
            d[i, k] = eps
            grad[i, k] = (_printed_H(w0 + d, G) - _printed_H(w0 - d, G)) / (2 * eps)
    gradF = phi(grad / 2.0) / G[:, None, None]
    Bm = np.swapaxes(gradF, -1, -2)
    W = phi(w0)
    flow = -2.0 * (Bm @ W - W @ Bm)
    assert np.allclose(phi_inv(flow), prob.vector_field(w0), rtol=1e-6, atol=1e-6)


def test_printed_ode_conserves_H_and_momentum_dop853():
    """Independent check: DOP853 on the hand-written printed ODE conserves the printed H and
    sum G_i w_i, and agrees with iso.reference_solution (the problem's own vector field)."""
    prob, w0 = iso.models.hyperbolic_vortices(config=2)
    G = prob.parameters["circulations"]
    ts = np.linspace(0.0, 0.25, 6)
    sol = solve_ivp(
        lambda t, y: _printed_rhs(y.reshape(3, 3), G).ravel(),
        (0.0, ts[-1]),
        w0.ravel(),
        method="DOP853",
        t_eval=ts,
        rtol=1e-13,
        atol=1e-13,
    )
    ys = sol.y.T.reshape(-1, 3, 3)
    H = [_printed_H(y, G) for y in ys]
    assert np.ptp(H) <= 1e-10
    assert np.abs(np.einsum("i,tik->tk", G, ys) - G @ w0).max() <= 1e-10
    ref = iso.reference_solution(prob, w0, ts)
    assert np.abs(ref - ys).max() <= 1e-9


def test_user_positions_and_validation():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, size=(4, 2))
    pos = np.column_stack([xy, np.sqrt(1 + np.sum(xy**2, axis=1))])
    prob, w0 = iso.models.hyperbolic_vortices(positions=pos, circulations=[1.0, -0.5, 0.3, 2.0])
    assert w0.shape == (4, 3) and prob.algebra.N == 4 and prob.parameters["config"] is None
    assert np.abs(np.sum(w0 * w0 * L, axis=-1) + 1).max() <= 1e-15
    printed_4_digits = [[-0.5, 0.866, 1.4142], [-0.5, -0.866, 1.4142], [1.0, 0.0, 1.4142]]
    with pytest.raises(iso.NotInSpaceError, match="hyperboloid"):
        iso.models.hyperbolic_vortices(positions=printed_4_digits, circulations=[1, 1, 1])
    _, w_r = iso.models.hyperbolic_vortices(
        positions=printed_4_digits, circulations=[1, 1, 1], tol=1e-3
    )
    assert np.abs(np.sum(w_r * w_r * L, axis=-1) + 1).max() <= 1e-15
    lower = pos.copy()
    lower[:, 2] *= -1
    with pytest.raises(iso.NotInSpaceError, match="upper sheet"):
        iso.models.hyperbolic_vortices(positions=lower, circulations=np.ones(4))
    with pytest.raises(iso.NotInSpaceError, match="coincide"):
        iso.models.hyperbolic_vortices(positions=pos[[0, 0, 1]], circulations=np.ones(3))
    with pytest.raises(iso.ShapeError):
        iso.models.hyperbolic_vortices(positions=pos, circulations=np.ones(3))
    with pytest.raises(iso.ShapeError):
        iso.models.hyperbolic_vortices(positions=pos[:, :2], circulations=np.ones(4))
    with pytest.raises(iso.models.ParameterError):
        iso.models.hyperbolic_vortices(positions=pos, circulations=[1.0, 0.0, 1.0, 1.0])
    with pytest.raises(iso.NonFiniteError):
        iso.models.hyperbolic_vortices(positions=pos, circulations=[1.0, np.inf, 1.0, 1.0])
    with pytest.raises(iso.models.ParameterError):
        iso.models.hyperbolic_vortices(config=3)
    with pytest.raises(iso.models.ParameterError):
        iso.models.hyperbolic_vortices(config=1, positions=pos, circulations=np.ones(4))
    with pytest.raises(iso.models.ParameterError):
        iso.models.hyperbolic_vortices(positions=pos)
    with pytest.raises(iso.DtypeError):
        iso.models.hyperbolic_vortices(positions=pos.astype(complex), circulations=np.ones(4))


# ---- compact hyperbolic midpoint == matrix IsoMP -------------------------------------------------


def _embed(w: np.ndarray) -> np.ndarray:
    """(N, 3) -> sp(2N): blocks phi(w_i) spread over the (i, N+i) rows/columns."""
    N = w.shape[-2]
    P = phi(w)
    idx = np.arange(N)
    out = np.zeros((*w.shape[:-2], 2 * N, 2 * N))
    out[..., idx, idx] = P[..., 0, 0]
    out[..., idx, N + idx] = P[..., 0, 1]
    out[..., N + idx, idx] = P[..., 1, 0]
    out[..., N + idx, N + idx] = P[..., 1, 1]
    return out


def _unembed(M: np.ndarray, N: int) -> np.ndarray:
    idx = np.arange(N)
    Q = np.stack(
        [
            np.stack([M[..., idx, idx], M[..., idx, N + idx]], axis=-1),
            np.stack([M[..., N + idx, idx], M[..., N + idx, N + idx]], axis=-1),
        ],
        axis=-2,
    )
    return phi_inv(Q)


@pytest.mark.parametrize(("config", "h"), [(1, 0.01), (1, 0.25), (2, 0.001)])
def test_compact_step_equals_matrix_isomp(config, h):
    """The matrix B is phi(B_i): [phi(b), phi(w)] = phi(bracket(b, w)) = -phi(b x_L w)."""
    prob, w0 = iso.models.hyperbolic_vortices(config=config)
    N = 3
    malg = iso.algebras.sp(2 * N)
    assert malg.contains(_embed(w0))
    mprob = iso.IsospectralProblem(B=lambda M: _embed(prob.B(_unembed(M, N))), algebra=malg)
    method = iso.IsoMP(solver=iso.FixedPoint(rtol=1e-16), initial_guess="state")
    w = w0
    for _ in range(4):
        w_next = iso.step(prob, method, w, h)
        M_next = iso.step(mprob, method, _embed(w), h)
        scale = max(1.0, np.abs(w_next).max())
        assert np.abs(_unembed(M_next, N) - w_next).max() <= 1e-14 * scale
        assert np.abs(M_next - _embed(_unembed(M_next, N))).max() <= 1e-14 * scale
        w = w_next


# ---- the paper's runs ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("config", "h", "T", "h_bound"), [(1, 0.01, 10.0, 1e-12), (2, 0.001, 1.0, 1e-3)]
)
def test_paper_runs_constraint_momentum_hamiltonian(config, h, T, h_bound):
    prob, w0 = iso.models.hyperbolic_vortices(config=config)
    sol = iso.solve(prob, iso.IsoMP(), y0=w0, dt=h, t1=T)
    assert sol.success
    ys = sol.ys
    assert np.abs(np.sum(ys * ys * L, axis=-1) + 1.0).max() <= 1e-12  # each on its hyperboloid
    assert np.all(ys[..., 2] > 0)
    d = sol.diagnostics
    assert d.invariant_drift["momentum"].max() <= 1e-12
    dH = np.abs(d.hamiltonian - d.hamiltonian[0])
    assert dH.max() <= h_bound
    n = len(dH)
    assert dH[-n // 4 :].max() <= 2.0 * dH[: n // 4].max() + 1e-14  # bounded, no drift


def test_config_1_is_a_relative_equilibrium():
    """Equilateral relative equilibrium: the mutual Lorentz products (hyperbolic distances)
    stay constant while the triangle moves."""
    prob, w0 = iso.models.hyperbolic_vortices(config=1)
    sol = iso.solve(prob, iso.IsoMP(), y0=w0, dt=0.01, t1=10.0, save_every=10)
    D = np.einsum("tik,tjk->tij", sol.ys * L, sol.ys)
    assert np.allclose(D[0][np.triu_indices(3, 1)], -2.5)
    assert np.abs(D - D[0]).max() <= 1e-5
    assert np.abs(sol.y_final - w0).max() >= 0.1  # it does move


@pytest.mark.parametrize(
    ("config", "T", "exponents"), [(1, 1.0, range(1, 9)), (2, 1.0 / 16, range(11, 17))]
)
def test_second_order_against_dop853(config, T, exponents):
    """Config 2 only in its asymptotic range h <= 5e-4 (NOTES)."""
    prob, w0 = iso.models.hyperbolic_vortices(config=config)
    ref = iso.reference_solution(prob, w0, [T], rtol=1e-13, atol=1e-13)[-1]
    hs = 2.0 ** -np.array(list(exponents), dtype=float)
    errors = [
        np.abs(
            iso.solve(prob, iso.IsoMP(), y0=w0, dt=h, t1=T, diagnostics=False).y_final - ref
        ).max()
        for h in hs
    ]
    slope = loglog_slope(hs, errors)
    assert abs(slope - 2.0) <= 0.1, (slope, errors)


def test_hyperbolic_midpoint_is_a_poisson_map_for_the_weighted_structure():
    """P(w) = diag(-(2/G_i) L hat(w_i) L); the unweighted tensor is *not* preserved, the
    classical midpoint and RK4 fail (config 1, h = 0.5)."""
    prob, w0 = iso.models.hyperbolic_vortices(config=1)
    G = prob.parameters["circulations"]
    Lm = np.diag(L)

    def tensor(w, c):
        P = np.zeros((9, 9))
        for i in range(3):
            P[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = c[i] * 2.0 * Lm @ hat(w[i]) @ Lm
        return P

    def defect(method, c, h=0.5, eps=1e-5):
        def f(w):
            return iso.step(prob, method, w, h, validate=False)

        cols = []
        for a in range(9):
            d = np.zeros(9)
            d[a] = eps
            cols.append(((f(w0 + d.reshape(3, 3)) - f(w0 - d.reshape(3, 3))) / (2 * eps)).ravel())
        J = np.stack(cols, axis=-1)
        P1 = tensor(f(w0), c)
        return np.abs(J @ tensor(w0, c) @ J.T - P1).max() / np.abs(P1).max()

    fp = iso.FixedPoint(rtol=1e-16)
    isomp = iso.IsoMP(solver=fp, initial_guess="state")
    assert defect(isomp, -1.0 / G) <= 1e-9  # measured 1e-11
    assert defect(isomp, np.ones(3)) >= 1e-4
    assert defect(iso.ClassicalMidpoint(solver=fp), -1.0 / G) >= 1e-5  # measured 1e-4
    assert defect(iso.RK4(), -1.0 / G) >= 2e-7  # measured 2e-6
