"""The generalized rigid body on so(n) (paper, Section 3.1, with the symmetrized inertia operator of
the corrections to the paper in ``docs/theory/method.rst``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import isoflow as iso
from helpers import loglog_slope
from isoflow.models import ParameterError, rigid_body

PAPER_D = np.array([1, 1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 5, 1 / 4, 1 / 3, 1 / 2, 1])


def hat(a: np.ndarray) -> np.ndarray:
    """``hat(a) b = a x b``: ``W_32 = a_1``, ``W_13 = a_2``, ``W_21 = a_3``."""
    W = np.zeros((*a.shape[:-1], 3, 3))
    W[..., 2, 1], W[..., 1, 2] = a[..., 0], -a[..., 0]
    W[..., 0, 2], W[..., 2, 0] = a[..., 1], -a[..., 1]
    W[..., 1, 0], W[..., 0, 1] = a[..., 2], -a[..., 2]
    return W


# ---- the model as specified --------------------------------------------------------------------
def test_paper_defaults():
    prob, W0 = rigid_body()
    assert prob.algebra.name == "so(10)"
    np.testing.assert_array_equal(prob.parameters["d"], PAPER_D)
    expected_W0 = np.array([[np.sign(j - i) * 0.1 for j in range(10)] for i in range(10)])
    np.testing.assert_array_equal(W0, expected_W0)
    # I^{-1} W computed entry by entry from the corrected formula (docs/theory/method.rst)
    W = prob.algebra.random(seed=3)
    IW = np.array([[(PAPER_D[i] + PAPER_D[j]) / 2 * W[i, j] for j in range(10)] for i in range(10)])
    np.testing.assert_allclose(prob.B(W), -IW, rtol=1e-15, atol=0)
    assert prob.algebra.contains(prob.B(W))
    np.testing.assert_allclose(prob.hamiltonian(W), 0.5 * np.trace(IW.T @ W), rtol=1e-14)
    np.testing.assert_allclose(prob.vector_field(W), -(IW @ W - W @ IW), rtol=1e-13, atol=1e-15)


def test_W0_override_and_batch():
    alg = iso.algebras.so(4)
    Ws = alg.random(seed=1, batch=(2,))
    prob, W0 = rigid_body(n=4, W0=Ws)
    np.testing.assert_allclose(W0, Ws, rtol=0, atol=1e-15)
    assert prob.hamiltonian(W0).shape == (2,)


def test_inertia_forms_are_consistent():
    rng = np.random.default_rng(0)
    n = 5
    d = rng.uniform(0.5, 2.0, n)
    prob_d, _ = rigid_body(n=n, d=d)
    plane = 2.0 / (d[:, None] + d[None, :])
    prob_I, _ = rigid_body(n=n, inertia=plane)
    W = iso.algebras.so(n).random(seed=2)
    np.testing.assert_allclose(prob_I.B(W), prob_d.B(W), rtol=1e-14, atol=0)
    # Manakov's body: I_ij = J_i + J_j, i.e. M = J Omega + Omega J
    J = rng.uniform(0.5, 2.0, n)
    prob_J, _ = rigid_body(n=n, inertia=J[:, None] + J[None, :])
    Omega = -prob_J.B(W)
    np.testing.assert_allclose(np.diag(J) @ Omega + Omega @ np.diag(J), W, rtol=1e-13, atol=1e-15)
    # n = 3 principal moments: plane (j, k) carries I_i
    prob_3, _ = rigid_body(n=3, inertia=(1.0, 2.0, 3.0))
    I_plane = np.array([[1.0, 3.0, 2.0], [3.0, 1.0, 1.0], [2.0, 1.0, 1.0]])
    np.testing.assert_array_equal(
        prob_3.parameters["inertia"][~np.eye(3, dtype=bool)], I_plane[~np.eye(3, dtype=bool)]
    )


# ---- the paper's experiment: n = 10, h = 0.1, T = 100 --------------------------------------------
@pytest.fixture(scope="module")
def paper_run():
    prob, W0 = rigid_body()
    return prob, W0, iso.solve(prob, iso.IsoMP(), W0, dt=0.1, t1=100.0)


def test_paper_run_invariants(paper_run):
    _, W0, sol = paper_run
    assert sol.success and sol.ys.shape == (1001, 10, 10)
    d = sol.diagnostics
    # eigenvalues of iW relative to ||W0||: measured 1.9e-14
    assert d.casimir_drift <= 1e-13
    eig = np.linalg.eigvalsh(1j * sol.ys)
    assert np.max(np.abs(eig - eig[0])) <= 1e-13 * np.linalg.norm(W0)
    # the state is exactly skew (every step is projected), as computed directly
    assert np.array_equal(sol.ys, -np.swapaxes(sol.ys, -1, -2))
    assert d.max_distance == 0.0
    # H is not a Casimir: an O(h^2) oscillation, measured 7.6e-6 relative
    assert 1e-8 < d.hamiltonian_relative_drift <= 2e-5


def test_hamiltonian_bounded_without_secular_drift():
    """T = 1000 (10^4 steps): the H error of the last tenth is no larger than of the first."""
    prob, W0 = rigid_body()
    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, t1=1000.0, save_every=5)
    dH = sol.diagnostics.hamiltonian - sol.diagnostics.hamiltonian[0]
    m = len(dH) // 10
    first, last = np.max(np.abs(dH[:m])), np.max(np.abs(dH[-m:]))
    # measured: first tenth 1.55e-6, last tenth 4.5e-7
    assert last <= 1.5 * first
    # least-squares trend over the whole run: measured 4.8e-8 over T, vs amplitude 1.6e-6
    slope = np.polyfit(sol.ts, dH, 1)[0]
    assert abs(slope) * sol.ts[-1] <= 0.1 * np.max(np.abs(dH))
    assert sol.diagnostics.casimir_drift <= 1e-13  # measured 7.5e-14 after 10^4 steps


def test_hamiltonian_error_is_second_order(paper_run):
    prob, W0, sol = paper_run
    sol_half = iso.solve(prob, iso.IsoMP(), W0, dt=0.05, t1=100.0, save_every=2)
    ratio = sol.diagnostics.hamiltonian_drift / sol_half.diagnostics.hamiltonian_drift
    assert 3.5 <= ratio <= 4.5  # measured 4.0


def test_second_order_against_dop853():
    prob, W0 = rigid_body()
    T = 10.0
    ref = iso.reference_solution(prob, W0, [T], rtol=1e-13, atol=1e-13)[-1]
    hs = np.array([0.4, 0.2, 0.1, 0.05])
    errs = [
        np.linalg.norm(
            iso.solve(prob, iso.IsoMP(), W0, dt=h, t1=T, diagnostics=False).y_final - ref
        )
        for h in hs
    ]
    slope = loglog_slope(hs, errs)
    assert abs(slope - 2.0) <= 0.1, (slope, errs)  # measured 1.993
    assert errs[-1] < 2e-4


# ---- n = 3 against Euler's equations written with vectors ----------------------------------------
def test_n3_agrees_with_vector_euler_equations():
    moments = np.array([1.0, 2.0, 3.0])
    m0 = np.array([0.3, -1.1, 0.7])
    prob, _ = rigid_body(n=3, inertia=tuple(moments))
    W0 = hat(m0)

    def euler(_t, m):  # m' = m x omega, omega_k = m_k / I_k
        return np.cross(m, m / moments)

    # the angular velocity is hat(omega): Omega_32 = m_1 / I_1, Omega_13 = m_2 / I_2, ...
    np.testing.assert_allclose(-prob.B(W0), hat(m0 / moments), rtol=1e-15, atol=0)
    # the vector field at random points, mapped through the hat map
    rng = np.random.default_rng(7)
    for m in rng.standard_normal((5, 3)):
        np.testing.assert_allclose(
            prob.vector_field(hat(m)), hat(euler(0.0, m)), rtol=1e-14, atol=1e-15
        )
    # H with the Frobenius pairing is twice the classical kinetic energy
    np.testing.assert_allclose(prob.hamiltonian(W0), np.sum(m0**2 / moments), rtol=1e-15)

    # trajectories: independent DOP853 on the 3-vector ODE vs the model's matrix ODE
    ts = np.linspace(0.0, 10.0, 11)
    vec = solve_ivp(euler, (0, 10), m0, method="DOP853", t_eval=ts, rtol=1e-13, atol=1e-13)
    mat = iso.reference_solution(prob, W0, ts)
    np.testing.assert_allclose(mat, hat(vec.y.T), rtol=0, atol=1e-11)

    # IsoMP converges to the vector solution at second order
    errs = []
    hs = np.array([0.1, 0.05, 0.025])
    for h in hs:
        sol = iso.solve(prob, iso.IsoMP(), W0, dt=h, t1=10.0, diagnostics=False)
        errs.append(np.max(np.abs(sol.y_final - hat(vec.y[:, -1]))))
    assert abs(loglog_slope(hs, errs) - 2.0) <= 0.1


# ---- solvers and ensembles ---------------------------------------------------------------------
@pytest.mark.parametrize("jacobian", ["dense", "krylov"])
def test_newton_matches_fixed_point(jacobian):
    prob, W0 = rigid_body()
    fp = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=20)
    nt = iso.solve(prob, iso.IsoMP(solver=iso.Newton(jacobian=jacobian)), W0, dt=0.1, n_steps=20)
    assert nt.stats.iterations_max <= 5  # exact Jacobian (B_jvp): quadratic convergence
    np.testing.assert_allclose(nt.ys, fp.ys, rtol=0, atol=1e-13)
    assert nt.diagnostics.casimir_drift <= 1e-13


@pytest.mark.parametrize("solver", [iso.FixedPoint(), iso.Newton()], ids=["fixed", "newton"])
def test_ensemble_equals_separate_runs(solver):
    prob, W0 = rigid_body()
    alg = prob.algebra
    ensemble = np.stack([W0, alg.random(seed=1, scale=0.05), alg.random(seed=2, scale=0.1)])
    n_steps = 200 if isinstance(solver, iso.FixedPoint) else 10
    method = iso.IsoMP(solver=solver)
    together = iso.solve(prob, method, ensemble, dt=0.1, n_steps=n_steps)
    assert together.ys.shape == (n_steps + 1, 3, 10, 10)
    for k in range(3):
        alone = iso.solve(prob, method, ensemble[k], dt=0.1, n_steps=n_steps)
        np.testing.assert_allclose(together.ys[:, k], alone.ys, rtol=0, atol=1e-13)
    assert np.all(together.diagnostics.casimir_drift <= 1e-13)


# ---- bad parameters ----------------------------------------------------------------------------
def _nonsymmetric_plane():
    plane = np.ones((4, 4))
    plane[0, 1] = 2.0
    return plane


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"n": 1}, ParameterError),
        ({"n": 2.5}, ParameterError),
        ({"n": True}, ParameterError),
        ({"n": 3, "inertia": (1.0, -2.0, 3.0)}, ParameterError),
        ({"n": 3, "inertia": (1.0, 0.0, 3.0)}, ParameterError),
        ({"n": 4, "inertia": -np.ones((4, 4))}, ParameterError),
        ({"n": 4, "inertia": _nonsymmetric_plane()}, ParameterError),
        ({"n": 4, "inertia": (1.0, 2.0, 3.0, 4.0)}, iso.ShapeError),
        ({"n": 3, "inertia": (1.0, 2.0)}, iso.ShapeError),
        ({"n": 4, "inertia": np.ones((3, 3))}, iso.ShapeError),
        ({"n": 3, "inertia": (1.0, np.nan, 3.0)}, iso.NonFiniteError),
        ({"n": 3, "inertia": (1.0, 2j, 3.0)}, iso.DtypeError),
        ({"n": 3, "inertia": ("a", "b", "c")}, iso.DtypeError),
        ({"n": 3, "inertia": (1.0, 2.0, 3.0), "d": (1.0, 1.0, 1.0)}, ParameterError),
        ({"n": 4, "d": (1.0, 1.0, 1.0)}, iso.ShapeError),
        ({"n": 3, "d": (1.0, -1.0, 1.0)}, ParameterError),
        ({"n": 3, "W0": np.eye(3)}, iso.NotInSpaceError),
        ({"n": 3, "W0": np.zeros((4, 4))}, iso.ShapeError),
    ],
)
def test_bad_parameters_raise(kwargs, error):
    with pytest.raises(error) as info:
        rigid_body(**kwargs)
    assert isinstance(info.value, iso.IsoflowError)
    if error is not iso.DtypeError:
        assert isinstance(info.value, ValueError)
