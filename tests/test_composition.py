"""Symmetric compositions of symmetric methods: order conditions, observed orders, structure
(spectrum, symmetry, Lie–Poisson), per-substep warm starts, ensembles, failures, arguments."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import isoflow as iso
from helpers import (
    hamiltonian_problem,
    initial_state,
    loglog_slope,
    random_problem,
    run_with,
    spectrum_backward_error,
)
from isoflow._solve import RUN_FAILED
from isoflow._stepping import PythonRunner
from isoflow.io.codec import pack_state as _pack_state
from isoflow.io.codec import unpack_state as _unpack_state
from isoflow.methods.composition import SCHEMES, composition_order, full_coefficients
from isoflow.methods.isomp import state_parts
from isoflow.registry import build
from test_lie_poisson import _defect
from test_lie_poisson import _problem as lp_problem

NAMED_ORDER = {
    "triple-jump-4": 4,
    "suzuki-4": 4,
    "yoshida-6": 6,
    "kahan-li-6": 6,
    "kahan-li-8": 8,
}


# ---- coefficients and order conditions --------------------------------------------------------
@pytest.mark.parametrize("scheme", list(NAMED_ORDER))
def test_named_schemes_satisfy_their_order_conditions(scheme: str) -> None:
    coeffs = full_coefficients(SCHEMES[scheme][0])
    stages = {"triple-jump-4": 3, "suzuki-4": 5, "yoshida-6": 7, "kahan-li-6": 9, "kahan-li-8": 17}
    assert len(coeffs) == stages[scheme]
    assert coeffs == coeffs[::-1] and abs(sum(coeffs) - 1.0) <= 1e-15
    assert composition_order(coeffs) == NAMED_ORDER[scheme]
    method = iso.Composition(iso.IsoMP(), scheme)
    assert method.order == NAMED_ORDER[scheme] and method.stages == len(coeffs)
    assert method.name == f"IsoMP o {scheme}"


def test_order_conditions_known_cases() -> None:
    """Closed-form cases (HLW II.4): sum g^3 = 0 gives order 4 from a base of order 2; the
    triple jump 1/(2 - 2^(1/(p+1))) raises an order-p base to p + 2 (and no further)."""
    assert composition_order((0.5, 0.5)) == 2  # two half steps: the base method itself
    assert composition_order((0.5, 0.6)) == 0  # inconsistent
    for p in (2, 4, 6):
        g = 1.0 / (2.0 - 2.0 ** (1.0 / (p + 1)))
        coeffs = (g, 1.0 - 2.0 * g, g)
        assert composition_order(coeffs, base_order=p) == p + 2
    # the order-4 triple jump does not raise an order-4 base (the exponent is that of p = 2)
    assert composition_order(full_coefficients(SCHEMES["triple-jump-4"][0]), base_order=4) == 4


def test_user_coefficients() -> None:
    g = 1.0 / (2.0 - 2.0 ** (1.0 / 5.0))
    six = iso.Composition(iso.IsoSyRK(2), [g, 1.0 - 2.0 * g, g])  # triple jump of an order-4 base
    assert six.order == 6 and six.name == "IsoSyRK(2) o custom-6 (3 stages)"
    assert six.scheme == (g, 1.0 - 2.0 * g, g)  # stored as a tuple
    prob = hamiltonian_problem(iso.algebras.so(4), seed=11, nonlinear=True)
    W0 = initial_state(prob.algebra, 6)
    ref = iso.reference_solution(prob, W0, [1.0])[-1]
    ends = [iso.solve(prob, six, W0, dt=1 / n, n_steps=n).ys[-1] for n in (4, 6, 8, 12)]
    errs = [np.linalg.norm(y - ref) for y in ends]
    assert abs(loglog_slope(1 / np.array([4, 6, 8, 12]), errs) - 6.0) <= 0.25, errs


@pytest.mark.parametrize(
    ("base", "scheme", "match"),
    [
        (iso.IsoMP(), "suzuki-6", "unknown composition scheme"),
        (iso.IsoMP(), (0.4, 0.3, 0.3), "symmetric"),
        (iso.IsoMP(), (0.4, 0.3, 0.4), "sum to 1"),
        (iso.IsoMP(), (0.5, float("nan"), 0.5), "finite"),
        (iso.IsoMP(), (), "at least one"),
        (iso.IsoMP(), "x", "unknown"),
        (iso.IsoMP(), 3.0, "name or a sequence"),
        (iso.RK4(), "suzuki-4", "not a symmetric method"),
        ("isomp", "suzuki-4", "must be a Method"),
    ],
)
def test_bad_arguments_raise_parameter_error(base, scheme, match: str) -> None:
    with pytest.raises(iso.ParameterError, match=match):
        iso.Composition(base, scheme)


# ---- accuracy -----------------------------------------------------------------------------------
# (norm of W0, numbers of steps over T = 1): errors between ~1e-4 and ~1e-11, far above the
# DOP853 reference (~1e-13) and in the asymptotic range (measured slopes within 0.13)
ORDER_SETUP = {
    "triple-jump-4": (1.0, [8, 12, 16, 24, 32]),
    "suzuki-4": (1.0, [8, 12, 16, 24, 32]),
    "yoshida-6": (1.0, [8, 12, 16, 24, 32]),
    "kahan-li-6": (1.0, [4, 6, 8, 12, 16]),
    "kahan-li-8": (2.0, [12, 16, 24, 32]),
}


@pytest.fixture(scope="module")
def order_problem():
    prob = hamiltonian_problem(iso.algebras.so(4), seed=11, nonlinear=True)
    refs = {}
    for norm in (1.0, 2.0):
        W0 = initial_state(prob.algebra, 6, norm=norm)
        refs[norm] = (W0, iso.reference_solution(prob, W0, [1.0], rtol=1e-13, atol=1e-13)[-1])
    return prob, refs


@pytest.mark.parametrize("scheme", list(NAMED_ORDER))
def test_observed_order_against_dop853(order_problem, scheme: str) -> None:
    prob, refs = order_problem
    norm, ns = ORDER_SETUP[scheme]
    W0, ref = refs[norm]
    method = iso.Composition(iso.IsoMP(), scheme)
    errs = []
    for n in ns:
        sol = iso.solve(prob, method, W0, dt=1.0 / n, n_steps=n, diagnostics=False)
        errs.append(float(np.linalg.norm(sol.ys[-1] - ref)))
    slope = loglog_slope(1.0 / np.array(ns), np.array(errs))
    assert abs(slope - NAMED_ORDER[scheme]) <= 0.2, (slope, errs)
    assert errs[-1] > 1e-11 and errs[0] < 1e-3, errs


def test_compositions_beat_isomp_on_the_rigid_body() -> None:
    """T = 1, 32 steps on the paper's body (n = 10): each scheme is more accurate than the one
    before it in the table (measured 4.4e-6, 2.2e-9, 3.1e-11, 4.6e-14, 3.3e-15)."""
    prob, W0 = iso.models.rigid_body(n=10)
    ref = iso.reference_solution(prob, W0, [1.0])[-1]
    errs = [
        float(np.linalg.norm(iso.solve(prob, m, W0, dt=1 / 32, n_steps=32).ys[-1] - ref))
        for m in [iso.IsoMP()] + [iso.Composition(iso.IsoMP(), s) for s in list(NAMED_ORDER)[:4]]
    ]
    assert all(b < 0.1 * a for a, b in itertools.pairwise(errs)), errs


# ---- structure ----------------------------------------------------------------------------------
@pytest.mark.parametrize("key", ["so4", "u3", "sym4", "herm3"])
def test_spectrum_preserved_over_many_steps_matrices(key: str) -> None:
    prob = random_problem(key, seed=3, nonlinear=True)
    W0 = initial_state(prob.algebra, 1)
    method = iso.Composition(iso.IsoMP(), "suzuki-4")
    sol = iso.solve(prob, method, W0, dt=0.05, n_steps=400, save_every=400)
    assert sol.success
    assert np.linalg.norm(sol.ys[-1] - W0) > 1e-2 * np.linalg.norm(W0)  # it moved
    assert spectrum_backward_error(W0, sol.ys[-1]) <= 1e-12 * np.linalg.norm(W0, 2)
    assert float(np.max(sol.diagnostics.max_distance)) <= 1e-13


@pytest.mark.parametrize(
    ("model", "base"),
    [
        ("spin", iso.IsoMP()),
        ("spin", iso.SphericalMidpoint()),
        ("vortices", iso.IsoMP()),  # the hyperbolic midpoint: IsoMP on sl2_vectors
    ],
)
def test_casimirs_preserved_on_the_compact_forms(model: str, base: iso.Method) -> None:
    if model == "spin":
        prob, w0 = iso.models.heisenberg_chain(N=12)
        dt, n = 0.05, 300
    else:
        prob, w0 = iso.models.hyperbolic_vortices(config=1)
        dt, n = 0.01, 300
    sol = iso.solve(prob, iso.Composition(base, "yoshida-6"), w0, dt=dt, n_steps=n, save_every=50)
    assert sol.success
    assert np.max(np.abs(sol.ys[-1] - w0)) > 1e-2  # it moved
    assert float(np.max(sol.diagnostics.casimir_drift)) <= 1e-12


@pytest.mark.parametrize(
    ("key", "base"),
    [
        ("so4", iso.IsoMP()),
        ("sp4", iso.IsoMP()),
        ("glC3", iso.IsoMP()),
        ("so4", iso.ClassicalMidpoint()),
        ("spin", iso.SphericalMidpoint()),
        ("vortices", iso.IsoMP()),
    ],
)
def test_composition_is_symmetric(key: str, base: iso.Method) -> None:
    if key == "spin":
        prob, W0 = iso.models.heisenberg_chain(N=6, initial="random", seed=1)
    elif key == "vortices":
        prob, W0 = iso.models.hyperbolic_vortices(config=1)
    else:
        prob = random_problem(key, seed=5, nonlinear=True)
        W0 = initial_state(prob.algebra, 2)
    method = iso.Composition(base, "kahan-li-6")
    h = 0.1
    W1 = iso.step(prob, method, W0, h)
    back = iso.step(prob, method, W1, -h)
    assert float(np.max(np.abs(W1 - W0))) > 1e-3  # a real step
    assert float(np.max(np.abs(back - W0))) <= 1e-13 * max(1.0, float(np.max(np.abs(W0))))


@pytest.mark.parametrize("n", [3, 4])
def test_isomp_compositions_are_lie_poisson(n: int) -> None:
    """The step map's Jacobian preserves the Lie–Poisson tensor (as in test_lie_poisson)."""
    prob = lp_problem(n)
    tight = iso.FixedPoint(rtol=1e-15, stall_rtol=1e-13)
    h = 0.5
    for scheme in ("suzuki-4", "kahan-li-8"):
        assert _defect(prob, iso.Composition(iso.IsoMP(solver=tight), scheme), h) <= 1e-9
    # the composition of a non-Poisson map is not Poisson (measured 3e-8 on so(3), 3e-6 so(4))
    assert _defect(prob, iso.Composition(iso.ClassicalMidpoint(solver=tight)), h) >= 1e-8


# ---- warm starts, state, ensembles, failures ----------------------------------------------------
def test_one_warm_start_per_substep_position() -> None:
    prob = random_problem("so4", seed=17, nonlinear=True)
    W0 = initial_state(prob.algebra, 1)
    method = iso.Composition(iso.IsoMP(), "yoshida-6")
    cold = iso.Composition(iso.IsoMP(initial_guess="state"), "yoshida-6")
    a = iso.solve(prob, cold, W0, dt=0.05, n_steps=100)
    b = iso.solve(prob, method, W0, dt=0.05, n_steps=100)
    assert float(np.max(np.abs(a.ys - b.ys))) <= 1e-13
    assert b.stats.iterations_mean < 0.8 * a.stats.iterations_mean  # measured 32 vs 51
    # the state: (m, k_1, *s_1, ..., k_m, *s_m); position i extrapolates its own offsets,
    # made with its own step g_i h
    y, state = W0, None
    for _ in range(3):
        res = method.step(prob, y, 0.05, state)
        y, state = res.y, res.state
    m = method.stages
    assert state[0] == m
    pos, seen = 1, []
    for g in method.coefficients:
        k = state[pos]
        sub = state[pos + 1 : pos + 1 + k]
        # (g h, D_k, D_{k-1}, D_{k-2}, E, 3): three offsets and the compensation E
        offsets, E = state_parts(sub, g * 0.05)
        assert sub[0] == g * 0.05 and len(offsets) == 3 and sub[-1] == 3
        assert all(isinstance(D, np.ndarray) and D.shape == W0.shape for D in (*offsets, E))
        seen.append(offsets[0])
        pos += 1 + k
    assert pos == len(state)
    # substeps of the same length at mirrored positions keep distinct histories
    assert float(np.max(np.abs(seen[0] - seen[-1]))) > 1e-6


def test_state_is_checkpointable_bit_for_bit() -> None:
    """The state survives the result file's codec, and continuing from it is bit for bit."""
    prob = random_problem("u3", seed=2, nonlinear=True)
    W0 = initial_state(prob.algebra, 3)
    method = iso.Composition(iso.IsoMP(), "suzuki-4")
    full = run_with(PythonRunner(prob, method, W0, 0.05), 10, 10)
    half = run_with(PythonRunner(prob, method, W0, 0.05), 10, 10, chunks=(5,))
    state = _unpack_state(*_pack_state(half.state))
    rest = run_with(PythonRunner(prob, method, half.y, 0.05, method_state=state, k=5), 10, 10,
                    chunks=(5,))  # fmt: skip
    assert np.array_equal(rest.y, full.y)


def test_ensemble_equals_separate_runs() -> None:
    prob = random_problem("so4", seed=13, nonlinear=True)
    W0s = prob.algebra.random(21, batch=(3, 2))
    W0s *= 0.6 / prob.algebra.norm(W0s)[..., None, None]
    W0s[1, 0] *= 2.0  # members converge at different speeds
    method = iso.Composition(iso.IsoMP(), "yoshida-6")
    sol = iso.solve(prob, method, W0s, dt=0.1, n_steps=30, save_every=10)
    assert sol.ys.shape == (4, 3, 2, 4, 4)
    for i in range(3):
        for j in range(2):
            single = iso.solve(prob, method, W0s[i, j], dt=0.1, n_steps=30, save_every=10)
            assert float(np.max(np.abs(single.ys - sol.ys[:, i, j]))) <= 1e-13


def test_failing_substep_fails_the_step() -> None:
    prob = random_problem("so4", seed=13, nonlinear=True)
    W0s = prob.algebra.random(21, batch=(3,))
    W0s *= 0.6 / prob.algebra.norm(W0s)[..., None, None]
    W0s[2] *= 50.0  # h ||B|| far too large for this member
    method = iso.Composition(iso.IsoMP(), "triple-jump-4")
    with pytest.raises(iso.ConvergenceError, match="IsoMP o triple-jump-4"):
        iso.solve(prob, method, W0s, dt=0.1, n_steps=5)
    sol = iso.solve(prob, method, W0s, dt=0.1, n_steps=5, throw=False)
    assert not sol.success and sol.status == RUN_FAILED and "1 of 3" in sol.message
    # the failed member is frozen at its initial state, the others take every step
    assert list(sol.failed_step) == [-1, -1, 0] and np.array_equal(sol.ys[-1, 2], W0s[2])
    # the step record: iterations summed over substeps, the failure code of the bad member,
    # and the good members took the whole composed step
    res = method.step(prob, W0s, 0.1)
    assert not res.success and res.status[2] != 0 and np.all(res.status[:2] == 0)
    singles = [method.step(prob, W0s[i], 0.1) for i in range(2)]
    assert np.array_equal(res.iterations[:2], [s.iterations for s in singles])
    for i in range(2):
        assert float(np.max(np.abs(res.y[i] - singles[i].y))) <= 1e-15
        assert res.iterations[i] >= 3  # one solve per substep at least
    # a single system
    with pytest.raises(iso.ConvergenceError):
        iso.step(prob, method, W0s[2], 0.1)


def test_registry_names() -> None:
    cfg = {"model": "rigid-body", "method": "isomp-kahan-li-8", "dt": 0.1, "t1": 1}
    _, _, method, _ = build(cfg)
    assert isinstance(method, iso.Composition) and method.order == 8
    cfg = {"model": "spin-chain", "method": "spherical-midpoint-suzuki-4", "dt": 0.1, "t1": 1}
    _, _, method, _ = build(cfg)
    assert method.name == "spherical midpoint o suzuki-4"
