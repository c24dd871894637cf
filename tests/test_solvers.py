"""Nonlinear solvers: agreement, failure detection and reporting, per-member convergence."""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso
from helpers import initial_state, random_problem
from isoflow._solve import RUN_FAILED

SOLVERS = {
    "fixed_point": iso.FixedPoint(),
    "newton_dense": iso.Newton(),
    "newton_krylov": iso.Newton(jacobian="krylov"),
}


@pytest.mark.parametrize("key", ["so4", "herm3", "sp4", "glC3"])
@pytest.mark.parametrize("solver", ["newton_dense", "newton_krylov"])
def test_newton_and_fixed_point_agree(key: str, solver: str) -> None:
    prob = random_problem(key, seed=23, nonlinear=True)
    W0 = initial_state(prob.algebra, 3)
    a = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=20, diagnostics=False)
    b = iso.solve(
        prob, iso.IsoMP(solver=SOLVERS[solver]), W0, dt=0.1, n_steps=20, diagnostics=False
    )
    assert float(np.max(np.abs(a.ys - b.ys))) <= 1e-12
    assert b.stats.iterations_mean < a.stats.iterations_mean  # Newton converges faster


def test_newton_with_exact_jacobian_is_quadratic() -> None:
    """With ``B_jvp`` Newton needs very few iterations from ``X = W``."""
    alg = iso.algebras.so(5)
    D = np.add.outer(np.arange(1.0, 6.0), np.arange(1.0, 6.0)) / 10

    def B(W):
        return -D * W

    exact = iso.IsospectralProblem(B=B, algebra=alg, B_jvp=lambda W, dW: -D * dW)
    fd = iso.IsospectralProblem(B=B, algebra=alg)
    W0 = initial_state(alg, 4, norm=2.0)
    meth = iso.IsoMP(solver=iso.Newton(), initial_guess="state")
    s_exact = iso.solve(exact, meth, W0, dt=0.2, n_steps=10, diagnostics=False)
    s_fd = iso.solve(fd, meth, W0, dt=0.2, n_steps=10, diagnostics=False)
    assert float(np.max(np.abs(s_exact.ys - s_fd.ys))) <= 1e-13
    assert s_exact.stats.iterations_max <= 4


@pytest.mark.parametrize(
    "solver", [iso.FixedPoint(), iso.Newton(max_iter=3), iso.Newton(jacobian="krylov", max_iter=3)]
)
def test_too_large_step_raises_convergence_error(solver: iso.FixedPoint | iso.Newton) -> None:
    """Fixed point diverges for ``h ||B|| >> 2``. Newton on so(n) still finds *a* root there (off
    the consistent branch; see the Newton docstring), so its failure is exercised through the
    iteration budget: it needs ~15 iterations at this step."""
    prob = random_problem("so4", seed=29, nonlinear=True)
    W0 = initial_state(prob.algebra, 5, norm=3.0)
    with pytest.raises(iso.ConvergenceError, match="did not converge") as info:
        iso.solve(prob, iso.IsoMP(solver=solver), W0, dt=5.0, n_steps=3)
    err = info.value
    assert err.step == 0 and err.time == 0.0
    assert err.reason in {"max_iter", "diverged", "non_finite"}
    assert isinstance(err, RuntimeError) and isinstance(err, iso.IsoflowError)


def test_throw_false_returns_partial_solution() -> None:
    """A failing step mid-run: the states so far come back, with success=False."""
    alg = iso.algebras.so(3)
    calls = {"n": 0}

    def B(W):
        calls["n"] += 1
        # blows up after a while: the solve at that point cannot converge
        return -W * (1.0 if calls["n"] < 60 else 1e6)

    prob = iso.IsospectralProblem(B=B, algebra=alg)
    W0 = initial_state(alg, 6)
    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=100, save_every=3, throw=False)
    assert not sol.success and sol.status == RUN_FAILED
    assert "did not converge" in sol.message
    assert 1 < len(sol.ts) < 35
    # the last saved state is the last good state, at its own time
    assert sol.ts[-1] == pytest.approx(sol.stats.n_steps * 0.1)
    assert np.all(np.isfinite(sol.ys))
    assert float(np.max(np.abs(alg.casimirs(sol.ys[-1]) - alg.casimirs(W0)))) <= 1e-13


def test_per_member_failure_is_reported_not_accepted() -> None:
    prob = random_problem("so4", seed=31, nonlinear=True)
    W0s = np.stack([initial_state(prob.algebra, 7), initial_state(prob.algebra, 8, norm=40.0)])
    with pytest.raises(iso.ConvergenceError, match="1 of 2 ensemble member"):
        iso.solve(prob, iso.IsoMP(), W0s, dt=0.5, n_steps=2)


def test_an_ensembles_failure_message_says_what_is_left() -> None:
    prob, W0 = iso.models.rigid_body(3)
    some = iso.solve(prob, iso.IsoMP(), np.stack([W0, 100 * W0]), dt=0.5, n_steps=3,
                     throw=False, progress=False)  # fmt: skip
    assert "1 of 2" in some.message and "The other members took every step." in some.message
    assert some.message.endswith(
        "Reduce dt (h * ||B(W)|| should stay well below 2) or change the solver."
    )
    every = iso.solve(prob, iso.IsoMP(), np.stack([300 * W0, 100 * W0]), dt=0.5, n_steps=3,
                      throw=False, progress=False)  # fmt: skip
    assert "2 of 2" in every.message and "No member is left." in every.message
    assert "other members" not in every.message


def test_stopping_rule_parameters_are_checked() -> None:
    with pytest.raises(ValueError, match="max_iter"):
        iso.FixedPoint(max_iter=0)
    with pytest.raises(ValueError, match="tolerances"):
        iso.FixedPoint(rtol=0.0, atol=0.0)
    with pytest.raises(iso.ParameterError, match="jacobian must be 'dense' or 'krylov'"):
        iso.Newton(jacobian="banana")  # type: ignore[arg-type]
    for bad in (-1, 0, 2.5, True):  # -1 ended in an UnboundLocalError inside the solve
        with pytest.raises(iso.ParameterError, match="krylov_max_restarts must be an integer"):
            iso.Newton(jacobian="krylov", krylov_max_restarts=bad)  # type: ignore[arg-type]
    for bad in (-1.0, 0.0, 1.0, float("nan"), "1e-7"):
        with pytest.raises(
            iso.ParameterError, match=r"krylov_rtol must be a real number in \(0, 1\)"
        ):
            iso.Newton(jacobian="krylov", krylov_rtol=bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="initial_guess"):
        iso.IsoMP(initial_guess="zero")  # type: ignore[arg-type]


def test_stall_at_rounding_floor_is_accepted() -> None:
    """An unreachable tolerance (below rounding) still converges via the stall rule."""
    prob = random_problem("so4", seed=37)
    W0 = initial_state(prob.algebra, 9)
    strict = iso.IsoMP(solver=iso.FixedPoint(rtol=1e-30, stall_rtol=1e-12))
    sol = iso.solve(prob, strict, W0, dt=0.1, n_steps=10)
    assert sol.success
    assert sol.stats.residual_max <= 1e-12 * float(prob.algebra.norm(W0))
