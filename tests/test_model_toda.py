"""The non-periodic Toda lattice in Flaschka's variables, L' = [L_+ - L_-, L] on sym(n)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import isoflow as iso
from helpers import loglog_slope
from isoflow.models import ParameterError, jacobi_coefficients, jacobi_matrix, off_band, toda


def flaschka_rhs(_t: float, y: np.ndarray) -> np.ndarray:
    """a_i' = 2 (b_i^2 - b_{i-1}^2), b_i' = b_i (a_{i+1} - a_i), written out componentwise."""
    n = (len(y) + 1) // 2
    a, b = y[:n], y[n:]
    da = np.empty(n)
    for i in range(n):
        right = b[i] ** 2 if i < n - 1 else 0.0
        left = b[i - 1] ** 2 if i > 0 else 0.0
        da[i] = 2.0 * (right - left)
    db = np.array([b[i] * (a[i + 1] - a[i]) for i in range(n - 1)])
    return np.concatenate([da, db])


def closed_form_eigenvalues(n: int) -> np.ndarray:
    """Spectrum of the default state a = 0, b = 1, in descending order."""
    return 2.0 * np.cos(np.arange(1, n + 1) * np.pi / (n + 1))


# ---- the model as specified --------------------------------------------------------------------
def test_defaults_and_helpers():
    prob, L0 = toda()
    n = 12
    assert prob.algebra.name == "sym(12)"
    a, b = jacobi_coefficients(L0)
    np.testing.assert_array_equal(a, np.zeros(n))
    np.testing.assert_array_equal(b, np.ones(n - 1))
    np.testing.assert_array_equal(L0, jacobi_matrix(a, b))
    assert off_band(L0) == 0.0
    np.testing.assert_allclose(
        np.linalg.eigvalsh(L0)[::-1], closed_form_eigenvalues(n), rtol=0, atol=1e-14
    )
    # B(L) = L_+ - L_- on any symmetric matrix; H = Tr(L^2) / 2
    L = prob.algebra.random(seed=2)
    np.testing.assert_array_equal(prob.B(L), np.triu(L, 1) - np.tril(L, -1))
    np.testing.assert_allclose(prob.hamiltonian(L), 0.5 * np.trace(L @ L), rtol=1e-14)
    # seeded random state: reproducible, b in [0.5, 1.5)
    _, L1 = toda(seed=0)
    np.testing.assert_array_equal(toda(seed=0)[1], L1)
    b1 = jacobi_coefficients(L1)[1]
    assert np.all((b1 >= 0.5) & (b1 < 1.5))


def test_vector_field_is_flaschka_componentwise():
    prob, _ = toda()
    rng = np.random.default_rng(3)
    for _ in range(5):
        a, b = rng.standard_normal(12), rng.standard_normal(11)
        F = prob.vector_field(jacobi_matrix(a, b))
        assert off_band(F) == 0.0  # the exact flow stays tridiagonal
        da, db = jacobi_coefficients(F)
        expected = flaschka_rhs(0.0, np.concatenate([a, b]))
        np.testing.assert_allclose(np.concatenate([da, db]), expected, rtol=1e-14, atol=1e-14)


def test_matrix_ode_matches_flaschka_ode():
    """DOP853 on the matrix ODE of the model vs DOP853 on the componentwise (a, b) equations."""
    prob, L0 = toda(seed=0)
    a0, b0 = jacobi_coefficients(L0)
    ts = np.linspace(0.0, 5.0, 6)
    vec = solve_ivp(
        flaschka_rhs,
        (0, 5),
        np.concatenate([a0, b0]),
        method="DOP853",
        t_eval=ts,
        rtol=1e-13,
        atol=1e-13,
    )
    mat = iso.reference_solution(prob, L0, ts)
    np.testing.assert_allclose(mat, jacobi_matrix(vec.y[:12].T, vec.y[12:].T), rtol=0, atol=1e-11)


def test_second_order_against_dop853():
    prob, L0 = toda(seed=0)
    T = 5.0
    ref = iso.reference_solution(prob, L0, [T], rtol=1e-13, atol=1e-13)[-1]
    hs = np.array([0.1, 0.05, 0.025, 0.0125])
    errs = [
        np.linalg.norm(
            iso.solve(prob, iso.IsoMP(), L0, dt=h, t1=T, diagnostics=False).y_final - ref
        )
        for h in hs
    ]
    assert abs(loglog_slope(hs, errs) - 2.0) <= 0.1, errs


# ---- long run: invariants, band, sorting -------------------------------------------------------
@pytest.fixture(scope="module")
def long_run():
    prob, L0 = toda()
    return prob, L0, iso.solve(prob, iso.IsoMP(), L0, dt=0.1, t1=200.0)


def test_long_run_invariants(long_run):
    _, _, sol = long_run
    d = sol.diagnostics
    assert d.casimir_drift <= 1e-13  # measured 1e-14
    np.testing.assert_allclose(
        d.casimirs[-1][::-1], closed_form_eigenvalues(12), rtol=0, atol=1e-13
    )
    # H = Tr(L^2)/2 is spectral: conserved to rounding, not just O(h^2); measured 1.1e-15
    assert d.hamiltonian_relative_drift <= 1e-13
    # symmetric exactly (every state is projected onto sym(n))
    assert np.array_equal(sol.ys, np.swapaxes(sol.ys, -1, -2))


def test_off_band_is_small_and_second_order(long_run):
    """IsoMP does not keep L tridiagonal exactly: the off-band part is O(h^2) and transient."""
    prob, L0, sol = long_run
    ob = sol.diagnostics.invariants["off_band"]
    np.testing.assert_array_equal(ob, off_band(sol.ys))
    assert sol.diagnostics.invariant_drift["off_band"] == ob.max()
    # measured 2.1e-3 at h = 0.1 (peak near t = 1.4), then decays with the flow
    assert 1e-4 < ob.max() <= 4e-3
    # once sorted, the band error has decayed to rounding level (relative to ||L||)
    assert ob[-1] <= 1e-13 * np.linalg.norm(L0)
    # halving h divides the peak by 4 (measured 5.4e-4 at h = 0.05)
    half = iso.solve(prob, iso.IsoMP(), L0, dt=0.05, t1=10.0)
    ratio = ob.max() / half.diagnostics.invariants["off_band"].max()
    assert 3.5 <= ratio <= 4.5


@pytest.mark.parametrize("seed", [None, 0, 1])
def test_flow_sorts_eigenvalues_descending(seed):
    prob, L0 = toda(seed=seed)
    sol = iso.solve(prob, iso.IsoMP(), L0, dt=0.1, t1=200.0, save_every=100)
    a, b = jacobi_coefficients(sol.y_final)
    assert np.max(np.abs(b)) <= 1e-10  # measured <= 9e-12
    assert np.all(np.diff(a) < 0)
    np.testing.assert_allclose(a, np.linalg.eigvalsh(L0)[::-1], rtol=0, atol=1e-10)
    # a_1 -> lambda_max from below (a_1' = 2 b_1^2 >= 0 for the exact flow)
    assert a[0] >= np.diag(L0)[0]


# ---- solvers and ensembles ---------------------------------------------------------------------
@pytest.mark.parametrize("jacobian", ["dense", "krylov"])
def test_newton_matches_fixed_point(jacobian):
    prob, L0 = toda(seed=1)
    fp = iso.solve(prob, iso.IsoMP(), L0, dt=0.1, n_steps=20)
    nt = iso.solve(prob, iso.IsoMP(solver=iso.Newton(jacobian=jacobian)), L0, dt=0.1, n_steps=20)
    np.testing.assert_allclose(nt.ys, fp.ys, rtol=0, atol=1e-13)
    assert nt.diagnostics.casimir_drift <= 1e-13


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_newton_with_exact_linear_jvp():
    """The exact ``B_jvp`` vanishes on diagonal directions; Newton must still work (this used
    to overflow to inf * 0 = NaN in the polarization scale of the IsoMP Jacobian)."""
    prob, L0 = toda()
    assert prob.B_jvp is not None
    exact = iso.solve(prob, iso.IsoMP(solver=iso.Newton()), L0, dt=0.1, n_steps=5)
    fixed = iso.solve(prob, iso.IsoMP(), L0, dt=0.1, n_steps=5)
    np.testing.assert_allclose(exact.ys, fixed.ys, rtol=0, atol=1e-13)
    assert exact.stats.iterations_max <= 5


@pytest.mark.parametrize("solver", [iso.FixedPoint(), iso.Newton()], ids=["fixed", "newton"])
def test_ensemble_equals_separate_runs(solver):
    rng = np.random.default_rng(11)
    a, b = rng.standard_normal((3, 12)), rng.uniform(0.5, 1.5, (3, 11))
    prob, L0 = toda(a=a, b=b)
    assert L0.shape == (3, 12, 12)
    n_steps = 300 if isinstance(solver, iso.FixedPoint) else 10
    method = iso.IsoMP(solver=solver)
    together = iso.solve(prob, method, L0, dt=0.1, n_steps=n_steps)
    for k in range(3):
        alone = iso.solve(prob, method, L0[k], dt=0.1, n_steps=n_steps)
        np.testing.assert_allclose(together.ys[:, k], alone.ys, rtol=0, atol=1e-13)
    assert np.all(together.diagnostics.casimir_drift <= 1e-13)


# ---- bad parameters ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"n": 1}, ParameterError),
        ({"n": 4, "a": np.zeros(4)}, ParameterError),
        ({"n": 4, "b": np.ones(3)}, ParameterError),
        ({"n": 4, "a": np.zeros(4), "b": np.array([1.0, 0.0, 1.0])}, ParameterError),
        ({"n": 4, "a": np.zeros(4), "b": np.ones(3), "seed": 0}, ParameterError),
        ({"n": 4, "a": np.zeros(3), "b": np.ones(3)}, iso.ShapeError),
        ({"n": 4, "a": np.zeros(4), "b": np.ones(4)}, iso.ShapeError),
        ({"n": 4, "a": np.full(4, np.nan), "b": np.ones(3)}, iso.NonFiniteError),
    ],
)
def test_bad_parameters_raise(kwargs, error):
    with pytest.raises(error) as info:
        toda(**kwargs)
    assert isinstance(info.value, iso.IsoflowError)
    assert isinstance(info.value, ValueError)
