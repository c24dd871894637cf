"""Compiled fast paths equal the NumPy path: same states (1e-13), iterations, failures.

No timing assertions here; speed is measured by ``benchmarks/`` (``isoflow bench``).
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import subprocess
import sys

import numpy as np
import pytest

import isoflow as iso
from helpers import FAST_TOL as TOL
from helpers import assert_same, numpy_advance
from isoflow._fast import ElementwiseLinear, SpinNeighbourSum, dispatch
from isoflow.threads import available_cores, current_threads, thread_limits


def run_isolated(name: str) -> None:
    """Run ``_isolated_<name>()`` of this module in a fresh interpreter.

    For the tests that start numba's thread pool: once started it stays for the life of the
    process and changes what later tests in the same process measure (e.g. tracemalloc peaks).
    """
    here = os.path.dirname(os.path.abspath(__file__))
    code = f"import sys; sys.path.insert(0, {here!r}); import test_fast_paths as t; "
    code += f"t._isolated_{name}()"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def rigid(n: int = 10):
    prob, W0 = iso.models.rigid_body(n)
    assert isinstance(prob.kernel, ElementwiseLinear)
    return prob, W0


# ---- dense so(n) / u(n) / herm(n), small n ----------------------------------------------------
@pytest.mark.parametrize("guess", ["extrapolate", "state"])
def test_rigid_body_single_matches_numpy(guess: str) -> None:
    prob, W0 = rigid()
    m = iso.IsoMP(initial_guess=guess)
    assert_same(m.advance(prob, W0, 0.1, 60), numpy_advance(m, prob, W0, 0.1, 60))


def test_rigid_body_chunks_resume_bit_for_bit() -> None:
    prob, W0 = rigid()
    m = iso.IsoMP()
    whole = m.advance(prob, W0, 0.1, 20)
    a = m.advance(prob, W0, 0.1, 7)
    b = m.advance(prob, a.y, 0.1, 13, a.state)
    np.testing.assert_array_equal(b.y, whole.y)
    assert a.iterations_total + b.iterations_total == whole.iterations_total
    assert all(isinstance(v, (float, np.ndarray)) for v in whole.state)


def test_solve_uses_fast_path_same_solution() -> None:
    prob, W0 = rigid()
    fast = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=50, save_every=10)
    slow = iso.solve(dataclasses.replace(prob, kernel=None), iso.IsoMP(), W0, dt=0.1, n_steps=50,
                     save_every=10)  # fmt: skip
    assert np.max(np.abs(fast.ys - slow.ys)) <= TOL
    assert fast.stats.n_B_evaluations == slow.stats.n_B_evaluations


@pytest.mark.parametrize("members", [3, 20])  # member-by-member and blocked layouts
def test_rigid_body_ensemble_matches_numpy(members: int) -> None:
    prob, _ = rigid(6)
    W = iso.algebras.so(6).random(seed=members, batch=(members,), scale=0.3)
    m = iso.IsoMP()
    assert_same(m.advance(prob, W, 0.1, 25), numpy_advance(m, prob, W, 0.1, 25))


def test_threaded_ensembles_match_numpy() -> None:
    run_isolated("threaded_ensembles")


def _isolated_threaded_ensembles() -> None:
    prob, _ = rigid(6)
    W = iso.algebras.so(6).random(seed=40, batch=(40,), scale=0.3)  # threaded blocked driver
    m = iso.IsoMP()
    assert_same(m.advance(prob, W, 0.1, 25), numpy_advance(m, prob, W, 0.1, 25))
    _check_failing_member()
    prob_s, w0 = chain(64)
    Ws = np.stack([w0, 0.5 * w0[::-1]])
    ref = numpy_advance(m, prob_s, Ws, 0.1, 15)
    dispatch.PARALLEL_MIN_SPINS = 16  # threaded sweeps
    assert_same(m.advance(prob_s, Ws, 0.1, 15), ref, iters_exact=False)
    _check_thread_limits()


def test_ensemble_with_failing_member_stops_at_same_step(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dispatch, "PARALLEL_MIN_MEMBERS", 10**9)  # serial here, threaded above
    _check_failing_member()


def _check_failing_member() -> None:
    prob, _ = rigid(5)
    alg = iso.algebras.so(5)
    W = alg.random(seed=1, batch=(2, 20), scale=0.2)
    W[1, 7] *= 400.0  # h ||B|| far beyond the fixed-point contraction: this member diverges
    m = iso.IsoMP()
    a = m.advance(prob, W, 0.1, 10)
    b = numpy_advance(m, prob, W, 0.1, 10)
    assert b.failure is not None and b.n_done == 0
    assert_same(a, b)
    np.testing.assert_array_equal(a.y, W)  # last good state
    assert a.failure is not None
    ok = b.failure.status == 0  # the members that converged took the same step
    assert ok.sum() == 39
    assert np.max(np.abs(a.failure.y[ok] - b.failure.y[ok])) <= TOL


def test_failure_after_good_steps_keeps_last_good_state() -> None:
    prob, W0 = rigid()
    good = iso.IsoMP().advance(prob, W0, 0.1, 5)
    tight = iso.IsoMP(solver=iso.FixedPoint(max_iter=2))
    a = tight.advance(prob, good.y, 0.1, 5, good.state)
    b = numpy_advance(tight, prob, good.y, 0.1, 5, good.state)
    assert a.n_done == b.n_done == 0 and a.failure is not None
    assert_same(a, b)
    assert a.failure.failure_reason() == "max_iter"


@pytest.mark.parametrize("space", ["u", "su", "herm"])
def test_complex_spaces_match_numpy(space: str) -> None:
    n = 6
    rng = np.random.default_rng(3)
    if space in ("u", "su"):
        alg = getattr(iso.algebras, space)(n)
        d = rng.random(n) + 0.5
        C = -(d[:, None] + d[None, :]) / 2
    else:
        alg = iso.algebras.herm(n)
        nu = np.arange(1.0, n + 1)
        C = nu[:, None] - nu[None, :]
    prob = iso.IsospectralProblem(B=lambda W: C * W, algebra=alg, kernel=ElementwiseLinear(C))
    W = alg.random(seed=4, batch=(9,), scale=0.1)  # blocked ensemble layout
    m = iso.IsoMP()
    for y in (W, W[0]):
        assert dispatch.isomp_advance(m, prob, y, 0.1, 1, None) is not None  # compiled
        a = m.advance(prob, y, 0.1, 20)
        assert_same(a, numpy_advance(m, prob, y, 0.1, 20))
        if space == "su":  # the trace is removed as by the projection of su(n)
            assert np.max(np.abs(np.trace(a.y, axis1=-2, axis2=-1))) <= 1e-15


def test_su_large_dense_matches_numpy_and_stays_traceless() -> None:
    n = dispatch.LARGE_N
    alg = iso.algebras.su(n)
    d = np.linspace(0.5, 1.5, n)
    C = -(d[:, None] + d[None, :]) / 2
    prob = iso.IsospectralProblem(B=lambda W: C * W, algebra=alg, kernel=ElementwiseLinear(C))
    W0 = alg.random(seed=8, scale=1.0 / n)
    m = iso.IsoMP()
    assert dispatch.isomp_advance(m, prob, W0, 0.1, 1, None) is not None  # compiled
    a = m.advance(prob, W0, 0.1, 5)
    assert_same(a, numpy_advance(m, prob, W0, 0.1, 5))
    assert abs(np.trace(a.y)) <= 1e-15


def test_brockett_model_carries_kernel() -> None:
    prob, W0 = iso.models.brockett(n=6)
    assert isinstance(prob.kernel, ElementwiseLinear) and prob.kernel.frame is None
    m = iso.IsoMP()
    assert_same(m.advance(prob, W0, 0.1, 30), numpy_advance(m, prob, W0, 0.1, 30))


def random_hermitian(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))
    return (A + A.conj().T) / 2


@pytest.mark.parametrize(("n", "batch"), [(6, ()), (6, (20,)), (dispatch.LARGE_N, ())])
def test_brockett_nondiagonal_N_runs_compiled_in_its_eigenframe(n: int, batch: tuple) -> None:
    """``[N, .]`` is entrywise in the eigenframe of ``N``: the compiled path runs there and
    maps back; same steps (to rounding) as the NumPy path with ``B(W) = NW - WN``."""
    N = random_hermitian(n, seed=1) / np.sqrt(n)
    prob, _ = iso.models.brockett(n=n, N=N)
    assert prob.kernel.frame is not None
    W0 = iso.algebras.herm(n).random(seed=2, batch=batch, scale=0.5 / np.sqrt(n))
    m = iso.IsoMP()
    h = 0.05
    assert dispatch.isomp_advance(m, prob, W0, h, 1, None) is not None  # compiled
    a, b = m.advance(prob, W0, h, 12), numpy_advance(m, prob, W0, h, 12)
    assert_same(a, b, iters_exact=False)
    np.testing.assert_array_equal(a.y, np.swapaxes(a.y, -1, -2).conj())  # Hermitian exactly
    for Da, Db in zip(a.state[1:], b.state[1:], strict=True):  # offsets in the user's frame
        assert np.max(np.abs(Da - Db)) <= 1e-12
    # resuming from the returned state continues the same trajectory
    a2 = m.advance(prob, a.y, h, 5, a.state)
    b2 = numpy_advance(m, prob, b.y, h, 5, b.state)
    assert_same(a2, b2, iters_exact=False)


def test_brockett_nondiagonal_N_failure_maps_back() -> None:
    N = random_hermitian(6, seed=3)
    prob, W0 = iso.models.brockett(n=6, N=N)
    m = iso.IsoMP(solver=iso.FixedPoint(max_iter=2))
    a, b = m.advance(prob, W0, 0.2, 5), numpy_advance(m, prob, W0, 0.2, 5)
    assert a.failure is not None and b.failure is not None
    assert_same(a, b)
    assert np.max(np.abs(a.failure.stage - b.failure.stage)) <= 1e-12


def test_elementwise_frame_validation() -> None:
    C = np.zeros((3, 3))
    with pytest.raises(ValueError, match="unitary"):
        ElementwiseLinear(C, frame=2.0 * np.eye(3))
    with pytest.raises(ValueError, match="shape"):
        ElementwiseLinear(C, frame=np.eye(4))
    with pytest.raises(ValueError, match="non-finite"):
        ElementwiseLinear(C, frame=np.full((3, 3), np.nan))


def test_other_solvers_take_the_numpy_path() -> None:
    prob, W0 = rigid(4)
    assert dispatch.isomp_advance(iso.IsoMP(solver=iso.Newton()), prob, W0, 0.1, 3, None) is None


def test_kernel_must_be_a_fast_kernel() -> None:
    with pytest.raises(TypeError, match="kernel"):
        iso.IsospectralProblem(B=lambda W: W, algebra=iso.algebras.so(3), kernel="rigid")


# ---- large dense: buffered BLAS path ---------------------------------------------------------
@pytest.mark.parametrize("space", ["so", "u", "sym", "herm"])
@pytest.mark.parametrize("with_kernel", [True, False])
def test_large_dense_buffered_path_matches_numpy(space: str, with_kernel: bool) -> None:
    n = dispatch.LARGE_N
    alg = getattr(iso.algebras, space)(n)
    d = np.linspace(0.5, 1.5, n)
    # B in the normalizer: C symmetric on the skew spaces, antisymmetric on Sym/Herm
    C = -(d[:, None] + d[None, :]) / 2 if space in ("so", "u") else d[:, None] - d[None, :]
    prob = iso.IsospectralProblem(
        B=lambda W: C * W, algebra=alg, kernel=ElementwiseLinear(C) if with_kernel else None
    )
    W0 = alg.random(seed=5, scale=1.0 / n)
    m = iso.IsoMP()
    a = m.advance(prob, W0, 0.1, 6)
    assert_same(a, numpy_advance(m, prob, W0, 0.1, 6))


@pytest.mark.parametrize(("space", "n"), [("so", 200), ("u", 256), ("herm", 300)])
def test_large_dense_triangular_product_matches_numpy(space: str, n: int) -> None:
    """Several row blocks of the half product ``B X B``, ragged last block and tile; the
    state stays in ``V`` bit for bit."""
    from isoflow._fast.blas import lower_blocks

    assert len(lower_blocks(n)) >= 2
    alg = getattr(iso.algebras, space)(n)
    d = np.linspace(0.5, 1.5, n)
    C = -(d[:, None] + d[None, :]) / 2 if space in ("so", "u") else d[:, None] - d[None, :]
    prob = iso.IsospectralProblem(B=lambda W: C * W, algebra=alg, kernel=ElementwiseLinear(C))
    W0 = alg.random(seed=7, scale=1.0 / n)
    m = iso.IsoMP()
    a, b = m.advance(prob, W0, 0.1, 3), numpy_advance(m, prob, W0, 0.1, 3)
    assert_same(a, b)
    sign = -1.0 if space in ("so", "u") else 1.0
    for A in (a.y, *a.state[1:]):  # state and stored offsets complete and in V
        np.testing.assert_array_equal(A, sign * A.conj().T)
    for Da, Db in zip(a.state[1:], b.state[1:], strict=True):
        assert np.max(np.abs(Da - Db)) <= 1e-13
    assert_same(m.advance(prob, a.y, 0.1, 2, a.state), numpy_advance(m, prob, b.y, 0.1, 2, b.state))


@pytest.mark.parametrize("n", [1, 31, 32, 33, 64, 130, 1000])
def test_lower_blocks_tile_the_rows(n: int) -> None:
    from isoflow._fast.blas import _TILE, lower_blocks

    blocks = lower_blocks(n)
    assert blocks[0][0] == 0 and blocks[-1][1] == n
    assert all(a[1] == b[0] for a, b in itertools.pairwise(blocks))
    assert all(r0 % _TILE == 0 for r0, _ in blocks)
    assert 1 <= len(blocks) <= 8


def test_large_dense_failure_matches_numpy() -> None:
    n = dispatch.LARGE_N
    alg = iso.algebras.so(n)
    prob = iso.IsospectralProblem(B=lambda W: -W, algebra=alg)
    W0 = alg.random(seed=6, scale=3.0)
    m = iso.IsoMP()
    a, b = m.advance(prob, W0, 0.1, 3), numpy_advance(m, prob, W0, 0.1, 3)
    assert b.failure is not None
    assert_same(a, b)


# ---- spin chains ------------------------------------------------------------------------------
def chain(N: int, seed: int = 0):
    prob, w0 = iso.models.heisenberg_chain(N, initial="random", seed=seed)
    assert isinstance(prob.kernel, SpinNeighbourSum) and prob.kernel.coupling == -1.0
    return prob, w0


@pytest.mark.parametrize("guess", ["extrapolate", "state"])
def test_spin_chain_isomp_matches_numpy(guess: str) -> None:
    prob, w0 = chain(50)
    m = iso.IsoMP(initial_guess=guess)
    assert_same(m.advance(prob, w0, 0.1, 40), numpy_advance(m, prob, w0, 0.1, 40),
                iters_exact=False)  # fmt: skip


def test_spin_chain_ensemble() -> None:
    prob, w0 = chain(64)
    W = np.stack([w0, 0.5 * w0[::-1]])
    m = iso.IsoMP()
    ref = numpy_advance(m, prob, W, 0.1, 15)
    assert_same(m.advance(prob, W, 0.1, 15), ref, iters_exact=False)


@pytest.mark.parametrize("method", [iso.IsoMP(), iso.SphericalMidpoint()])
def test_spin_chain_chunks_resume_bit_for_bit(method) -> None:
    """The stored offsets come back as views of the compiled layout; feeding them to the next
    call (compiled or NumPy) continues the same trajectory."""
    prob, w0 = chain(40)
    whole = method.advance(prob, w0, 0.1, 10)
    a = method.advance(prob, w0, 0.1, 4)
    b = method.advance(prob, a.y, 0.1, 6, a.state)
    np.testing.assert_array_equal(b.y, whole.y)
    assert b.iterations_total + a.iterations_total == whole.iterations_total
    c = numpy_advance(method, prob, a.y, 0.1, 6, a.state)
    assert np.max(np.abs(c.y - whole.y)) <= 1e-13


@pytest.mark.parametrize("method", [iso.IsoMP(), iso.SphericalMidpoint()])
def test_single_spin_input_is_not_overwritten(method) -> None:
    """With one spin the ``(3, N)`` layout is a view of the input: the fast path must copy."""
    prob = iso.IsospectralProblem(
        B=SpinNeighbourSum(-1.0).evaluate, algebra=iso.algebras.so3_vectors(1),
        kernel=SpinNeighbourSum(-1.0),
    )  # fmt: skip
    w0 = np.array([[[0.3, -0.2, 0.9]], [[0.1, 0.5, -0.4]]])
    keep = w0.copy()
    a = method.advance(prob, w0, 0.1, 4)
    np.testing.assert_array_equal(w0, keep)
    assert not np.shares_memory(a.y, w0)


@pytest.mark.parametrize("guess", ["extrapolate", "state"])
def test_spin_chain_spherical_midpoint_matches_numpy(guess: str) -> None:
    prob, w0 = chain(50)
    s = iso.SphericalMidpoint(initial_guess=guess)
    assert dispatch.smm_advance(s, prob, w0, 0.1, 1, None) is not None  # compiled path taken
    assert_same(s.advance(prob, w0, 0.1, 40), numpy_advance(s, prob, w0, 0.1, 40),
                iters_exact=False)  # fmt: skip


def test_spin_chain_failure_matches_numpy() -> None:
    prob, w0 = chain(30)
    W = np.stack([w0, 40.0 * w0])  # second member: h |B| too large, diverges
    m = iso.IsoMP()
    a, b = m.advance(prob, W, 0.1, 5), numpy_advance(m, prob, W, 0.1, 5)
    assert b.failure is not None
    assert_same(a, b, iters_exact=False)
    np.testing.assert_array_equal(a.y, W)


# ---- initial guess ------------------------------------------------------------------------------
@pytest.mark.parametrize("rtol", [1e-14, 1e-16])
def test_extrapolated_guess_same_answer_quarter_fewer_iterations(rtol: float) -> None:
    prob, W0 = rigid()
    fp = iso.FixedPoint(rtol=rtol)
    paper = iso.IsoMP(solver=fp, initial_guess="state")
    ours = iso.IsoMP(solver=fp)
    a = numpy_advance(paper, prob, W0, 0.1, 100)
    b = numpy_advance(ours, prob, W0, 0.1, 100)
    assert np.max(np.abs(a.y - b.y)) <= TOL
    assert b.iterations_total <= 0.75 * a.iterations_total
    assert_same(ours.advance(prob, W0, 0.1, 100), b)


def test_extrapolation_order_validated_and_state_shape() -> None:
    with pytest.raises(ValueError, match="extrapolation_order"):
        iso.IsoMP(extrapolation_order=9)
    prob, W0 = rigid(4)
    st = iso.IsoMP(extrapolation_order=1).advance(prob, W0, 0.1, 5).state
    assert len(st) == 3 and st[0] == 0.1
    # a state written by another step size is ignored (restart from W_k)
    m = iso.IsoMP()
    assert m.history(0.05, st) == ()


# ---- thread policy ------------------------------------------------------------------------------
def test_thread_limits_validation() -> None:
    with pytest.raises(ValueError):
        with thread_limits(blas=available_cores() + 1, numba=1):
            pass


def _check_thread_limits() -> None:  # run by test_threaded_ensembles_match_numpy
    cores = available_cores()
    with thread_limits(blas=1) as lim:
        assert lim["blas"] * lim["numba"] <= cores
        assert current_threads()["numba"] == lim["numba"]
    with pytest.raises(ValueError):
        with thread_limits(blas=cores, numba=2):
            pass


def test_kernel_inconsistent_with_B_is_rejected() -> None:
    """A kernel that does not describe the problem's B would silently change the flow."""
    prob, W0 = iso.models.rigid_body(n=4)
    wrong = dataclasses.replace(prob, kernel=iso.ElementwiseLinear(2.0 * prob.kernel.coeff))
    with pytest.raises(iso.InvalidBError, match="does not describe its B"):
        iso.solve(wrong, iso.IsoMP(), W0, dt=0.1, n_steps=3)


def test_toda_fast_path_equals_numpy_path() -> None:
    """Toda's B = sign o L is an ElementwiseLinear kernel on sym(n): same run both ways."""
    prob, L0 = iso.models.toda(n=12)
    assert isinstance(prob.kernel, ElementwiseLinear)
    plain = dataclasses.replace(prob, kernel=None)
    fast = iso.solve(prob, iso.IsoMP(), L0, dt=0.1, n_steps=300, save_every=30)
    ref = iso.solve(plain, iso.IsoMP(), L0, dt=0.1, n_steps=300, save_every=30)
    assert float(np.max(np.abs(fast.ys - ref.ys))) <= 1e-13
    assert fast.stats.iterations_mean == ref.stats.iterations_mean
