"""The conformance suite: every method on every space it applies to, the same properties.

A method joins by being listed once in :data:`METHODS`, a space in
:data:`helpers.SPACES`. Each pair is checked for the observed order (log-log fit against
DOP853), symmetry (``step(-h) o step(h) = id`` for symmetric methods), structure (the state
stays in ``V``; isospectral methods keep the Casimirs to rounding), ensembles (equal to separate
runs), failure behaviour (a hopeless step fails with a typed error; in an ensemble only that
member is frozen) and the checkpoint round trip (a run continued from its packed method state
is the uninterrupted run, bit for bit). Method-specific properties live in their own files.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

import isoflow as iso
from helpers import SPACES, loglog_slope, run_with, space_problem, space_state
from isoflow._stepping import PythonRunner
from isoflow.io.codec import pack_state as _pack_state
from isoflow.io.codec import unpack_state as _unpack_state


@dataclass(frozen=True)
class MethodCase:
    """A method and what it promises."""

    make: Callable[[], iso.Method]
    isospectral: bool
    spaces: tuple[str, ...] | None = None  # None: every space
    order_spaces: tuple[str, ...] = ("so4", "herm3")
    #: whether a far too large step makes its solve fail (Newton may find a root off the
    #: consistent branch there instead; see the Newton docstring)
    fails_on_huge_steps: bool = True


VECTOR = ("so3-vectors",)
METHODS: dict[str, MethodCase] = {
    "IsoMP": MethodCase(
        iso.IsoMP, True, order_spaces=("so4", "herm3", "sl2-vectors", "su3-pairs", "se3-vectors")
    ),
    "IsoMP, X0 = W": MethodCase(lambda: iso.IsoMP(initial_guess="state"), True),
    "IsoMP, Anderson": MethodCase(lambda: iso.IsoMP(solver=iso.FixedPoint(anderson=3)), True),
    "IsoMP, Newton": MethodCase(
        lambda: iso.IsoMP(solver=iso.Newton()), True, fails_on_huge_steps=False
    ),
    "classical midpoint": MethodCase(iso.ClassicalMidpoint, False),
    "RK4": MethodCase(iso.RK4, False),
    "spherical midpoint": MethodCase(iso.SphericalMidpoint, True, VECTOR, VECTOR),
    "IsoMP o suzuki-4": MethodCase(lambda: iso.Composition(iso.IsoMP(), "suzuki-4"), True),
    "spherical o triple-jump-4": MethodCase(
        lambda: iso.Composition(iso.SphericalMidpoint(), "triple-jump-4"), True, VECTOR, VECTOR
    ),
    "IsoSyRK(2)": MethodCase(lambda: iso.IsoSyRK(2), True),
}

PAIRS = [
    (m, s) for m, case in METHODS.items() for s in SPACES if case.spaces is None or s in case.spaces
]
ORDER_PAIRS = [(m, s) for m, case in METHODS.items() for s in case.order_spaces]


def _ids(pairs: list[tuple[str, str]]) -> list[str]:
    return [f"{m} on {s}" for m, s in pairs]


@pytest.mark.parametrize(("name", "space"), ORDER_PAIRS, ids=_ids(ORDER_PAIRS))
def test_observed_order(name: str, space: str) -> None:
    method = METHODS[name].make()
    prob = space_problem(space, seed=3)
    W0 = space_state(prob.algebra, 1, norm=0.7)
    T = 1.0
    ref = iso.reference_solution(prob, W0, [T])[0]
    hs = np.array([0.2, 0.1, 0.05])
    errs = []
    for h in hs:
        sol = iso.solve(prob, method, W0, dt=float(h), t1=T, save_every=1000)
        errs.append(float(np.max(np.abs(sol.ys[-1] - ref))))
    assert min(errs) > 1e-11  # above the reference's error: the fit measures the method
    assert loglog_slope(hs, np.array(errs)) == pytest.approx(method.order, abs=0.25)


@pytest.mark.parametrize(("name", "space"), PAIRS, ids=_ids(PAIRS))
def test_symmetric_methods_step_back(name: str, space: str) -> None:
    method = METHODS[name].make()
    if not method.symmetric:
        pytest.skip(f"{method.name} is not symmetric")
    prob = space_problem(space, seed=5)
    W0 = space_state(prob.algebra, 2)
    W1 = iso.step(prob, method, W0, 0.1)
    assert float(np.max(np.abs(W1 - W0))) > 1e-3  # a real step
    assert float(np.max(np.abs(iso.step(prob, method, W1, -0.1) - W0))) <= 1e-13


@pytest.mark.parametrize(("name", "space"), PAIRS, ids=_ids(PAIRS))
def test_structure(name: str, space: str) -> None:
    """In ``V`` to rounding; Casimirs to rounding for the isospectral methods."""
    case = METHODS[name]
    prob = space_problem(space, seed=7)
    W0 = space_state(prob.algebra, 3)
    sol = iso.solve(prob, case.make(), W0, dt=0.05, n_steps=200, save_every=20)
    d = sol.diagnostics
    assert sol.success and float(np.max(d.max_distance)) <= 1e-13
    assert float(np.max(np.abs(sol.ys[-1] - W0))) > 1e-2  # the flow moved
    if case.isospectral:
        assert float(np.max(d.casimir_drift)) <= 1e-12


@pytest.mark.parametrize(("name", "space"), PAIRS, ids=_ids(PAIRS))
def test_ensemble_equals_separate_runs(name: str, space: str) -> None:
    method = METHODS[name].make()
    """A ``(2, 2)`` ensemble whose members converge at different speeds."""
    prob = space_problem(space, seed=9)
    Ws = np.stack([space_state(prob.algebra, s, norm=0.3 + 0.1 * s) for s in range(4)])
    Ws = Ws.reshape(2, 2, *prob.algebra.shape)
    ens = iso.solve(prob, method, Ws, dt=0.1, n_steps=15, save_every=5)
    assert ens.ys.shape == (4, 2, 2, *prob.algebra.shape)
    assert ens.diagnostics.casimir_drift.shape == (2, 2)
    for i in range(2):
        for j in range(2):
            one = iso.solve(prob, method, Ws[i, j], dt=0.1, n_steps=15, save_every=5)
            scale = float(np.max(np.abs(one.ys)))
            assert float(np.max(np.abs(ens.ys[:, i, j] - one.ys))) <= 1e-13 * scale


@pytest.mark.parametrize(("name", "space"), PAIRS, ids=_ids(PAIRS))
def test_hopeless_step_fails_clearly_and_freezes_only_that_member(name: str, space: str) -> None:
    method = METHODS[name].make()
    if not method.implicit:
        pytest.skip(f"{method.name} is explicit: no nonlinear solve to fail")
    if not METHODS[name].fails_on_huge_steps:
        pytest.skip(f"{method.name} finds a root off the consistent branch at huge steps")
    prob = space_problem(space, seed=11)
    good = space_state(prob.algebra, 4, norm=0.5)
    bad = space_state(prob.algebra, 5, norm=60.0)
    with pytest.raises((iso.ConvergenceError, iso.NonFiniteError)):
        iso.solve(prob, method, bad, dt=0.5, n_steps=3)
    sol = iso.solve(prob, method, np.stack([good, bad, good]), dt=0.05, n_steps=6, throw=False)
    assert not sol.success and sol.status == 1
    assert list(sol.failed_step) == [-1, 0, -1] and list(sol.failure_reasons) == [(1,)]
    assert np.array_equal(sol.ys[-1, 1], prob.algebra.validate(bad))  # frozen at its start
    alone = iso.solve(prob, method, good, dt=0.05, n_steps=6)
    assert float(np.max(np.abs(sol.ys[-1, 0] - alone.ys[-1]))) <= 1e-13


@pytest.mark.parametrize(("name", "space"), PAIRS, ids=_ids(PAIRS))
def test_checkpoint_round_trip_is_bit_for_bit(name: str, space: str) -> None:
    method = METHODS[name].make()
    prob = space_problem(space, seed=13)
    W0 = space_state(prob.algebra, 6)
    h = 0.05
    whole = run_with(PythonRunner(prob, method, W0, h), 12, 12)
    part = run_with(PythonRunner(prob, method, W0, h), 12, 12, chunks=(5,))
    state = _unpack_state(*_pack_state(part.state))
    rest = run_with(PythonRunner(prob, method, part.y, h, method_state=state, k=5), 12, 12,
                    chunks=(7,))  # fmt: skip
    assert np.array_equal(rest.y, whole.y)


# ---- a method written once runs compiled on every layout ---------------------------------------


@dataclass(frozen=True)
class ToyMidpoint(iso.ClassicalMidpoint):
    """A test-only method: the implicit midpoint rule, whose compiled stage is written here,
    once, against the layout blocks, and joins the compiled paths by one registration."""

    name = "toy midpoint"  # type: ignore[assignment]


def _register_toy_stage() -> None:
    import numba

    from isoflow._compiled import blocks, stages

    @numba.njit(cache=True)
    def iterate(f, fargs, lay, mp, sd, W, X, G, aux, work, h, rr):  # type: ignore[no-untyped-def]
        blocks.evaluate_B(lay, f, fargs, X, work[0])
        blocks.bracket(lay, work[0], X, aux)
        blocks.stage_update1(lay, W, 0.5 * h, aux, G, X, rr)

    @numba.njit(cache=True)
    def finish(f, fargs, lay, mp, sd, W, X, aux, work, h, Wn, fin):  # type: ignore[no-untyped-def]
        blocks.advance_state(lay, W, h, aux, Wn, fin)

    needs = frozenset({"evaluate_B", "bracket", "stage_update1", "advance_state"})
    stages.register(ToyMidpoint, stages.CompiledStage("toy midpoint", iterate, finish, needs, 1))


_register_toy_stage()


def _toy_cases() -> dict[str, tuple[Callable[[], tuple], str]]:
    import user_kernels as uk

    def elementwise(n: int) -> tuple:
        C = np.random.default_rng(n).uniform(-1, 1, (n, n))
        kernel = iso.ElementwiseLinear(0.5 * (C + C.T))
        alg = iso.algebras.so(n)
        W0 = alg.random(1)
        return iso.IsospectralProblem(B=kernel.evaluate, algebra=alg, kernel=kernel), W0

    def particles(kind: str) -> tuple:
        alg = iso.algebras.so3_vectors(4) if kind == "so3" else iso.algebras.sl2_vectors(4)
        axis = np.array([0.6, 0.0, 0.8])
        prob = iso.IsospectralProblem(
            B=uk.precession_numpy(axis, 0.7), algebra=alg,
            kernel=iso.CompiledB(uk.precession, (axis, 0.7)),
        )  # fmt: skip
        w0 = np.random.default_rng(4).standard_normal((4, 3))
        if kind == "sl2":
            w0[:, 2] = np.sqrt(1.0 + w0[:, 0] ** 2 + w0[:, 1] ** 2)
        return prob, w0

    def brockett() -> tuple:
        rng = np.random.default_rng(3)
        A = rng.standard_normal((5, 5)) + 1j * rng.standard_normal((5, 5))
        return iso.models.brockett(n=5, N=0.1 * (A + A.conj().T), seed=1)

    def vortices() -> tuple:
        pos = np.eye(3) + 0.1
        pos /= np.linalg.norm(pos, axis=1, keepdims=True)
        return iso.models.sphere_vortices(positions=pos, circulations=np.array([1.0, 0.7, 1.3]))

    def rigid_members() -> tuple:
        prob, W0 = iso.models.rigid_body(6)
        return prob, np.stack([W0 * (1 + 0.05 * i) for i in range(10)])

    def mhd(N: int) -> tuple:
        return iso.models.mhd_sphere(N=N, seed=2, lmax=3)

    return {
        "dense, written-out products": (lambda: iso.models.rigid_body(6), "written-out"),
        "dense, SIMD lanes": (rigid_members, "lanes"),
        "dense, BLAS": (lambda: elementwise(20), "BLAS"),
        "dense, in a frame": (brockett, "frame"),
        "(R^3, x)^N": (lambda: particles("so3"), "(R^3, x)^N"),
        "(R^3, x_L)^N": (lambda: particles("sl2"), "(R^3, x_L)^N"),
        "vortices on the sphere": (vortices, "sphere"),
        "vortices on the hyperboloid": (
            lambda: iso.models.hyperbolic_vortices(config=1),
            "hyperbolic",
        ),
        "spin chain": (
            lambda: iso.models.heisenberg_chain(N=12, initial="random", seed=3),
            "spin chain",
        ),
        "dual pairs, written-out products": (lambda: mhd(6), "dual pairs"),
        "dual pairs, BLAS": (lambda: mhd(20), "BLAS"),
        "heavy top": (lambda: iso.models.heavy_top("kovalevskaya"), "se(3) pairs"),
    }


TOY_CASES = _toy_cases()


@pytest.mark.parametrize("layout", list(TOY_CASES))
def test_a_method_written_once_runs_compiled_on_every_layout(layout: str) -> None:
    """The toy method's stage, written once in this file, runs compiled on every layout and
    equals its own NumPy steps (the time loop's two runners, :data:`helpers.FAST_TOL`)."""
    from helpers import assert_same_run, compiled_and_numpy

    make, label = TOY_CASES[layout]
    prob, y0 = make()
    y0 = prob.algebra.project(np.asarray(y0, dtype=prob.algebra.dtype))
    a, b = compiled_and_numpy(prob, ToyMidpoint(), y0, 0.02, 12, 3)
    assert label in a.label and "toy midpoint" in a.label
    assert a.iterations > 12  # a real solve per step
    assert_same_run(a, b)
