"""The solve driver: time grid, saving, stats, diagnostics, non-vectorized B, progress."""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso
from helpers import initial_state


def _rigid_body(n: int = 4) -> iso.IsospectralProblem:
    alg = iso.algebras.so(n)
    d = 1.0 / np.arange(1, n + 1)
    D = 0.5 * (d[:, None] + d[None, :])
    return iso.IsospectralProblem(
        B=lambda W: -D * W,
        algebra=alg,
        hamiltonian=lambda W: 0.5 * np.sum(D * W * W, axis=(-2, -1)),
    )


def test_time_grid_and_saving() -> None:
    prob = _rigid_body()
    W0 = initial_state(prob.algebra, 1)
    sol = iso.solve(prob, iso.IsoMP(), W0, t0=2.0, dt=0.1, t1=3.05 + 0.05, save_every=4)
    assert sol.n_steps == 11 and sol.success and sol.status == 0
    # saved at steps 0, 4, 8 and the final step 11
    np.testing.assert_allclose(sol.ts, [2.0, 2.4, 2.8, 3.1])
    assert sol.ys.shape == (4, 4, 4)
    assert sol.stats.n_steps == 11 and sol.stats.iterations_max >= sol.stats.iterations_mean > 0
    assert sol.stats.residual_max <= 1e-14 * float(prob.algebra.norm(W0))
    assert sol.stats.as_dict()["n_steps"] == 11
    np.testing.assert_array_equal(sol.y_final, sol.ys[-1])


def test_n_steps_and_t1_give_same_run() -> None:
    prob = _rigid_body()
    W0 = initial_state(prob.algebra, 2)
    a = iso.solve(prob, iso.IsoMP(), W0, dt=0.25, t1=5.0)
    b = iso.solve(prob, iso.IsoMP(), W0, dt=0.25, n_steps=20)
    c = iso.solve(prob, iso.IsoMP(), W0, t1=5.0, n_steps=20)
    np.testing.assert_array_equal(a.ys, b.ys)
    np.testing.assert_array_equal(a.ys, c.ys)
    np.testing.assert_allclose(a.ts, 0.25 * np.arange(21))


def test_step_matches_solve() -> None:
    # iso.step keeps no method state between calls (no extrapolation history, no compensation):
    # it equals a run whose method keeps none
    prob = _rigid_body()
    W0 = initial_state(prob.algebra, 3)
    W = W0
    method = iso.IsoMP(initial_guess="state", compensated=False)
    for _ in range(3):
        W = iso.step(prob, method, W, 0.1)
    sol = iso.solve(prob, method, W0, dt=0.1, n_steps=3)
    np.testing.assert_array_equal(W, sol.ys[-1])


def test_diagnostics_track_invariants() -> None:
    prob = _rigid_body(5)
    W0 = initial_state(prob.algebra, 4)
    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, t1=20.0, save_every=10)
    d = sol.diagnostics
    assert d.casimirs.shape == (21, 5) and d.hamiltonian.shape == (21,)
    assert float(d.casimir_drift) <= 1e-13
    # energy error is O(h^2) and bounded, not zero
    assert 1e-8 < float(d.hamiltonian_relative_drift) < 1e-2
    s = d.summary()
    assert set(s) >= {"casimir_drift", "max_distance", "hamiltonian_drift"}
    assert all(isinstance(v, float) for v in s.values())
    assert (
        iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=2, diagnostics=False).diagnostics is None
    )


def test_user_invariants_and_lyapunov() -> None:
    alg = iso.algebras.sym(4)
    N = np.diag(np.arange(1.0, 5.0))

    def B(W):  # Brockett-type double bracket on real symmetric matrices
        return N @ W - W @ N

    prob = iso.IsospectralProblem(
        B=B,
        algebra=alg,
        lyapunov=lambda W: np.trace(W @ N, axis1=-2, axis2=-1),
        invariants={"trace": lambda W: np.trace(W, axis1=-2, axis2=-1)},
    )
    W0 = initial_state(alg, 5)
    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, t1=10.0)
    assert float(sol.diagnostics.lyapunov_max_decrease) == 0.0
    assert sol.diagnostics.lyapunov[-1] > sol.diagnostics.lyapunov[0]
    assert float(sol.diagnostics.invariant_drift["trace"]) <= 1e-14


def test_non_vectorized_B_runs_per_member() -> None:
    alg = iso.algebras.so(3)
    d = np.array([1.0, 2.0, 3.0])
    D = 0.5 * (d[:, None] + d[None, :])

    def B(W):
        assert W.shape == (3, 3)  # one member at a time
        return -D * W

    looped = iso.IsospectralProblem(B=B, algebra=alg, vectorized=False)
    vec = iso.IsospectralProblem(B=lambda W: -D * W, algebra=alg)
    W0s = alg.random(1, batch=(3,)) * 0.3
    a = iso.solve(looped, iso.IsoMP(), W0s, dt=0.1, n_steps=10)
    b = iso.solve(vec, iso.IsoMP(), W0s, dt=0.1, n_steps=10)
    np.testing.assert_allclose(a.ys, b.ys, atol=1e-15)


def test_progress_bar_can_be_forced_on_and_off(capsys) -> None:
    """``progress=True`` shows the bar at once on stderr (not a terminal here), ``False`` never;
    the default shows it only on a terminal."""
    prob = _rigid_body()
    W0 = initial_state(prob.algebra, 6)
    iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=5, progress=True)
    err = capsys.readouterr().err
    assert "IsoMP" in err and "/5 [" in err and "step" in err, err
    for progress in (False, None):
        iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=5, progress=progress)
        assert capsys.readouterr().err == ""


@pytest.mark.parametrize("method", [iso.IsoMP(), iso.ClassicalMidpoint(), iso.RK4()])
def test_methods_share_the_driver(method) -> None:
    prob = _rigid_body()
    W0 = initial_state(prob.algebra, 7)
    sol = iso.solve(prob, method, W0, dt=0.05, t1=1.0)
    ref = iso.reference_solution(prob, W0, [1.0])[-1]
    assert np.linalg.norm(sol.ys[-1] - ref) < 1e-3
