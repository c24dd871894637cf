"""IsoSyRK (isospectral symplectic Gauss–Legendre RK): tableau, s = 1 is IsoMP, orders 4 and 6,
stages in V, spectrum and space over long runs, symmetry, Lie–Poisson, ensembles, failures."""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso
from helpers import (
    ALGEBRA_FACTORIES,
    hamiltonian_problem,
    initial_state,
    loglog_slope,
    random_problem,
    spectrum_backward_error,
)
from isoflow._solve import RUN_FAILED
from isoflow.algebras import Stacked
from isoflow.methods.isosyrk import _stages_from_B, gauss_legendre
from isoflow.registry import build
from test_lie_poisson import _defect
from test_lie_poisson import _problem as lp_problem


@pytest.mark.parametrize("s", [1, 2, 3])
def test_gauss_tableau(s: int) -> None:
    """Symplectic (b_i a_ij + b_j a_ji = b_i b_j), quadrature order 2s (B(2s)), stage order s
    (C(s)), symmetric nodes: the conditions that make it the order-2s Gauss method."""
    A, b, c = gauss_legendre(s)
    M = b[:, None] * A + (b[:, None] * A).T - np.outer(b, b)
    assert np.max(np.abs(M)) <= 1e-15
    for k in range(1, 2 * s + 1):
        assert abs(b @ c ** (k - 1) - 1.0 / k) <= 1e-15
    for k in range(1, s + 1):
        assert np.max(np.abs(A @ c ** (k - 1) - c**k / k)) <= 1e-15
    assert np.allclose(c + c[::-1], 1.0, rtol=0, atol=1e-15) and np.allclose(A.sum(1), c)


@pytest.mark.parametrize("key", list(ALGEBRA_FACTORIES))
def test_one_stage_is_isomp(key: str) -> None:
    prob = random_problem(key, seed=7, nonlinear=True)
    W0 = initial_state(prob.algebra, 4)
    a = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=20, diagnostics=False).ys[-1]
    b = iso.solve(prob, iso.IsoSyRK(1), W0, dt=0.1, n_steps=20, diagnostics=False).ys[-1]
    assert np.max(np.abs(a - W0)) > 1e-2  # it moved
    assert float(np.max(np.abs(a - b))) <= 1e-13  # measured <= 7e-15 (same fixed point)


@pytest.mark.parametrize("key", list(ALGEBRA_FACTORIES))
@pytest.mark.parametrize("s", [2, 3])
def test_stages_lie_in_the_space(key: str, s: int) -> None:
    r"""``R_i W S_i`` lies in the stage space for *any* stage values (the reason the unknowns
    are s copies of V): checked before the projection, for random stages."""
    prob = random_problem(key, seed=7, nonlinear=True)
    alg = prob.algebra
    W = initial_state(alg, 4)
    X = alg.stage_algebra.project(np.stack([initial_state(alg, 10 + i) for i in range(s)]))
    A, _, _ = gauss_legendre(s)
    raw = _stages_from_B(alg, 0.3 * A, prob.evaluate_B(X), W)
    assert float(np.max(Stacked(alg.stage_algebra, s).distance(raw))) <= 1e-15


# ---- accuracy -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("s", "norm", "ns"), [(2, 1.0, [8, 12, 16, 24, 32]), (3, 2.0, [8, 12, 16, 24, 32])]
)
def test_observed_order_against_dop853(s: int, norm: float, ns: list[int]) -> None:
    """Errors at T = 1 from ~1e-6 down to ~1e-10, far above the reference (~1e-13)."""
    prob = hamiltonian_problem(iso.algebras.so(4), seed=11, nonlinear=True)
    W0 = initial_state(prob.algebra, 6, norm=norm)
    ref = iso.reference_solution(prob, W0, [1.0], rtol=1e-13, atol=1e-13)[-1]
    errs = []
    for n in ns:
        sol = iso.solve(prob, iso.IsoSyRK(s), W0, dt=1.0 / n, n_steps=n, diagnostics=False)
        errs.append(float(np.linalg.norm(sol.ys[-1] - ref)))
    slope = loglog_slope(1.0 / np.array(ns), np.array(errs))
    assert abs(slope - 2 * s) <= 0.15, (slope, errs)  # measured 3.999, 5.987
    assert errs[-1] > 1e-11 and errs[0] < 1e-3, errs


@pytest.mark.parametrize("key", ["herm3", "sp4"])
def test_order_on_other_spaces(key: str) -> None:
    prob = random_problem(key, seed=11, nonlinear=True)
    W0 = initial_state(prob.algebra, 6)
    ref = iso.reference_solution(prob, W0, [1.0])[-1]
    ns = np.array([4, 6, 8, 12])
    errs = [
        np.linalg.norm(iso.solve(prob, iso.IsoSyRK(2), W0, dt=1 / n, n_steps=n).ys[-1] - ref)
        for n in ns
    ]
    assert abs(loglog_slope(1.0 / ns, np.array(errs)) - 4.0) <= 0.15, errs


# ---- structure ----------------------------------------------------------------------------------
@pytest.mark.parametrize("key", ["so4", "u3", "su3", "sym4", "herm3"])
def test_spectrum_preserved_over_many_steps(key: str) -> None:
    prob = random_problem(key, seed=3, nonlinear=True)
    W0 = initial_state(prob.algebra, 1)
    sol = iso.solve(prob, iso.IsoSyRK(2), W0, dt=0.05, n_steps=500, save_every=500)
    assert sol.success
    assert np.linalg.norm(sol.ys[-1] - W0) > 1e-2 * np.linalg.norm(W0)
    assert spectrum_backward_error(W0, sol.ys[-1]) <= 1e-12 * np.linalg.norm(W0, 2)
    assert float(np.max(sol.diagnostics.max_distance)) <= 1e-14


def test_long_run_stays_in_the_space() -> None:
    """3000 steps on the paper's rigid body: exactly skew (every stage and state is projected)
    and the eigenvalues kept to rounding, for s = 2 and 3 (measured drift 3e-15)."""
    prob, W0 = iso.models.rigid_body(n=6)
    for s in (2, 3):
        sol = iso.solve(prob, iso.IsoSyRK(s), W0, dt=0.1, n_steps=3000, save_every=300)
        assert sol.success
        assert np.array_equal(sol.ys, -np.swapaxes(sol.ys, -1, -2))
        assert float(sol.diagnostics.casimir_drift) <= 1e-13
        assert float(sol.diagnostics.hamiltonian_relative_drift) <= 1e-9  # 6e-11, 4e-14: O(h^2s)


@pytest.mark.parametrize("model", ["spin", "vortices"])
def test_compact_forms(model: str) -> None:
    """On (R^3, x)^N and (R^3, x_L)^N through hat and phi: Casimirs kept, and the answer is
    that of the same method on the 3x3 / 2x2 matrices (one particle)."""
    if model == "spin":
        prob, w0 = iso.models.heisenberg_chain(N=12)
        dt = 0.05
    else:
        prob, w0 = iso.models.hyperbolic_vortices(config=1)
        dt = 0.01
    sol = iso.solve(prob, iso.IsoSyRK(3), w0, dt=dt, n_steps=300, save_every=100)
    assert sol.success and np.max(np.abs(sol.ys[-1] - w0)) > 1e-2
    assert float(np.max(sol.diagnostics.casimir_drift)) <= 1e-13
    # one particle in a fixed field, vector form against matrix form
    vec = iso.algebras.so3_vectors(1) if model == "spin" else iso.algebras.sl2_vectors(1)
    mat = iso.algebras.so(3) if model == "spin" else iso.algebras.sl2()
    rng = np.random.default_rng(0)
    K = rng.standard_normal((1, 3))

    def B_vec(w):
        return K + 0.5 * w * np.sum(w * w, axis=-1, keepdims=True)

    def B_mat(W):
        return vec.to_matrix(B_vec(vec.from_matrix(W)[..., None, :]))[..., 0, :, :]

    w = rng.standard_normal((1, 3))
    a = iso.step(iso.IsospectralProblem(B=B_vec, algebra=vec), iso.IsoSyRK(2), w, 0.2)
    b = iso.step(
        iso.IsospectralProblem(B=B_mat, algebra=mat), iso.IsoSyRK(2), vec.to_matrix(w)[0], 0.2
    )
    assert float(np.max(np.abs(vec.to_matrix(a)[0] - b))) <= 1e-14


@pytest.mark.parametrize("key", ["so4", "u3", "sp4", "glR3", "herm3"])
@pytest.mark.parametrize("s", [2, 3])
def test_step_is_symmetric(key: str, s: int) -> None:
    prob = random_problem(key, seed=5, nonlinear=True)
    W0 = initial_state(prob.algebra, 2)
    h = 0.1
    W1 = iso.step(prob, iso.IsoSyRK(s), W0, h)
    back = iso.step(prob, iso.IsoSyRK(s), W1, -h)
    assert float(np.max(np.abs(W1 - W0))) > 1e-3
    assert float(np.max(np.abs(back - W0))) <= 1e-14


@pytest.mark.parametrize("n", [3, 4])
def test_isosyrk_is_lie_poisson(n: int) -> None:
    """Modin–Viviani Thm. 3: a Poisson map for B = (grad H)^T (measured defect ~1e-11, the
    finite-difference noise; RK4: 6e-7 and 3e-5)."""
    prob = lp_problem(n)
    tight = iso.FixedPoint(rtol=1e-15, stall_rtol=1e-13)
    for s in (2, 3):
        assert _defect(prob, iso.IsoSyRK(s, solver=tight), 0.5) <= 1e-9


# ---- solver, warm start, ensembles, failures ----------------------------------------------------
def test_newton_and_fixed_point_agree() -> None:
    prob = random_problem("so4", seed=9, nonlinear=True)
    W0 = initial_state(prob.algebra, 3)
    a, ra = iso.step(prob, iso.IsoSyRK(3), W0, 0.2, return_info=True)
    b, rb = iso.step(prob, iso.IsoSyRK(3, solver=iso.Newton()), W0, 0.2, return_info=True)
    assert float(np.max(np.abs(a - b))) <= 1e-14
    assert int(rb.iterations) < int(ra.iterations)
    assert ra.stage.shape == (3, 4, 4)


def test_extrapolated_warm_start_saves_iterations_same_answer() -> None:
    prob, W0 = iso.models.rigid_body(n=6)
    W0 = 5 * W0
    a = iso.solve(prob, iso.IsoSyRK(2, initial_guess="state"), W0, dt=0.05, n_steps=200)
    b = iso.solve(prob, iso.IsoSyRK(2), W0, dt=0.05, n_steps=200)
    assert float(np.max(np.abs(a.ys - b.ys))) <= 1e-12
    assert b.stats.iterations_mean < 0.75 * a.stats.iterations_mean  # measured 4.9 vs 8.3


def test_default_start_is_isomps_degree_on_the_maps_offsets() -> None:
    """The default degree is IsoMP's for the space (6 on so(10)), the offsets are the map's
    values at the accepted stages, and the answer is the cubic start's to the tolerance."""
    prob, W0 = iso.models.rigid_body(n=10)
    assert iso.IsoSyRK(2).order_for(prob.algebra) == 6
    assert iso.IsoSyRK(2, extrapolation_order=3).order_for(prob.algebra) == 3
    cubic = iso.solve(prob, iso.IsoSyRK(2, extrapolation_order=3), W0, dt=0.1, n_steps=200)
    default = iso.solve(prob, iso.IsoSyRK(2), W0, dt=0.1, n_steps=200)
    assert float(np.max(np.abs(cubic.ys - default.ys))) <= 1e-12
    # measured 2.05 against 4.02 iterations a step
    assert default.stats.iterations_mean < 0.6 * cubic.stats.iterations_mean
    method = iso.IsoSyRK(2)
    y, state = W0, None
    for _ in range(8):
        prev = y
        res = method.step(prob, y, 0.1, state)
        y, state = res.y, res.state
    assert len(state) == 1 + 7  # (h, D_1, ..., D_7): degree 6 keeps seven offsets
    G_acc, _ = method.stage_problem(prob, prev, 0.1).G(res.stage, None)
    assert float(np.max(np.abs(state[1] - (G_acc - prev)))) <= 1e-15
    assert float(np.max(np.abs(state[1] - (res.stage - prev)))) > 0.0  # not X - W


def test_ensemble_equals_separate_runs() -> None:
    prob = random_problem("u3", seed=13, nonlinear=True)
    W0s = prob.algebra.random(21, batch=(2, 3))
    W0s *= 0.6 / prob.algebra.norm(W0s)[..., None, None]
    W0s[1, 0] *= 2.0  # members converge at different speeds
    sol = iso.solve(prob, iso.IsoSyRK(2), W0s, dt=0.1, n_steps=30, save_every=10)
    assert sol.ys.shape == (4, 2, 3, 3, 3)
    for i in range(2):
        for j in range(3):
            single = iso.solve(prob, iso.IsoSyRK(2), W0s[i, j], dt=0.1, n_steps=30, save_every=10)
            assert float(np.max(np.abs(single.ys - sol.ys[:, i, j]))) <= 1e-13


def test_non_converging_solve_fails_clearly() -> None:
    prob = random_problem("so4", seed=13, nonlinear=True)
    W0s = prob.algebra.random(21, batch=(3,))
    W0s *= 0.6 / prob.algebra.norm(W0s)[..., None, None]
    W0s[1] *= 50.0
    with pytest.raises(iso.ConvergenceError, match=r"IsoSyRK\(2\).*1 of 3") as exc:
        iso.solve(prob, iso.IsoSyRK(2), W0s, dt=0.1, n_steps=5)
    assert exc.value.reason in ("diverged", "max_iter", "non_finite")
    sol = iso.solve(prob, iso.IsoSyRK(2), W0s, dt=0.1, n_steps=5, throw=False)
    assert not sol.success and sol.status == RUN_FAILED and list(sol.failed_step) == [-1, 0, -1]
    res = iso.IsoSyRK(2).step(prob, W0s, 0.1)
    assert list(res.status == 0) == [True, False, True]
    with pytest.raises(iso.ConvergenceError):
        iso.step(prob, iso.IsoSyRK(2, solver=iso.FixedPoint(max_iter=3)), W0s[0], 0.1)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"stages": 0},
        {"stages": 4},
        {"stages": 2.0},
        {"stages": True},
        {"initial_guess": "zero"},
        {"extrapolation_order": 8},
        {"solver": "newton"},
    ],
)
def test_bad_arguments(kwargs) -> None:
    with pytest.raises(iso.ParameterError):
        iso.IsoSyRK(**kwargs)


def test_names_and_registry() -> None:
    assert [iso.IsoSyRK(s).order for s in (1, 2, 3)] == [2, 4, 6]
    assert iso.IsoSyRK(3).name == "IsoSyRK(3)" and iso.IsoSyRK.symmetric
    _, _, method, _ = build({"model": "toda", "method": "isosyrk-3", "dt": 0.1, "t1": 1.0})
    assert method == iso.IsoSyRK(3)
