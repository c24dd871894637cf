"""Compensated summation in IsoMP's update ``W_{k+1} = W_k + h C`` (issue 21, item 4).

Two properties, on the NumPy path and every compiled layout:

* increments far below the rounding of the state are not lost: with ``h C`` a twentieth of an
  ulp of ``W`` per step, ``n`` steps move ``W`` by ``n h C`` to within about an ulp (without
  compensation ``W`` does not move at all, or only by rounding noise);
* Brouwer's law: over ``10^6`` steps with the stage solved to the rounding floor, the Casimir
  drift stays far below ``eps sqrt(n)`` (the uncompensated run drifts ~5x past the bound).

The compensation is part of the method state: a run cut in two continues bit for bit.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest

import isoflow as iso

EPS = float(np.finfo(float).eps)


def _cases() -> dict[str, Callable[[], tuple[iso.IsospectralProblem, np.ndarray, str]]]:
    def numpy_so4() -> tuple:
        prob, W0 = iso.models.rigid_body(4)
        return dataclasses.replace(prob, kernel=None), W0, "NumPy"

    def with_runner(make: Callable[[], tuple], runner: str) -> Callable[[], tuple]:
        return lambda: (*make(), runner)

    def ensemble() -> tuple:  # members as SIMD lanes from 8 members on (9: a padded unit)
        prob, W0 = iso.models.rigid_body(4)
        alg = prob.algebra
        return prob, np.stack([W0, *(alg.random(seed=s) * 0.1 for s in range(3, 11))])

    return {
        "numpy": numpy_so4,
        "dense small": with_runner(lambda: iso.models.rigid_body(5), "written-out"),
        "dense BLAS": with_runner(lambda: iso.models.rigid_body(20), "BLAS"),
        "su(N) small": with_runner(lambda: iso.models.euler_sphere(N=8, seed=1), "written-out"),
        "su(N) BLAS tiles": with_runner(lambda: iso.models.euler_sphere(N=40, seed=1), "BLAS"),
        "su(N) BLAS real planes": with_runner(
            lambda: iso.models.euler_sphere(N=130, seed=1), "real planes"
        ),
        "lanes": with_runner(ensemble, "lanes"),
        "spin chain": with_runner(
            lambda: iso.models.heisenberg_chain(N=30, initial="random", seed=1), "spin chain"
        ),
        "vortices": with_runner(lambda: iso.models.hyperbolic_vortices(), "point vortices"),
        "dual pairs small": with_runner(
            lambda: iso.models.mhd_sphere(N=6, seed=1), "dual pairs su(6) x| su(6)* (written"
        ),
        "dual pairs BLAS": with_runner(lambda: iso.models.mhd_sphere(N=24, seed=1), "(BLAS)"),
        "se(3) pairs": with_runner(lambda: iso.models.heavy_top(), "se(3) pairs"),
    }


CASES = _cases()


def _traceless(alg: iso.algebras.Algebra, A: np.ndarray) -> np.ndarray:
    """``A`` without its trace part on ``su(n)`` and on pairs of ``su(n)`` fields (the initial
    states carry a trace at rounding, which the first step removes); ``A`` itself elsewhere."""
    base = getattr(alg, "base", alg)
    return np.asarray(alg.project(A)) if getattr(base, "traceless", False) else A


@pytest.mark.parametrize("name", list(CASES))
def test_increments_below_the_rounding_of_the_state_add_up(name: str) -> None:
    prob, W0, runner = CASES[name]()
    alg = prob.algebra
    W0 = np.asarray(W0)
    C0 = np.asarray(prob.vector_field(W0))
    n = 2000
    h = 0.05 * EPS * float(np.abs(W0).max()) / float(np.abs(C0).max())
    ulp = EPS * float(np.abs(W0).max())
    moved = {}
    for compensated in (False, True):
        method = iso.IsoMP(compensated=compensated)
        sol = iso.solve(prob, method, W0, dt=h, n_steps=n, save_every=n, progress=False)
        assert runner in sol.stats.runner
        moved[compensated] = _traceless(alg, sol.ys[-1] - W0)
    expected = _traceless(alg, n * h * C0)
    assert float(np.abs(expected).max()) > 50 * ulp  # the increments add up to many ulps
    assert float(np.abs(moved[True] - expected).max()) <= 2 * ulp
    assert float(np.abs(moved[False] - expected).max()) >= 20 * ulp


def test_brouwer_law_over_a_million_steps() -> None:
    """so(3) rigid body, compiled, the stage solved to the rounding floor (``rtol`` below
    ``eps``: the stall rule stops it). With a looser tolerance the solve's residual, the
    same sign step after step, dominates and drifts linearly whatever the summation."""
    prob, W0 = iso.models.rigid_body(3)
    n = 10**6
    method = iso.IsoMP(solver=iso.FixedPoint(rtol=1e-17))
    sol = iso.solve(prob, method, W0, dt=0.1, n_steps=n, save_every=n // 10, progress=False)
    assert "compiled" in sol.stats.runner
    lam0 = np.linalg.eigvalsh(1j * W0)
    drift = max(
        float(np.abs(np.linalg.eigvalsh(1j * W) - lam0).max() / np.abs(lam0).max()) for W in sol.ys
    )
    # measured: 3 eps (the uncompensated run reaches ~150 eps on the same grid)
    assert drift <= 0.03 * EPS * np.sqrt(n)


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_compensation_is_part_of_the_method_state(compiled: bool) -> None:
    """A runner rebuilt from another's exported state continues it bit for bit (the
    resume tests of ``test_restart_layouts.py`` check the same through files)."""
    from isoflow._save_grid import SaveGrid
    from isoflow._solution import RunState
    from isoflow._time_loop import runner_for
    from isoflow.methods.isomp import state_parts

    prob, W0 = iso.models.euler_sphere(N=6, seed=2)
    if not compiled:
        prob = dataclasses.replace(prob, kernel=None)
    method, h = iso.IsoMP(), 0.05

    def advance(runner: object, n: int) -> None:
        out = np.empty((1, 1, *W0.shape), dtype=W0.dtype)  # (rows, members, *core)
        runner.advance(n, SaveGrid(2**62, runner.k + n), out)  # type: ignore[attr-defined]

    whole = runner_for(prob, method, RunState(0, W0, None), h)
    advance(whole, 12)
    first = runner_for(prob, method, RunState(0, W0, None), h)
    advance(first, 5)
    y, st = first.state()
    _, E = state_parts(st, h)
    assert E is not None and float(np.abs(E).max()) > 0
    rest = runner_for(prob, method, RunState(5, y, st), h)
    assert ("compiled" in rest.label) == compiled
    advance(rest, 7)
    assert rest.state()[0].tobytes() == whole.state()[0].tobytes()


def test_old_states_without_compensation_are_read() -> None:
    """A state of an earlier version, ``(h, D_1, ..., D_q)``, gives its offsets and no
    compensation; a compensated state ends with the number of offsets."""
    from isoflow.methods.isomp import pack_state, state_parts

    D1, D2, E = np.ones(3), 2 * np.ones(3), 1e-17 * np.ones(3)
    offsets, comp = state_parts((0.1, D1, D2), 0.1)
    assert len(offsets) == 2 and comp is None
    offsets, comp = state_parts(pack_state(0.1, (D1, D2), E), 0.1)
    assert [o.tolist() for o in offsets] == [D1.tolist(), D2.tolist()] and comp is E
    offsets, comp = state_parts(pack_state(0.1, (D1,), E), 0.2)  # another step: no offsets
    assert offsets == () and comp is E
