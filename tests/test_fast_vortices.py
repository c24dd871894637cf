"""Compiled point-vortex loops (``PairwiseVortex``) equal the NumPy path.

Same states (1e-13), iteration counts, failures and method states as the generic loop over
``step`` on the problem without its kernel; sphere (IsoMP and spherical midpoint) and
hyperboloid (IsoMP). No timing assertions: speed is benchmark 7 (``isoflow bench --only 7``).
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest

import isoflow as iso
from helpers import FAST_TOL as TOL
from helpers import assert_same, numpy_advance
from isoflow._fast import dispatch, vortices
from isoflow._fast.kernels import PairwiseVortex
from isoflow.methods._base import Method
from isoflow.nonlinear import STATUS_CONVERGED, STATUS_MAX_ITER, STATUS_NON_FINITE


# ---- helpers ------------------------------------------------------------------------------------
def sphere(N: int, seed: int = 0, batch: tuple[int, ...] = ()):
    """``N`` random vortices on the sphere (mixed signs), kept apart."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((*batch, N, 3))
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    circ = rng.uniform(0.5, 1.5, N) * rng.choice([-1.0, 1.0], N)
    prob, x0 = iso.models.sphere_vortices(positions=x, circulations=circ)
    assert isinstance(prob.kernel, PairwiseVortex) and prob.kernel.geometry == "sphere"
    return prob, x0


def hyperboloid(N: int, seed: int = 0, batch: tuple[int, ...] = ()):
    """``N`` vortices on the upper sheet ``z = sqrt(1 + x^2 + y^2)``, about a ring (random)."""
    rng = np.random.default_rng(seed)
    theta = 2.0 * np.pi * np.arange(N) / N + rng.uniform(-0.3, 0.3, (*batch, N))
    r = rng.uniform(0.8, 1.2, (*batch, N))
    xy = np.stack([r * np.cos(theta), r * np.sin(theta)], axis=-1)
    z = np.sqrt(1.0 + np.sum(xy * xy, axis=-1, keepdims=True))
    circ = rng.uniform(0.2, 1.0, N)
    prob, w0 = iso.models.hyperbolic_vortices(
        positions=np.concatenate([xy, z], axis=-1), circulations=circ
    )
    assert isinstance(prob.kernel, PairwiseVortex) and prob.kernel.geometry == "hyperbolic"
    return prob, w0


# ---- the kernel ---------------------------------------------------------------------------------
def test_kernels_of_the_models_are_their_B() -> None:
    for prob, y in (sphere(5, batch=(2,)), hyperboloid(4, batch=(3,))):
        assert np.max(np.abs(prob.kernel.evaluate(y) - prob.B(y))) <= 1e-14 * np.max(
            np.abs(prob.B(y))
        )
        prob.check_B(y)  # kernel == B at the state
    prob, _ = iso.models.hyperbolic_vortices(config=1)
    assert prob.kernel.coefficient == -1.0 / np.pi
    np.testing.assert_array_equal(prob.kernel.circulations, prob.parameters["circulations"])
    assert not prob.kernel.circulations.flags.writeable


def test_kernel_validation() -> None:
    with pytest.raises(ValueError, match="geometry"):
        PairwiseVortex([1.0, 2.0], "torus")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="shape"):
        PairwiseVortex(np.ones((2, 2)), "sphere")
    with pytest.raises(ValueError, match="shape"):
        PairwiseVortex([], "sphere")
    with pytest.raises(ValueError, match="finite"):
        PairwiseVortex([1.0, np.nan], "sphere")
    with pytest.raises(ValueError, match="real"):
        PairwiseVortex([1.0 + 1j, 2.0], "hyperbolic")
    k = PairwiseVortex([1, 2, 3], "sphere")
    assert k.circulations.dtype == np.float64 and k.N == 3
    assert k.coefficient == 1.0 / (4.0 * np.pi)
    with pytest.raises(ValueError, match="shape"):
        k.evaluate(np.ones((4, 3)))


def test_kernel_mismatch_rejected() -> None:
    prob, x0 = sphere(4)
    G = prob.kernel.circulations
    bad = dataclasses.replace(prob, kernel=PairwiseVortex(2.0 * G, "sphere"))
    with pytest.raises(iso.InvalidBError, match="does not describe its B"):
        iso.solve(bad, iso.IsoMP(), x0, dt=0.01, n_steps=2)
    for wrong in (PairwiseVortex(G, "hyperbolic"), PairwiseVortex(G[:3], "sphere")):
        with pytest.raises(iso.InvalidBError, match=r"describes B on|circulations for"):
            dataclasses.replace(prob, kernel=wrong)


def test_kernel_on_the_wrong_space_takes_the_numpy_path() -> None:
    prob, x0 = sphere(4)
    m = iso.IsoMP()
    assert dispatch.isomp_advance(m, prob, x0.astype(np.float32), 0.01, 2, None) is None
    hprob, w0 = iso.models.hyperbolic_vortices(config=1)
    assert dispatch.smm_advance(iso.SphericalMidpoint(), hprob, w0, 0.01, 2, None) is None


def test_other_solvers_take_the_numpy_path() -> None:
    prob, x0 = sphere(3)
    hprob, w0 = iso.models.hyperbolic_vortices(config=1)
    newton = iso.Newton()
    assert dispatch.isomp_advance(iso.IsoMP(solver=newton), prob, x0, 0.01, 3, None) is None
    assert dispatch.isomp_advance(iso.IsoMP(solver=newton), hprob, w0, 0.01, 3, None) is None
    s = iso.SphericalMidpoint(solver=newton)
    assert dispatch.smm_advance(s, prob, x0, 0.01, 3, None) is None
    m = iso.IsoMP(solver=newton)  # and the method still works (the NumPy loop)
    a, b = m.advance(hprob, w0, 0.01, 3), numpy_advance(m, hprob, w0, 0.01, 3)
    np.testing.assert_array_equal(a.y, b.y)


# ---- single systems ---------------------------------------------------------------------------
@pytest.mark.parametrize("guess", ["extrapolate", "state"])
@pytest.mark.parametrize(("config", "h", "n"), [(1, 0.01, 100), (2, 0.001, 40)])
def test_hyperbolic_paper_configs_match_numpy(config: int, h: float, n: int, guess: str) -> None:
    # config 2 is a strongly unstable relative equilibrium: rounding differences grow by
    # about 10x every 20 steps, so it is compared over 40 steps only
    prob, w0 = iso.models.hyperbolic_vortices(config=config)
    m = iso.IsoMP(initial_guess=guess)
    a = dispatch.isomp_advance(m, prob, w0, h, n, None)
    assert a is not None  # compiled path taken
    assert_same(a, numpy_advance(m, prob, w0, h, n))
    assert_same(m.advance(prob, w0, h, n), a)


@pytest.mark.parametrize("N", [3, 7, 20])
@pytest.mark.parametrize(
    "method",
    [iso.IsoMP(), iso.IsoMP(initial_guess="state"), iso.IsoMP(extrapolation_order=1),
     iso.SphericalMidpoint(), iso.SphericalMidpoint(initial_guess="state")],
    ids=["isomp", "isomp-state", "isomp-p1", "smm", "smm-state"],
)  # fmt: skip
def test_sphere_random_vortices_match_numpy(N: int, method: Method) -> None:
    prob, x0 = sphere(N, seed=N)
    x_in = x0.copy()
    fast = dispatch.isomp_advance if isinstance(method, iso.IsoMP) else dispatch.smm_advance
    a = fast(method, prob, x0, 0.005, 40, None)
    assert a is not None
    assert_same(a, numpy_advance(method, prob, x0, 0.005, 40))
    np.testing.assert_array_equal(x0, x_in)  # the input is not written


def test_single_vortex_input_not_written() -> None:
    # N = 1: the (3, N) copy of the state is a view of the input unless copied explicitly
    prob, x0 = iso.models.sphere_vortices(positions=[[0.0, 0.6, 0.8]], circulations=[1.0])
    x_in = x0.copy()
    a = iso.IsoMP().advance(prob, x0, 0.1, 3)
    np.testing.assert_array_equal(x0, x_in)
    np.testing.assert_array_equal(a.y, x_in)  # B = 0: a single vortex does not move


# ---- ensembles ----------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["sphere-isomp", "sphere-smm", "hyperbolic"])
def test_ensembles_match_numpy(kind: str) -> None:
    if kind == "hyperbolic":
        prob, y = hyperboloid(5, seed=1, batch=(2, 3))
        m: Method = iso.IsoMP()
    else:
        prob, y = sphere(6, seed=2, batch=(2, 3))
        m = iso.IsoMP() if kind == "sphere-isomp" else iso.SphericalMidpoint()
    a = m.advance(prob, y, 0.01, 25)
    b = numpy_advance(m, prob, y, 0.01, 25)
    assert b.failure is None and b.state is not None and b.state[1].shape == y.shape
    assert_same(a, b)
    one = m.advance(prob, y[1, 2], 0.01, 25)  # a member alone: the same run
    assert np.max(np.abs(one.y - a.y[1, 2])) <= TOL


def _close_pair(prob, y: np.ndarray, member: tuple[int, ...]) -> np.ndarray:
    """``y`` with vortex 1 of ``member`` moved next to vortex 0 (huge ``|B|``)."""
    y = y.copy()
    near = y[(*member, 0)] + np.array([1e-3, -1e-3, 0.0])
    y[(*member, 1)] = near / np.linalg.norm(near)
    return y


@pytest.mark.parametrize("method", [iso.IsoMP(), iso.SphericalMidpoint()], ids=["isomp", "smm"])
def test_failing_member_stops_the_ensemble(method: Method) -> None:
    prob, y = sphere(5, seed=3, batch=(2, 4))
    y = _close_pair(prob, y, (1, 2))  # h |B| far beyond the contraction: diverges
    a = method.advance(prob, y, 0.01, 10)
    b = numpy_advance(method, prob, y, 0.01, 10)
    assert b.failure is not None and b.n_done == 0
    assert_same(a, b)
    np.testing.assert_array_equal(a.y, y)  # last good state: the input
    assert a.failure is not None and int(a.failure.status[1, 2]) != STATUS_CONVERGED
    assert int(np.sum(a.failure.status == STATUS_CONVERGED)) == 7


@pytest.mark.parametrize("kind", ["sphere-isomp", "sphere-smm", "hyperbolic"])
def test_failure_after_good_steps_keeps_last_good_state(kind: str) -> None:
    if kind == "hyperbolic":
        prob, y0 = iso.models.hyperbolic_vortices(config=1)
        good_m: Method = iso.IsoMP()
        tight: Method = iso.IsoMP(solver=iso.FixedPoint(max_iter=1))
    elif kind == "sphere-isomp":
        prob, y0 = sphere(7, seed=4)
        good_m, tight = iso.IsoMP(), iso.IsoMP(solver=iso.FixedPoint(max_iter=1))
    else:
        prob, y0 = sphere(7, seed=4)
        good_m = iso.SphericalMidpoint()
        tight = iso.SphericalMidpoint(solver=iso.FixedPoint(max_iter=1))
    good = good_m.advance(prob, y0, 0.01, 5)
    a = tight.advance(prob, good.y, 0.01, 5, good.state)
    b = numpy_advance(tight, prob, good.y, 0.01, 5, good.state)
    assert a.n_done == b.n_done == 0 and a.failure is not None
    assert_same(a, b)
    np.testing.assert_array_equal(a.y, good.y)
    assert a.state is good.state  # the state of the last good step, untouched
    assert int(a.failure.status) == STATUS_MAX_ITER and int(a.failure.iterations) == 1
    assert a.failure.failure_reason() == "max_iter"


def test_huge_step_fails_like_numpy() -> None:
    prob, w0 = iso.models.hyperbolic_vortices(config=1)
    m = iso.IsoMP()
    a, b = m.advance(prob, w0, 50.0, 3), numpy_advance(m, prob, w0, 50.0, 3)
    assert b.failure is not None and b.n_done == 0
    assert_same(a, b)
    np.testing.assert_array_equal(a.y, w0)


def test_non_finite_state_detected() -> None:
    prob, x0 = sphere(4)
    x = x0.copy()
    x[2, 1] = np.nan
    m = iso.IsoMP()
    a, b = m.advance(prob, x, 0.01, 3), numpy_advance(m, prob, x, 0.01, 3)
    assert a.n_done == b.n_done == 0 and a.failure is not None and b.failure is not None
    assert int(a.failure.status) == int(b.failure.status) == STATUS_NON_FINITE
    assert a.iterations_total == b.iterations_total == 1
    np.testing.assert_array_equal(a.y, x)
    x = x0.copy()
    x[3] = x[1]  # two coinciding vortices: 1 / (1 - x_1 . x_3) = inf, no ZeroDivisionError
    a = m.advance(prob, x, 0.01, 3)
    with np.errstate(all="ignore"):
        b = numpy_advance(m, prob, x, 0.01, 3)
    assert a.failure is not None and b.failure is not None and a.n_done == b.n_done == 0
    assert int(a.failure.status) == int(b.failure.status) == STATUS_NON_FINITE
    # the finite flag of the final update: converged stage, non-finite new state
    buf = np.ones((vortices._RING + 2, 1, 3, 4))  # slots: state 0 -> 1, C, ring slot 0
    assert vortices._final(buf, 0, 1, 0, 0, 0.1)
    buf[vortices._C, 0, 1, 2] = np.inf
    assert not vortices._final(buf, 0, 1, 0, 0, 0.1)


# ---- resuming, solve ----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["sphere-isomp", "sphere-smm", "hyperbolic", "ensemble"])
def test_chunks_resume_bit_for_bit(kind: str) -> None:
    if kind == "hyperbolic":
        prob, y0 = iso.models.hyperbolic_vortices(config=1)
        m: Method = iso.IsoMP()
    elif kind == "ensemble":
        prob, y0 = hyperboloid(4, seed=5, batch=(3,))
        m = iso.IsoMP()
    else:
        prob, y0 = sphere(7, seed=6)
        m = iso.IsoMP() if kind == "sphere-isomp" else iso.SphericalMidpoint()
    whole = m.advance(prob, y0, 0.01, 20)
    a = m.advance(prob, y0, 0.01, 7)
    b = m.advance(prob, a.y, 0.01, 13, a.state)
    np.testing.assert_array_equal(b.y, whole.y)
    assert a.iterations_total + b.iterations_total == whole.iterations_total
    assert len(b.state) == len(whole.state)
    for x, y in zip(b.state[1:], whole.state[1:], strict=True):
        np.testing.assert_array_equal(x, y)


def test_solve_uses_the_fast_path_same_solution() -> None:
    prob, w0 = iso.models.hyperbolic_vortices(config=1)
    plain = dataclasses.replace(prob, kernel=None)
    fast = iso.solve(prob, iso.IsoMP(), w0, dt=0.01, n_steps=60, save_every=20)
    ref = iso.solve(plain, iso.IsoMP(), w0, dt=0.01, n_steps=60, save_every=20)
    assert np.max(np.abs(fast.ys - ref.ys)) <= TOL * np.max(np.abs(ref.ys))
    assert fast.stats.n_B_evaluations == ref.stats.n_B_evaluations


# ---- threads ------------------------------------------------------------------------------------
def test_threaded_ensembles_match_numpy() -> None:
    """Members over numba threads (in a fresh interpreter: the pool outlives its first use)."""
    here = os.path.dirname(os.path.abspath(__file__))
    code = f"import sys; sys.path.insert(0, {here!r}); import test_fast_vortices as t; "
    code += "t._isolated_threaded()"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def _isolated_threaded() -> None:
    def serial(*args):  # type: ignore[no-untyped-def]
        raise AssertionError("the serial driver was called")

    dispatch.PARALLEL_MIN_VORTEX_MEMBERS = 2
    dispatch.PARALLEL_MIN_VORTEX_WORK = 0
    dispatch._threads = lambda: 2  # the threaded driver even on a one-core machine
    vortices._drive_ser = serial
    prob, y = sphere(5, seed=7, batch=(6,))
    for m in (iso.IsoMP(), iso.SphericalMidpoint()):
        assert_same(m.advance(prob, y, 0.01, 15), numpy_advance(m, prob, y, 0.01, 15))
    bad = _close_pair(prob, y, (4,))
    m = iso.IsoMP()
    assert_same(m.advance(prob, bad, 0.01, 5), numpy_advance(m, prob, bad, 0.01, 5))
    hprob, w = hyperboloid(4, seed=8, batch=(5,))
    assert_same(m.advance(hprob, w, 0.01, 15), numpy_advance(m, hprob, w, 0.01, 15))
