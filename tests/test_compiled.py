"""The compiled loops equal the NumPy path: same states (1e-13), iterations, failures.

Every layout of :mod:`isoflow._compiled` (dense with written-out products, dense with BLAS,
blocked ensembles, particles, fused spin chains) and every kernel (the built-in ones and a
user's ``CompiledB``) is run by the compiled runner and by the method's own NumPy steps, and
the two runs are compared. No timing assertions here (speed: ``benchmarks/``).
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import subprocess
import sys
from collections.abc import Callable

import numpy as np
import pytest

import isoflow as iso
import user_kernels as uk
from helpers import assert_same_run, compiled_and_numpy, run_with
from isoflow._compiled import compiled_runner

Case = Callable[[], tuple]


def _rigid(n: int = 10, members: int = 0, scale: float = 1.0):
    prob, W0 = iso.models.rigid_body(n)
    if members:
        W0 = np.stack([W0 * scale * (1.0 + 0.05 * i) for i in range(members)])
    return prob, W0


def _elementwise(alg: iso.algebras.Algebra, seed: int = 0):
    """``B = C * W`` on any of the five dense spaces (C symmetric on the skew spaces,
    antisymmetric on the symmetric ones)."""
    rng = np.random.default_rng(seed)
    n = alg.shape[0]
    A = rng.uniform(-1.0, 1.0, (n, n))
    sym_space = isinstance(alg, (iso.algebras.Symmetric, iso.algebras.Hermitian))
    C = 0.5 * (A - A.T) if sym_space else 0.5 * (A + A.T)
    kernel = iso.ElementwiseLinear(C)
    prob = iso.IsospectralProblem(B=kernel.evaluate, algebra=alg, kernel=kernel)
    W0 = alg.random(seed + 1)
    return prob, W0 / float(alg.norm(W0))


def _brockett(n: int, members: int = 0):
    rng = np.random.default_rng(3)
    A = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))
    N = 0.5 * (A + A.conj().T) / n
    prob, W0 = iso.models.brockett(n=n, N=N, seed=1)
    if members:
        W0 = np.stack([W0 * (1.0 + 0.1 * i) for i in range(members)])
    return prob, W0


def _user_dense(alg: iso.algebras.Algebra, members: int = 0, seed: int = 0):
    prob = uk.cubic_problem(alg, seed=seed, scale=0.5)
    W0 = alg.random(seed + 7)
    W0 = W0 / float(alg.norm(W0))
    if members:
        W0 = np.stack([W0 * (1.0 + 0.1 * i) for i in range(members)])
    return prob, W0


def _user_particles(kind: str, N: int = 6, members: int = 0):
    rng = np.random.default_rng(11)
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    alg = iso.algebras.so3_vectors(N) if kind == "so3" else iso.algebras.sl2_vectors(N)
    prob = iso.IsospectralProblem(
        B=uk.precession_numpy(axis, 0.7),
        algebra=alg,
        kernel=iso.CompiledB(uk.precession, (axis, 0.7)),
    )
    w0 = rng.standard_normal((*((members,) if members else ()), N, 3))
    return prob, w0


def _chain(N: int = 30, members: int = 0):
    prob, w0 = iso.models.heisenberg_chain(N=N, initial="random", seed=2)
    if members:
        w0 = np.stack([np.roll(w0, i, axis=0) for i in range(members)])
    return prob, w0


def _user_chain(N: int = 30):
    prob, w0 = iso.models.heisenberg_chain(N=N, initial="random", seed=2)
    return dataclasses.replace(prob, kernel=iso.CompiledB(uk.neighbours, (-1.0,))), w0


def _sphere_vortices(N: int = 5, members: int = 0):
    rng = np.random.default_rng(N)
    pos = rng.standard_normal((N, 3))
    pos /= np.linalg.norm(pos, axis=1, keepdims=True)
    prob, x0 = iso.models.sphere_vortices(positions=pos, circulations=rng.uniform(0.5, 1.5, N))
    if members:
        x0 = np.stack([x0] * members)
    return prob, x0


IsoMP, SMM = iso.IsoMP, iso.SphericalMidpoint
A3 = iso.FixedPoint(anderson=3)

# name -> (problem factory, method, h, steps, save_every)
CASES: dict[str, tuple[Callable[[], tuple], iso.Method, float, int, int]] = {
    "rigid so(10)": (_rigid, IsoMP(), 0.1, 40, 1),
    "rigid so(10), X0 = W": (_rigid, IsoMP(initial_guess="state"), 0.1, 40, 3),
    "rigid so(10), order-1 guess": (_rigid, IsoMP(extrapolation_order=1), 0.1, 30, 1),
    "rigid so(10), Anderson": (_rigid, IsoMP(solver=A3), 0.3, 40, 4),
    "rigid ensemble 5 (members)": (lambda: _rigid(members=5), IsoMP(), 0.1, 25, 5),
    "rigid ensemble 20 (blocks)": (lambda: _rigid(members=20), IsoMP(), 0.1, 25, 5),
    "rigid ensemble 20, Anderson": (lambda: _rigid(members=20), IsoMP(solver=A3), 0.1, 25, 5),
    "u(6)": (lambda: _elementwise(iso.algebras.u(6)), IsoMP(), 0.2, 30, 2),
    "su(6)": (lambda: _elementwise(iso.algebras.su(6)), IsoMP(), 0.2, 30, 2),
    "herm(5)": (lambda: _elementwise(iso.algebras.herm(5)), IsoMP(), 0.2, 30, 2),
    "sym(5)": (lambda: _elementwise(iso.algebras.sym(5)), IsoMP(), 0.2, 30, 2),
    "su(5) ensemble 12 (blocks)": (
        lambda: (lambda p, w: (p, np.stack([w * (1 + 0.1 * i) for i in range(12)])))(
            *_elementwise(iso.algebras.su(5))
        ),
        IsoMP(),
        0.2,
        20,
        4,
    ),
    "brockett herm(6) in a frame": (lambda: _brockett(6), IsoMP(), 0.1, 30, 3),
    "brockett herm(6) in a frame, ensemble 10": (lambda: _brockett(6, 10), IsoMP(), 0.1, 20, 4),
    "so(40) BLAS": (lambda: _elementwise(iso.algebras.so(40)), IsoMP(), 0.1, 12, 3),
    "u(40) BLAS": (lambda: _elementwise(iso.algebras.u(40)), IsoMP(), 0.1, 12, 3),
    "su(40) BLAS": (lambda: _elementwise(iso.algebras.su(40)), IsoMP(), 0.1, 12, 3),
    "herm(33) BLAS": (lambda: _elementwise(iso.algebras.herm(33)), IsoMP(), 0.1, 10, 2),
    "so(130) BLAS, triangular blocks": (
        lambda: _elementwise(iso.algebras.so(130)),
        IsoMP(),
        0.1,
        4,
        1,
    ),
    "u(70) BLAS, a short last row block": (
        lambda: _elementwise(iso.algebras.u(70)),
        IsoMP(),
        0.1,
        4,
        1,
    ),
    "so(40) BLAS ensemble 3": (
        lambda: (lambda p, w: (p, np.stack([w, 0.5 * w, 1.5 * w])))(
            *_elementwise(iso.algebras.so(40))
        ),
        IsoMP(),
        0.1,
        8,
        2,
    ),
    "CompiledB so(8)": (lambda: _user_dense(iso.algebras.so(8)), IsoMP(), 0.2, 30, 3),
    "CompiledB u(7) ensemble 4": (
        lambda: _user_dense(iso.algebras.u(7), members=4),
        IsoMP(),
        0.2,
        20,
        5,
    ),
    "CompiledB herm(6) Anderson": (
        lambda: _user_dense(iso.algebras.herm(6)),
        IsoMP(solver=A3),
        0.3,
        20,
        2,
    ),
    "CompiledB so(36) BLAS": (lambda: _user_dense(iso.algebras.so(36)), IsoMP(), 0.1, 10, 2),
    "CompiledB su(34) BLAS": (lambda: _user_dense(iso.algebras.su(34)), IsoMP(), 0.1, 10, 2),
    "CompiledB (R^3, x)^6": (lambda: _user_particles("so3"), IsoMP(), 0.1, 40, 4),
    "CompiledB (R^3, x)^6 ensemble": (
        lambda: _user_particles("so3", members=3),
        IsoMP(),
        0.1,
        20,
        4,
    ),
    "CompiledB (R^3, x)^6 spherical": (lambda: _user_particles("so3"), SMM(), 0.1, 40, 4),
    "CompiledB (R^3, x_L)^6": (lambda: _user_particles("sl2"), IsoMP(), 0.05, 40, 4),
    "CompiledB spin chain (generic particles)": (_user_chain, IsoMP(), 0.1, 30, 3),
    "spin chain (fused)": (_chain, IsoMP(), 0.1, 40, 4),
    "spin chain (fused), X0 = W": (_chain, IsoMP(initial_guess="state"), 0.1, 30, 3),
    "spin chain (fused), Anderson": (_chain, IsoMP(solver=A3), 0.1, 30, 3),
    "spin chain (fused) spherical": (_chain, SMM(), 0.1, 40, 4),
    "spin chain ensemble 3 (fused)": (lambda: _chain(members=3), IsoMP(), 0.1, 20, 4),
    "sphere vortices": (_sphere_vortices, IsoMP(), 0.01, 40, 5),
    "sphere vortices spherical": (_sphere_vortices, SMM(), 0.01, 40, 5),
    "sphere vortices ensemble": (lambda: _sphere_vortices(members=3), IsoMP(), 0.01, 20, 5),
    "hyperbolic vortices 1": (
        lambda: iso.models.hyperbolic_vortices(config=1),
        IsoMP(),
        0.01,
        60,
        6,
    ),
    "hyperbolic vortices 2": (
        lambda: iso.models.hyperbolic_vortices(config=2),
        IsoMP(),
        0.001,
        40,
        5,
    ),
}


def test_lower_blocks_cover_the_rows_in_tile_aligned_pieces() -> None:
    """The triangular product's row blocks: contiguous, tile aligned, two or more from
    ``n = 2 * tile`` (one block is a full product), at most eight; packed size <= n^2."""
    from isoflow._compiled import dense

    tile = dense._TILE
    for n in range(1, 1100, 7):
        blocks = dense.lower_blocks(n)
        assert blocks[0][0] == 0 and blocks[-1][1] == n
        assert all(a[1] == b[0] for a, b in itertools.pairwise(blocks))
        assert all(r0 % tile == 0 and r1 > r0 for r0, r1 in blocks)
        assert len(blocks) <= 8
        if n >= 2 * tile:
            assert len(blocks) >= 2
        assert sum((r1 - r0) * r1 for r0, r1 in blocks) <= n * n


#: Complex dense runs that the planar 3M stage takes when its threshold is lowered
#: (:mod:`isoflow._compiled.dense_planar`): name -> (problem factory, steps).
PLANAR_CASES: dict[str, tuple[Callable[[], tuple], int]] = {
    "su(40)": (lambda: _elementwise(iso.algebras.su(40)), 8),
    "u(70), a short last row block": (lambda: _elementwise(iso.algebras.u(70)), 6),
    "herm(33)": (lambda: _elementwise(iso.algebras.herm(33)), 6),
    "CompiledB su(34)": (lambda: _user_dense(iso.algebras.su(34)), 6),
    "euler_sphere su(48)": (lambda: iso.models.euler_sphere(N=48, seed=1), 8),
}


@pytest.mark.parametrize("name", list(PLANAR_CASES))
def test_planar_3m_stage_equals_numpy_and_the_complex_tiles(name: str, monkeypatch) -> None:
    """The planar stage (three real products per complex one) gives the NumPy path's run and
    the complex-tile stage's to 1e-13, every state exactly in the space."""
    from isoflow._compiled import dense

    make, n = PLANAR_CASES[name]
    prob, y = make()
    h = 0.1 if prob.algebra.shape[0] != 48 else 0.3 / float(np.linalg.norm(prob.B(y), 2))
    monkeypatch.setattr(dense, "PLANAR_MIN_N", 2)
    runner = compiled_runner(prob, IsoMP(), y, h)
    assert runner is not None and runner.layout.record.planar
    a, b = compiled_and_numpy(prob, IsoMP(), y, h, n, 2, chunks=(n // 2, n - n // 2))
    assert_same_run(a, b)
    s = dense.sigma_sign(prob.algebra)
    assert np.array_equal(a.y, s * np.swapaxes(a.y, -1, -2).conj())  # exact mirrors
    monkeypatch.setattr(dense, "PLANAR_MIN_N", 10**9)
    tiles = run_with(compiled_runner(prob, IsoMP(), y, h), n, 2, None)
    assert np.max(np.abs(a.y - tiles.y)) <= 1e-13 * max(1.0, float(np.max(np.abs(tiles.y))))


def test_planar_stage_keeps_the_casimirs_at_rounding(monkeypatch) -> None:
    """Euler on the sphere through the planar stage: every Casimir ``Tr(W^k)`` at rounding
    after 30 steps at ``h ||B|| = 0.3``."""
    from isoflow._compiled import dense

    monkeypatch.setattr(dense, "PLANAR_MIN_N", 2)
    prob, W0 = iso.models.euler_sphere(N=48, seed=2)
    h = 0.3 / float(np.linalg.norm(prob.B(W0), 2))
    sol = iso.solve(prob, IsoMP(), W0, dt=h, n_steps=30, save_every=30, progress=False)
    assert sol.stats.runner == "compiled, dense su(48) (BLAS, real planes)"
    assert sol.diagnostics.casimir_drift < 1e-13


#: Cases where one step's residual lands within 1% of the tolerance, so the two paths' rounding
#: may take one more iteration on one of them: "hyperbolic vortices 2" with IsoMP's quartic start
#: (173 compiled against 172 NumPy iterations at rtol = 1e-14; equal counts at 0.99e-14 and
#: 1.01e-14).
ON_THE_TOLERANCE = {"hyperbolic vortices 2"}


@pytest.mark.parametrize("name", list(CASES))
def test_compiled_equals_numpy(name: str) -> None:
    """Same saved rows, final state, stored offsets, iterations and failures."""
    make, method, h, n, save_every = CASES[name]
    prob, y = make()
    a, b = compiled_and_numpy(prob, method, y, h, n, save_every, chunks=(n // 3, n - n // 3))
    assert a.label.startswith("compiled")
    exact = "Anderson" not in name and name not in ON_THE_TOLERANCE
    assert_same_run(a, b, iters_exact=exact)


@pytest.mark.parametrize(
    "name",
    ["rigid so(10)", "rigid ensemble 20 (blocks)", "so(40) BLAS", "spin chain (fused)",
     "hyperbolic vortices 1", "CompiledB (R^3, x)^6 spherical", "brockett herm(6) in a frame"],
)  # fmt: skip
def test_chunks_give_the_same_run_bit_for_bit(name: str) -> None:
    """A run split into calls anywhere is the same run (what makes resume bit for bit)."""
    make, method, h, n, save_every = CASES[name]
    prob, y = make()
    whole = run_with(compiled_runner(prob, method, y, h), n, save_every)
    split = run_with(compiled_runner(prob, method, y, h), n, save_every, chunks=(1, 5, n - 6))
    assert np.array_equal(whole.rows, split.rows) and np.array_equal(whole.y, split.y)
    for x, z in zip(whole.state[1:], split.state[1:], strict=True):
        assert np.array_equal(x, z)
    # a new runner started from the exported state continues the run exactly
    stop = 2 * save_every  # a save point (where the loop checkpoints every layout)
    part = run_with(compiled_runner(prob, method, y, h), n, save_every, chunks=(stop,))
    rest = compiled_runner(prob, method, part.y, h, method_state=part.state, k=stop)
    done = run_with(rest, n, save_every, chunks=(n - stop,))
    assert np.array_equal(done.y, whole.y)


def test_solve_runs_compiled_and_agrees_with_numpy() -> None:
    prob, W0 = _rigid()
    sol = iso.solve(prob, IsoMP(), W0, dt=0.1, n_steps=200, save_every=7)
    ref = iso.solve(dataclasses.replace(prob, kernel=None), IsoMP(), W0, dt=0.1, n_steps=200,
                    save_every=7)  # fmt: skip
    assert sol.stats.runner.startswith("compiled") and ref.stats.runner == "NumPy"
    assert np.array_equal(sol.ts, ref.ts)
    assert np.max(np.abs(sol.ys - ref.ys)) <= 1e-13
    assert sol.stats.n_iterations == ref.stats.n_iterations
    # one B evaluation per fixed-point iteration, counted on both paths
    assert sol.stats.n_B_evaluations == ref.stats.n_B_evaluations == sol.stats.n_iterations
    assert sol.diagnostics.casimir_drift <= 1e-13


@pytest.mark.parametrize("method", [IsoMP(), SMM()], ids=["isomp", "spherical"])
def test_ensemble_member_that_fails_is_frozen_like_numpy(method: iso.Method) -> None:
    """One diverging member: frozen at its last good state; the others finish (both paths)."""
    prob, w0 = _user_particles("so3", N=4, members=4)
    w0[2] *= 60.0  # h ||B|| far too large for this member
    a, b = compiled_and_numpy(prob, method, w0, 0.5, 12, 3)
    assert_same_run(a, b)
    assert a.failures.step[2] >= 0 and (a.failures.step[[0, 1, 3]] == -1).all()
    assert a.k == 12


def test_blocked_ensemble_member_failure_matches_numpy() -> None:
    prob, W0 = _rigid(members=20, scale=1.0)
    W0[13] *= 400.0
    a, b = compiled_and_numpy(prob, IsoMP(), W0, 0.1, 10, 2)
    assert "lanes" in a.label
    assert_same_run(a, b)
    assert list(a.failures.failed) == [13]


def test_single_system_failure_after_good_steps() -> None:
    """A run continued (from its exported state) with a tighter iteration budget fails in the
    middle: it ends at the last good state, on both paths."""
    from isoflow._stepping import PythonRunner

    prob, W0 = _rigid()
    good = run_with(compiled_runner(prob, IsoMP(), W0, 0.1), 40, 40, chunks=(5,))
    tight = IsoMP(solver=iso.FixedPoint(max_iter=2))
    plain = dataclasses.replace(prob, kernel=None)
    kw = {"method_state": good.state, "k": 5}
    a = run_with(compiled_runner(prob, tight, good.y, 0.1, **kw), 40, 1, chunks=(35,))
    b = run_with(PythonRunner(plain, tight, good.y, 0.1, **kw), 40, 1, chunks=(35,))
    assert_same_run(a, b)
    assert a.k == 5 and a.failures.step[0] == 5 and np.array_equal(a.y, good.y)


def test_non_finite_state_fails_like_numpy() -> None:
    prob, x0 = _sphere_vortices(3)
    bad = x0.copy()
    bad[1] = bad[0]  # two vortices at one point: B is infinite
    a, b = compiled_and_numpy(prob, IsoMP(), bad, 0.01, 5, 1)
    assert_same_run(a, b)
    assert a.failures.step[0] == 0 and a.k == 0


@pytest.mark.parametrize("compensated", [False, True])
def test_lanes_update_reports_each_non_finite_lane(compensated: bool) -> None:
    """The lanes' update flags exactly the lanes holding an infinite or NaN entry (real or
    imaginary part), not those whose finite parts are near the overflow threshold."""
    import numba

    from isoflow._compiled import lanes

    @numba.njit
    def advance(lay, W, h, C, E, Wn, fin):  # type: ignore[no-untyped-def]
        lanes._advance_state(lay, W, h, C, E, Wn, fin)

    n, L = 2, lanes.LANES
    lay = lanes.ElementwiseLanes(n, -1.0, False, L, np.ones((n, n)))
    W = np.zeros((n, n, L), dtype=complex)
    C = np.zeros((n, n, L), dtype=complex)
    W[0, 1, 1] = 1.7e308  # + h C overflows the real part
    C[0, 1, 1] = 1.7e308
    W[1, 0, 2] = complex(0.0, np.nan)
    C[1, 1, 3] = complex(0.0, -np.inf)
    W[1, 1, 4] = complex(1.7e308, 1.7e308)  # finite, near the threshold in both parts
    W[0, 0, 5] = complex(-1.7e308, 1.0)
    E = np.zeros(W.size if compensated else 0, dtype=complex)
    Wn = np.empty(W.size, dtype=complex)
    fin = np.ones(L, dtype=np.bool_)
    advance(lay, W.reshape(-1), 1.0, C.reshape(-1), E, Wn, fin)
    assert [q for q in range(L) if not fin[q]] == [1, 2, 3]
    assert Wn.reshape(n, n, L)[1, 1, 4] == complex(1.7e308, 1.7e308)


def test_user_function_that_raises_fails_the_run_with_it_as_cause() -> None:
    alg = iso.algebras.so(5)
    d = np.arange(1.0, 6.0)
    C = 0.5 * (d[:, None] + d[None, :])
    W0 = alg.random(0)
    W0 *= 0.3 / float(np.max(np.abs(W0)))  # the largest entry is 0.3 and moves
    prob = iso.IsospectralProblem(
        B=lambda W: C * W, algebra=alg, kernel=iso.CompiledB(uk.raises_when_large, (C, 0.31))
    )
    with pytest.raises(iso.IsoflowError, match="B raised: ValueError: entry too large") as err:
        iso.solve(prob, IsoMP(), W0, dt=0.1, n_steps=500)
    assert isinstance(err.value.__cause__, ValueError)  # as on the NumPy path
    sol = iso.solve(prob, IsoMP(), W0, dt=0.1, n_steps=500, throw=False)
    k = int(sol.failed_step)
    assert 0 < k < 500 and sol.stats.n_steps == k and len(sol.ys) == k + 1
    assert sol.failure_reasons == {(): "B raised: ValueError: entry too large"}
    plain = iso.solve(dataclasses.replace(prob, kernel=None), IsoMP(), W0, dt=0.1, n_steps=k)
    assert np.allclose(sol.ys, plain.ys, rtol=0, atol=1e-12)  # the run up to the raise


def test_compiled_b_is_checked() -> None:
    alg = iso.algebras.so(4)
    with pytest.raises(TypeError, match="numba-compiled"):
        iso.CompiledB(lambda W, out: None)
    with pytest.raises(TypeError, match="args must be a tuple"):
        iso.CompiledB(uk.neighbours, [1.0])
    for nested in ((np.ones(2), 1.0), [1.0], {"c": 1.0}):  # numba's threads fail on these
        with pytest.raises(TypeError, match=r"CompiledB: args\[1\] is a .*flatten it"):
            iso.CompiledB(uk.neighbours, (np.ones(3), nested))
    bad = iso.IsospectralProblem(algebra=alg, kernel=iso.CompiledB(uk.returns_nothing_useful))
    with pytest.raises(iso.InvalidBError, match="does not compile"):
        iso.solve(bad, IsoMP(), alg.random(0), dt=0.1, n_steps=2)
    # the reason numba gives, not its first line (which names only its compiler stage)
    for kernel, reason in (
        (iso.CompiledB(uk.writes_complex_into_real, (1.0 + 1j,)),
         r"found for signature: setitem\(array\(float64, 2d, C\), .*complex128\)"),
        (iso.CompiledB(uk.declared_any_layout), r"compilation disabled \(f was compiled for an "
                                                r"explicit signature.*float64\[:, ::1\]"),
    ):  # fmt: skip
        prob = iso.IsospectralProblem(algebra=alg, kernel=kernel)
        with pytest.raises(iso.InvalidBError, match=reason) as err:
            iso.solve(prob, IsoMP(), alg.random(0), dt=0.1, n_steps=2)
        assert "Failed in" not in str(err.value) and "\n" not in str(err.value)
    # a field that modifies its state: named as such, not as a kernel/B or broadcasting slip
    C4 = np.ones((4, 4))
    moving = iso.IsospectralProblem(algebra=alg, kernel=iso.CompiledB(uk.modifies_its_state, (C4,)))
    for y0 in (alg.random(0), alg.random(0, batch=(3,))):
        with pytest.raises(iso.InvalidBError, match="gives other values for the same state"):
            iso.solve(moving, IsoMP(), y0, dt=0.1, n_steps=2)
    # a field that relies on out starting at zero: the NumPy path zeroes it, the compiled
    # loops do not (this ran on stale entries, and gave another answer from run to run)
    for f, entry in ((uk.skips_the_diagonal, r"out\[0, 0\]"), (uk.adds_into_out, r"out\[0, 0\]")):
        partial = iso.IsospectralProblem(algebra=alg, kernel=iso.CompiledB(f, (C4,)))
        for y0, where in ((alg.random(0), entry), (alg.random(0, batch=(3,)), r"out\[0, 0, 0\]")):
            with pytest.raises(iso.InvalidBError, match=where + " unwritten or adds to it"):
                iso.solve(partial, IsoMP(), y0, dt=0.1, n_steps=2)
    # a kernel that is not the problem's B is caught before the run
    C = np.ones((4, 4))
    wrong = iso.IsospectralProblem(
        B=lambda W: -C * W, algebra=alg, kernel=iso.CompiledB(uk.cubic_elementwise, (C,))
    )
    with pytest.raises(iso.InvalidBError, match="does not describe its B"):
        iso.solve(wrong, IsoMP(), alg.random(0), dt=0.1, n_steps=2)


def test_compiled_b_alone_defines_the_problem() -> None:
    """A problem given only a CompiledB gets its Python B from it (B written once)."""
    alg = iso.algebras.u(5)
    ref = uk.cubic_problem(alg, seed=4)
    only = iso.IsospectralProblem(algebra=alg, kernel=ref.kernel)
    W = 0.2 * alg.random(1, batch=(2, 3))
    assert np.max(np.abs(only.B(W) - ref.B(W))) <= 1e-14 * np.max(np.abs(ref.B(W)))
    sol = iso.solve(dataclasses.replace(only, kernel=None), IsoMP(), W[0, 0], dt=0.1, n_steps=20)
    assert sol.stats.runner == "NumPy" and sol.success


@pytest.mark.parametrize(
    "setup",
    [
        lambda: (iso.models.rigid_body(4)[0], iso.Newton()),
        lambda: (iso.models.rigid_body(4)[0], None),
        lambda: (iso.models.heisenberg_chain(5)[0], "classical"),
    ],
    ids=["newton", "no kernel", "classical midpoint"],
)
def test_runs_without_a_compiled_path_take_numpy(setup) -> None:
    prob, which = setup()
    if which is None:
        prob, method = dataclasses.replace(prob, kernel=None), IsoMP()
    elif which == "classical":
        method = iso.ClassicalMidpoint()
    else:
        method = IsoMP(solver=which)
    y0 = prob.algebra.random(0) * 0.1
    assert compiled_runner(prob, method, y0, 0.1) is None
    assert iso.solve(prob, method, y0, dt=0.1, n_steps=3).stats.runner == "NumPy"


def _isolated_threaded_ensembles() -> None:
    """Members over numba threads give the serial answer (run in a fresh process)."""
    import numba

    from isoflow.threads import available_cores, thread_limits

    if available_cores() < 2:
        return
    for name in (
        "rigid ensemble 20 (blocks)",
        "CompiledB u(7) ensemble 4",
        "sphere vortices ensemble",
    ):
        make, method, h, n, save_every = CASES[name]
        prob, y = make()
        with thread_limits(blas=1, numba=1):
            serial = run_with(compiled_runner(prob, method, y, h), n, save_every)
        with thread_limits(blas=1):
            r = compiled_runner(prob, method, y, h)
            assert r.parallel and numba.get_num_threads() > 1
            threaded = run_with(r, n, save_every)
        assert np.array_equal(serial.rows, threaded.rows), name
    # a long chain cut into chunks over the threads (the threshold lowered for the test): the
    # residual is summed chunk by chunk, so the agreement is to rounding, not bit for bit
    import isoflow._compiled.spin_chain as sc

    sc.PARALLEL_MIN_SPINS = 1000
    prob, w0 = _chain(N=3000)
    with thread_limits(blas=1, numba=1):
        serial = run_with(compiled_runner(prob, IsoMP(), w0, 0.1), 10, 2)
    with thread_limits(blas=1):
        r = compiled_runner(prob, IsoMP(), w0, 0.1)
        assert "threaded" in r.label
        threaded = run_with(r, 10, 2)
    assert np.max(np.abs(serial.rows - threaded.rows)) <= 1e-13
    assert abs(serial.iterations - threaded.iterations) <= 1


def test_threaded_ensembles_equal_serial() -> None:
    here = os.path.dirname(os.path.abspath(__file__))
    code = f"import sys; sys.path.insert(0, {here!r}); import test_compiled as t; "
    code += "t._isolated_threaded_ensembles()"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


COMPOSED = {
    "rigid so(10), suzuki-4": (_rigid, iso.Composition(IsoMP(), "suzuki-4"), 0.2, 20, 2),
    "rigid so(10), yoshida-6, X0 = W": (
        _rigid,
        iso.Composition(IsoMP(initial_guess="state"), "yoshida-6"),
        0.2,
        10,
        1,
    ),
    "rigid ensemble 20, triple-jump": (
        lambda: _rigid(members=20),
        iso.Composition(IsoMP(), "triple-jump-4"),
        0.1,
        10,
        5,
    ),
    "u(40) BLAS, kahan-li-6": (
        lambda: _elementwise(iso.algebras.u(40)),
        iso.Composition(IsoMP(), "kahan-li-6"),
        0.1,
        4,
        2,
    ),
    "spin chain (fused), spherical suzuki-4": (
        _chain,
        iso.Composition(SMM(), "suzuki-4"),
        0.1,
        10,
        2,
    ),
    "hyperbolic vortices 1, kahan-li-8": (
        lambda: iso.models.hyperbolic_vortices(config=1),
        iso.Composition(IsoMP(), "kahan-li-8"),
        0.05,
        10,
        5,
    ),
    "CompiledB so(8), Anderson, suzuki-4": (
        lambda: _user_dense(iso.algebras.so(8)),
        iso.Composition(IsoMP(solver=A3), "suzuki-4"),
        0.2,
        10,
        2,
    ),
}


@pytest.mark.parametrize("name", list(COMPOSED))
def test_compiled_compositions_equal_numpy(name: str) -> None:
    """Each substep a compiled step of its own length with its own warm start."""
    make, method, h, n, save_every = COMPOSED[name]
    prob, y = make()
    a, b = compiled_and_numpy(prob, method, y, h, n, save_every, chunks=(3, n - 3))
    assert a.label.startswith("compiled")
    assert_same_run(a, b, iters_exact="Anderson" not in name)
    # the exported state (one warm start per substep position) continues the run exactly
    longer = run_with(compiled_runner(prob, method, y, h), 2 * n, save_every)
    again = compiled_runner(prob, method, a.y, h, method_state=a.state, k=n)
    rest = run_with(again, 2 * n, save_every, chunks=(n,))
    assert np.array_equal(rest.y, longer.y)


def _steps_in_calls(
    problem: iso.IsospectralProblem,
    method: iso.IsoMP,
    y: np.ndarray,
    calls: tuple[int, ...],
    numba_threads: int,
) -> np.ndarray:
    """The state after the steps of ``calls`` (one compiled call each) from ``y``."""
    from isoflow._time_loop import run_threads

    with run_threads({"blas": 1, "numba": numba_threads}):
        runner = compiled_runner(problem, method, y, 0.05)
        assert runner is not None
        n = sum(calls)
        return run_with(runner, n, save_every=n, chunks=calls).y


@pytest.mark.parametrize("numba_threads", [1, 2])
@pytest.mark.parametrize("compensated", [True, False])
def test_kept_buffers_give_the_states_of_fresh_ones(
    monkeypatch: pytest.MonkeyPatch, numba_threads: int, compensated: bool
) -> None:
    """The driver's state-sized buffers, kept by the runner per thread from call to call for
    large units (:data:`isoflow._compiled.runner.KEEP_BUFFERS_BYTES`) and fresh in every call
    for small ones, give the same states bit for bit, whatever the calls' lengths: an
    ensemble (members as lanes, units over numba threads), one dense system, and a split step
    (whose failed steps return to the buffered start)."""
    from isoflow._compiled import runner as runner_module

    if numba_threads > iso.threads.available_cores():
        pytest.skip("needs 2 cores")
    Y = iso.algebras.so(6).random(seed=4, batch=(40,), scale=0.3)
    rigid, _ = iso.models.rigid_body(6)
    sphere, S0 = iso.models.euler_sphere(N=12, seed=2)
    split, _ = iso.models.euler_sphere(N=12, seed=2, viscosity=0.01, drag=0.1)
    runs = [(rigid, iso.IsoMP(compensated=compensated), Y),
            (sphere, iso.IsoMP(compensated=compensated), S0),
            (split, iso.Strang(iso.IsoMP(compensated=compensated)), S0)]  # fmt: skip
    for problem, method, y in runs:
        fresh = _steps_in_calls(problem, method, y, (12,), numba_threads)
        monkeypatch.setattr(runner_module, "KEEP_BUFFERS_BYTES", 0)
        kept_one = _steps_in_calls(problem, method, y, (12,), numba_threads)
        kept_many = _steps_in_calls(problem, method, y, (1, 5, 2, 4), numba_threads)
        monkeypatch.undo()
        assert fresh.tobytes() == kept_one.tobytes() == kept_many.tobytes()
