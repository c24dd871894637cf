"""Brockett's double bracket flow W' = [[N, W], W] on herm(n) (paper, Section 3.2)."""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso
from helpers import loglog_slope
from isoflow.models import BROCKETT_DEFAULT_SCALE, ParameterError, brockett


def offdiag(W: np.ndarray) -> np.ndarray:
    return W - np.einsum("...ii->...i", W)[..., None] * np.eye(W.shape[-1])


# ---- the model as specified --------------------------------------------------------------------
def test_defaults():
    prob, W0 = brockett()
    n = 10
    N = np.diag(np.arange(1.0, n + 1))
    assert prob.algebra.name == "herm(10)"
    np.testing.assert_array_equal(prob.parameters["N"], N)
    assert W0.dtype == np.complex128
    assert np.array_equal(W0, W0.conj().T)
    assert np.max(np.abs(W0.imag)) > 0.05  # genuinely complex
    np.testing.assert_allclose(np.linalg.norm(W0, 2), BROCKETT_DEFAULT_SCALE, rtol=1e-13)
    # seeded: reproducible, and different seeds differ
    np.testing.assert_array_equal(brockett(seed=0)[1], W0)
    assert not np.allclose(brockett(seed=1)[1], W0)
    # B(W) = [N, W] (skew-Hermitian), the flow is [[N, W], W], lyapunov = Re Tr(W N)
    W = prob.algebra.random(seed=5)
    np.testing.assert_allclose(prob.B(W), N @ W - W @ N, rtol=1e-15, atol=0)
    assert prob.algebra.normalizer.contains(prob.B(W))
    NW = N @ W - W @ N
    np.testing.assert_allclose(prob.vector_field(W), NW @ W - W @ NW, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(prob.lyapunov(W), np.trace(W @ N).real, rtol=1e-14)
    assert prob.hamiltonian is None


def test_nondiagonal_N_is_conjugate_to_diagonal():
    """With N = U D U^H, V = U^H W U solves the flow with diag D: the general-N path agrees."""
    n = 6
    D = np.arange(1.0, n + 1)
    U = np.linalg.qr(iso.algebras.u(n).random(seed=1) + np.eye(n))[0]
    N = U @ np.diag(D) @ U.conj().T
    prob_D, V0 = brockett(n=n, seed=3)
    prob_N, W0 = brockett(n=n, N=N, W0=U @ V0 @ U.conj().T)
    W = prob_N.algebra.random(seed=4)
    np.testing.assert_allclose(prob_N.lyapunov(W), np.trace(W @ N).real, rtol=1e-13)
    sol_D = iso.solve(prob_D, iso.IsoMP(), V0, dt=0.1, n_steps=50)
    sol_N = iso.solve(prob_N, iso.IsoMP(), W0, dt=0.1, n_steps=50)
    back = np.swapaxes(U.conj(), -1, -2) @ sol_N.ys @ U
    np.testing.assert_allclose(back, sol_D.ys, rtol=0, atol=1e-12)
    # a 1-d N is the diagonal
    prob_v, _ = brockett(n=n, N=D)
    np.testing.assert_array_equal(prob_v.B(W), prob_D.B(W))


# ---- the paper's experiment: n = 10, h = 0.1, T = 1000 -------------------------------------------
@pytest.fixture(scope="module")
def paper_run():
    prob, W0 = brockett(n=10, seed=0)
    return prob, W0, iso.solve(prob, iso.IsoMP(), W0, dt=0.1, t1=1000.0)


def test_paper_run_sorts_eigenvalues(paper_run):
    _, W0, sol = paper_run
    assert sol.success and sol.ys.shape == (10001, 10, 10)
    assert sol.ys.dtype == np.complex128
    # complex arithmetic end to end: the imaginary parts are carried, not dropped
    assert np.max(np.abs(sol.ys[100].imag)) > 1e-3
    lam = np.linalg.eigvalsh(W0)
    # eigenvalues preserved to rounding (relative to ||W0||): measured 3e-15
    assert sol.diagnostics.casimir_drift <= 1e-13
    WT = sol.y_final
    # W(T) diagonal (measured 1.3e-14) with the eigenvalues ascending, as N = diag(1..n)
    assert np.max(np.abs(offdiag(WT))) <= 1e-10
    diag = np.diag(WT)
    assert np.max(np.abs(diag.imag)) <= 1e-15
    assert np.all(np.diff(diag.real) > 0)
    np.testing.assert_allclose(diag.real, lam, rtol=0, atol=1e-12)
    # the state stays exactly Hermitian
    assert np.array_equal(sol.ys, np.conj(np.swapaxes(sol.ys, -1, -2)))


def test_paper_run_trace_WN_non_decreasing(paper_run):
    _, W0, sol = paper_run
    L = sol.diagnostics.lyapunov
    np.testing.assert_allclose(L, np.einsum("tii,i->t", sol.ys, np.arange(1.0, 11)).real)
    # every step, to rounding: measured largest decrease 0 (<= 5e-15 for other seeds)
    assert sol.diagnostics.lyapunov_max_decrease <= 1e-13 * np.max(np.abs(L))
    # strictly increasing while the state is away from the limit
    moving = np.max(np.abs(offdiag(sol.ys[:-1])), axis=(-2, -1)) > 1e-4
    assert moving[:100].all()
    assert np.all(np.diff(L)[moving] > 0)
    # and the limit is the maximum of Tr(WN) on the orbit: sum_i i * lambda_i (ascending)
    np.testing.assert_allclose(L[-1], np.arange(1.0, 11) @ np.linalg.eigvalsh(W0), rtol=1e-13)


def test_second_order_against_dop853():
    prob, W0 = brockett(n=10, seed=0)
    T = 2.0
    ref = iso.reference_solution(prob, W0, [T], rtol=1e-13, atol=1e-13)[-1]
    hs = np.array([0.1, 0.05, 0.025, 0.0125])  # h = 0.2 is beyond the fixed point's reach
    errs = [
        np.linalg.norm(
            iso.solve(prob, iso.IsoMP(), W0, dt=h, t1=T, diagnostics=False).y_final - ref
        )
        for h in hs
    ]
    assert abs(loglog_slope(hs, errs) - 2.0) <= 0.1, errs
    assert np.iscomplexobj(ref)


def test_too_large_initial_state_is_reported():
    """The paper-size W0 (||W0|| ~ 5) does not converge at h = 0.1; this is detected."""
    prob, W0 = brockett(n=10, seed=0, scale=2.0)
    with pytest.raises(iso.ConvergenceError):
        iso.solve(prob, iso.IsoMP(), W0, dt=0.1, t1=1.0)


# ---- solvers and ensembles ---------------------------------------------------------------------
@pytest.mark.parametrize("jacobian", ["dense", "krylov"])
def test_newton_matches_fixed_point(jacobian):
    prob, W0 = brockett(n=10, seed=0)
    fp = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=10)
    nt = iso.solve(prob, iso.IsoMP(solver=iso.Newton(jacobian=jacobian)), W0, dt=0.1, n_steps=10)
    np.testing.assert_allclose(nt.ys, fp.ys, rtol=0, atol=1e-13)
    assert nt.diagnostics.casimir_drift <= 1e-13


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_newton_with_exact_linear_jvp():
    """The exact ``B_jvp`` vanishes on diagonal directions; Newton must still work (this used
    to overflow to inf * 0 = NaN in the polarization scale of the IsoMP Jacobian)."""
    prob, W0 = brockett(n=10, seed=0)
    assert prob.B_jvp is not None
    exact = iso.solve(prob, iso.IsoMP(solver=iso.Newton()), W0, dt=0.1, n_steps=5)
    fixed = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=5)
    np.testing.assert_allclose(exact.ys, fixed.ys, rtol=0, atol=1e-13)
    assert exact.stats.iterations_max <= 5


@pytest.mark.parametrize("solver", [iso.FixedPoint(), iso.Newton()], ids=["fixed", "newton"])
def test_ensemble_equals_separate_runs(solver):
    prob, _ = brockett(n=10)
    ensemble = np.stack([brockett(n=10, seed=s)[1] for s in range(3)])
    n_steps = 300 if isinstance(solver, iso.FixedPoint) else 5
    method = iso.IsoMP(solver=solver)
    together = iso.solve(prob, method, ensemble, dt=0.1, n_steps=n_steps)
    for k in range(3):
        alone = iso.solve(prob, method, ensemble[k], dt=0.1, n_steps=n_steps)
        np.testing.assert_allclose(together.ys[:, k], alone.ys, rtol=0, atol=1e-13)
    assert np.all(together.diagnostics.lyapunov_max_decrease <= 1e-13)


# ---- bad parameters ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"n": 1}, ParameterError),
        ({"scale": 0.0}, ParameterError),
        ({"scale": -1.0}, ParameterError),
        ({"scale": np.inf}, ParameterError),
        ({"scale": "big"}, ParameterError),
        ({"N": np.ones((3, 3))}, iso.ShapeError),
        ({"N": np.triu(np.ones((10, 10)))}, ParameterError),
        ({"N": np.arange(10) * 1j}, ParameterError),
        ({"N": np.full(10, np.nan)}, iso.NonFiniteError),
        ({"W0": np.triu(np.ones((10, 10)))}, iso.NotInSpaceError),
        ({"W0": np.eye(4)}, iso.ShapeError),
    ],
)
def test_bad_parameters_raise(kwargs, error):
    with pytest.raises(error) as info:
        brockett(**kwargs)
    assert isinstance(info.value, iso.IsoflowError)
    assert isinstance(info.value, ValueError)
