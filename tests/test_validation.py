"""Bad input gets a typed exception that names the problem."""

from __future__ import annotations

import re

import numpy as np
import pytest

import isoflow as iso
from helpers import initial_state

D3 = np.array([[1.0, 1.5, 2.0], [1.5, 2.0, 2.5], [2.0, 2.5, 3.0]])  # rigid-body weights


@pytest.fixture
def so3_problem() -> iso.IsospectralProblem:
    return iso.IsospectralProblem(B=lambda W: -D3 * W, algebra=iso.algebras.so(3))


@pytest.fixture
def W0() -> np.ndarray:
    return initial_state(iso.algebras.so(3), 1)


def _solve(prob, y0, **kw):
    kw.setdefault("dt", 0.1)
    kw.setdefault("t1", 1.0)
    return iso.solve(prob, iso.IsoMP(), y0, **kw)


def test_wrong_shape(so3_problem) -> None:
    with pytest.raises(iso.ShapeError, match=r"shape \(\*batch, 3, 3\).*got \(3, 4\)"):
        _solve(so3_problem, np.zeros((3, 4)))
    with pytest.raises(ValueError, match="shape"):  # also a ValueError
        _solve(so3_problem, np.zeros(3))


def test_wrong_dtype(so3_problem, W0) -> None:
    with pytest.raises(iso.DtypeError, match=r"complex.*real space"):
        _solve(so3_problem, W0 + 0j)
    with pytest.raises(TypeError, match="numeric"):
        _solve(so3_problem, np.array([["a"] * 3] * 3))


def test_integer_input_is_converted(so3_problem) -> None:
    W = np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 0]])
    sol = _solve(so3_problem, W)
    assert sol.ys.dtype == np.float64


def test_state_not_in_space_reports_distance(so3_problem, W0) -> None:
    bad = W0 + 0.01 * np.eye(3)
    with pytest.raises(iso.NotInSpaceError, match=r"not in so\(3\): distance 1\.73\de-02") as info:
        _solve(so3_problem, bad)
    assert info.value.distance == pytest.approx(0.01 * np.sqrt(3))


def test_rounding_level_asymmetry_is_accepted_and_projected(so3_problem, W0) -> None:
    noisy = W0 + 1e-14 * np.arange(9.0).reshape(3, 3)
    sol = _solve(so3_problem, noisy)
    assert np.array_equal(sol.ys[0], -sol.ys[0].T)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_state(so3_problem, W0, bad) -> None:
    W = W0.copy()
    W[0, 1], W[1, 0] = bad, -bad
    with pytest.raises(iso.NonFiniteError, match="finite"):
        _solve(so3_problem, W)


@pytest.mark.parametrize("dt", [0.0, -0.1, np.nan, np.inf])
def test_bad_step(so3_problem, W0, dt) -> None:
    with pytest.raises(iso.StepSizeError, match="dt must be positive and finite"):
        _solve(so3_problem, W0, dt=dt)


def test_step_rejects_zero_h(so3_problem, W0) -> None:
    with pytest.raises(iso.StepSizeError, match="nonzero"):
        iso.step(so3_problem, iso.IsoMP(), W0, 0.0)


def test_reversed_time_span(so3_problem, W0) -> None:
    with pytest.raises(iso.TimeSpanError, match="before t0"):
        _solve(so3_problem, W0, t0=1.0, t1=0.5)


def test_t1_not_a_whole_number_of_steps(so3_problem, W0) -> None:
    with pytest.raises(iso.StepSizeError, match=r"not a whole number of steps.*choose dt"):
        _solve(so3_problem, W0, dt=0.3, t1=1.0)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"t1": 0.0, "n_steps": 4}, iso.TimeSpanError, r"empty \(t1 == t0 = 0.0\): 4 steps"),
        ({"t1": 1.0, "dt": 1e-300}, iso.StepSizeError, "below the resolution .* near 1 are"),
        ({"t1": 1.0, "n_steps": 10**20}, iso.StepSizeError, "dt = 1e-20 is below the resolution"),
        ({"dt": 0.1, "n_steps": 10**30}, iso.StepSizeError, "below the resolution"),
        ({"t0": 1e16, "dt": 1.0, "n_steps": 4}, iso.StepSizeError, r"near 1e\+16 are 2 apart"),
        ({"t0": 1e308, "dt": 1e300, "n_steps": 10**9}, iso.StepSizeError, "not a finite time"),
        ({"dt": 1.0, "n_steps": 10**14}, iso.ParameterError,
         r"hold 10000000000000[12] saved states of shape \(3, 3\) in memory \(7.2e\+15 bytes\)"),
    ],
)  # fmt: skip
def test_time_grids_a_run_cannot_hold_are_refused_before_it_starts(
    so3_problem, W0, kwargs, error, match
) -> None:
    """An empty span, times that floats cannot tell apart (the saved times would repeat while
    the states advance), a grid whose saved states do not fit in memory: a typed error, not a
    run of steps of ``dt = 0``, wrong times or an allocation failure from NumPy."""
    with pytest.raises(error, match=match):
        iso.solve(so3_problem, iso.IsoMP(), W0, progress=False, **kwargs)
    sol = iso.solve(so3_problem, iso.IsoMP(), W0, t0=1e15, dt=1.0, n_steps=4, progress=False)
    assert np.array_equal(sol.ts, 1e15 + np.arange(5.0))  # 0.125 apart there: resolvable


def test_time_arguments_must_be_two_of_three(so3_problem, W0) -> None:
    with pytest.raises(ValueError, match="exactly two of t1, dt and n_steps"):
        iso.solve(so3_problem, iso.IsoMP(), W0, dt=0.1, t1=1.0, n_steps=10)
    with pytest.raises(ValueError, match="exactly two"):
        iso.solve(so3_problem, iso.IsoMP(), W0, dt=0.1)
    with pytest.raises(iso.StepSizeError, match="n_steps"):
        iso.solve(so3_problem, iso.IsoMP(), W0, dt=0.1, n_steps=2.5)
    with pytest.raises(ValueError, match="save_every"):
        iso.solve(so3_problem, iso.IsoMP(), W0, dt=0.1, n_steps=3, save_every=0)


def test_B_wrong_shape(W0) -> None:
    prob = iso.IsospectralProblem(B=lambda W: W[..., :2, :2], algebra=iso.algebras.so(3))
    with pytest.raises(iso.InvalidBError, match=r"B returned shape \(2, 2\), expected \(3, 3\)"):
        _solve(prob, W0)


@pytest.mark.parametrize(
    ("members", "what"),
    [
        (2, r"fails on the ensemble \(InvalidBError: B returned shape \(3, 3, 2\)"),
        (3, r"gives other values for its first member than for that state alone"),  # was silent
    ],
)
def test_B_that_does_not_broadcast_says_what_to_write(members: int, what: str) -> None:
    alg = iso.algebras.so(3)
    ensemble = np.stack([alg.random(k) for k in range(members)])

    def B(W):  # W / 2 for one skew state; W.T reverses every axis of a stack
        return -0.5 * W.T

    prob = iso.IsospectralProblem(B=B, algebra=alg)
    with pytest.raises(iso.InvalidBError, match=r"B works on one state but " + what) as err:
        _solve(prob, ensemble)
    msg = str(err.value)
    assert "np.swapaxes(W, -1, -2)" in msg and "vectorized=False" in msg and "\n" not in msg
    per_member = iso.IsospectralProblem(B=B, algebra=alg, vectorized=False)
    fixed = iso.IsospectralProblem(B=lambda W: -0.5 * np.swapaxes(W, -1, -2), algebra=alg)
    assert _solve(per_member, ensemble).ys.tobytes() == _solve(fixed, ensemble).ys.tobytes()


def test_B_outside_normalizer(W0) -> None:
    prob = iso.IsospectralProblem(B=lambda W: W @ W, algebra=iso.algebras.so(3))  # symmetric
    with pytest.raises(iso.InvalidBError, match=r"not in the normalizer so\(3\).*distance"):
        _solve(prob, W0)
    herm = iso.algebras.herm(2)
    prob = iso.IsospectralProblem(B=lambda W: W, algebra=herm)  # Hermitian, not in u(2)
    with pytest.raises(iso.InvalidBError, match=r"normalizer u\(2\)"):
        _solve(prob, herm.random(0))


def test_B_non_finite_or_complex(W0) -> None:
    prob = iso.IsospectralProblem(B=lambda W: W * np.nan, algebra=iso.algebras.so(3))
    with pytest.raises(iso.InvalidBError, match="non-finite"):
        _solve(prob, W0)
    prob = iso.IsospectralProblem(B=lambda W: W + 0j, algebra=iso.algebras.so(3))
    with pytest.raises(iso.InvalidBError, match="complex"):
        _solve(prob, W0)


def test_B_raising_is_wrapped_with_cause(W0) -> None:
    def B(W):
        raise KeyError("oops")

    prob = iso.IsospectralProblem(B=B, algebra=iso.algebras.so(3))
    with pytest.raises(iso.InvalidBError, match="B raised KeyError") as info:
        _solve(prob, W0)
    assert isinstance(info.value.__cause__, KeyError)


def test_B_going_nan_mid_run_is_reported(W0) -> None:
    calls = {"n": 0}

    def B(W):
        calls["n"] += 1
        return -D3 * W if calls["n"] < 20 else W * np.nan

    prob = iso.IsospectralProblem(B=B, algebra=iso.algebras.so(3))
    with pytest.raises(iso.ConvergenceError, match="non_finite") as info:
        _solve(prob, W0)
    assert info.value.reason == "non_finite" and info.value.step > 0


def test_problem_construction_checks_types() -> None:
    with pytest.raises(TypeError, match="callable"):
        iso.IsospectralProblem(B=3, algebra=iso.algebras.so(3))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="Algebra"):
        iso.IsospectralProblem(B=lambda W: W, algebra="so3")  # type: ignore[arg-type]


def test_all_errors_share_the_base_class() -> None:
    for cls in (
        iso.ShapeError,
        iso.DtypeError,
        iso.NonFiniteError,
        iso.NotInSpaceError,
        iso.InvalidBError,
        iso.StepSizeError,
        iso.TimeSpanError,
        iso.ConvergenceError,
    ):
        assert issubclass(cls, iso.IsoflowError)


def _changing_B(after: int, change):
    """A ``B`` that behaves (``-W``) for ``after`` calls and then returns ``change(W)``."""
    calls = {"n": 0}

    def B(W):
        calls["n"] += 1
        return -D3 * W if calls["n"] <= after else change(W)

    return B


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda W: -W + 1e-3j, "complex values"),
        (lambda W: -W[..., :2, :], "returned shape"),
        (lambda W: np.array("text"), "returned shape|non-numeric"),
    ],
    ids=["turns complex", "changes shape", "returns text"],
)
def test_B_that_changes_mid_run_stops_the_run_clearly(W0, change, match) -> None:
    """Mid-run: a clear typed error with throw=True; with throw=False the run so far is kept
    and the message names the problem (never a silent wrong answer)."""
    alg = iso.algebras.so(3)
    prob = iso.IsospectralProblem(B=_changing_B(40, change), algebra=alg)
    with pytest.raises(iso.IsoflowError, match=match):
        iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=50)
    prob = iso.IsospectralProblem(B=_changing_B(40, change), algebra=alg)
    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=50, throw=False)
    assert not sol.success and re.search(match, sol.message)
    assert 0 < sol.stats.n_steps < 50 and np.all(np.isfinite(sol.ys))
    assert sol.ts[-1] == pytest.approx(sol.stats.n_steps * 0.1)  # the last good state is kept


def test_B_that_raises_mid_run_keeps_the_run_so_far(W0) -> None:
    def boom(W):
        raise RuntimeError("the model broke")

    prob = iso.IsospectralProblem(B=_changing_B(30, boom), algebra=iso.algebras.so(3))
    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=50, throw=False)
    assert not sol.success and "the model broke" in sol.message
    assert 0 < sol.stats.n_steps < 50


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"problem": None}, iso.ArgumentTypeError, "IsospectralProblem"),
        ({"method": iso.IsoMP}, iso.ArgumentTypeError, r"iso.IsoMP\(\), not"),
        ({"method": "isomp"}, iso.ArgumentTypeError, "isoflow method"),
        ({"writer": "file.h5"}, iso.ArgumentTypeError, "HDF5Writer"),
        ({"diagnostics": "no"}, iso.ParameterError, "diagnostics must be True or False"),
        ({"y0": np.zeros((0, 3, 3))}, iso.ShapeError, "empty ensemble"),
        ({"save_every": 0}, iso.ParameterError, "save_every"),
        ({"save_every": 2.5}, iso.ParameterError, "save_every"),
        ({"progress": "x"}, iso.ParameterError, "progress must be True, False or None, got 'x'"),
        ({"throw": "no"}, iso.ParameterError, "throw must be True or False, got 'no'"),
    ],
)
def test_wrong_kinds_of_argument_get_typed_errors(so3_problem, W0, kwargs, error, match) -> None:
    args = {"problem": so3_problem, "method": iso.IsoMP(), "y0": W0, **kwargs}
    rest = {k: v for k, v in kwargs.items() if k not in ("problem", "method", "y0")}
    with pytest.raises(error, match=match) as err:
        iso.solve(args["problem"], args["method"], args["y0"], dt=0.1, n_steps=2, **rest)
    assert isinstance(err.value, iso.IsoflowError)  # every error raised on purpose
    if error is iso.ArgumentTypeError:
        assert isinstance(err.value, TypeError)  # and what `except TypeError` expects


def test_problems_and_compiled_fields_of_the_wrong_kind_are_argument_type_errors() -> None:
    alg = iso.algebras.so(3)
    for make in (
        lambda: iso.IsospectralProblem(B=lambda W: -W, algebra="so3"),
        lambda: iso.IsospectralProblem(algebra=alg),
        lambda: iso.IsospectralProblem(B=3.0, algebra=alg),
        lambda: iso.CompiledB(lambda W, out: None),
    ):
        with pytest.raises(iso.ArgumentTypeError):
            make()
    with pytest.raises(iso.ParameterError, match="config must be a mapping"):
        iso.io.HDF5Writer("never.h5", "cfg")  # type: ignore[arg-type]


def test_hamiltonian_returning_nonsense_is_named(W0) -> None:
    prob = iso.IsospectralProblem(
        B=lambda W: -W, algebra=iso.algebras.so(3), hamiltonian=lambda W: "energy"
    )
    with pytest.raises(iso.InvalidBError, match="hamiltonian returned non-numeric"):
        iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=2)


@pytest.mark.parametrize(
    ("make", "what"),
    [
        (lambda seed: iso.algebras.so(3).random(seed), "so(3).random: seed"),
        (lambda seed: iso.models.brockett(n=3, seed=seed), "brockett: seed"),
        (lambda seed: iso.models.toda(n=3, seed=seed), "toda: seed"),
        (lambda seed: iso.models.heisenberg_chain(N=4, initial="random", seed=seed),
         "heisenberg_chain: seed"),
        (lambda seed: iso.models.spin_lattice(shape=(3, 3), seed=seed), "spin_lattice: seed"),
        (lambda seed: iso.sphere.random_coefficients(3, seed=seed), "random_coefficients: seed"),
    ],
)  # fmt: skip
@pytest.mark.parametrize("seed", [-1, 1.5, "1", True, [1, -2]])
def test_bad_seeds_are_parameter_errors(make, what: str, seed) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(iso.ParameterError, match=rf"^{re.escape(what)} must be an integer >= 0"):
        make(seed)


def test_a_generator_gives_the_numbers_of_its_seed() -> None:
    alg = iso.algebras.so(4)
    assert alg.random(np.random.default_rng(7)).tobytes() == alg.random(7).tobytes()
    _, W7 = iso.models.brockett(n=4, seed=7)
    _, Wg = iso.models.brockett(n=4, seed=np.random.default_rng(7))
    assert W7.tobytes() == Wg.tobytes()


def test_states_too_large_for_memory_are_parameter_errors() -> None:
    """Sizes no machine here holds are refused with a ParameterError naming the estimate,
    before numpy tries (and fails, or swaps) to allocate them."""
    with pytest.raises(iso.ParameterError, match=r"so\(10\)\.random: batch \(1000000000,\)"):
        iso.algebras.so(10).random(seed=0, batch=(10**9,))
    with pytest.raises(iso.ParameterError, match=r"the basis of so\(1000000\) needs about"):
        iso.algebras.so(10**6).random(0)
    prob, y0 = iso.models.rigid_body(5)
    huge = np.broadcast_to(y0, (10**9, 5, 5))  # a view: no memory until it is copied
    with pytest.raises(iso.ParameterError, match=r"the y0 \(an ensemble of shape"):
        iso.solve(prob, iso.IsoMP(), huge, dt=0.1, n_steps=2)


@pytest.mark.parametrize("batch", [(), (3,)], ids=["one system", "ensemble"])
def test_an_explicit_method_whose_state_turns_nan_raises_convergence_error(batch) -> None:  # type: ignore[no-untyped-def]
    """One exception type for one failure, whatever the ensemble: ConvergenceError with the
    reason "non_finite" (an ensemble used to raise NonFiniteError)."""
    alg = iso.algebras.so(5)
    calls = [0]

    def B(W):  # type: ignore[no-untyped-def]
        calls[0] += 1
        return -W * (np.nan if calls[0] > 40 else 1.0)

    prob = iso.IsospectralProblem(B=B, algebra=alg)
    y0 = alg.random(seed=0, batch=batch)
    with pytest.raises(iso.ConvergenceError) as err:
        iso.solve(prob, iso.RK4(), y0, dt=0.1, n_steps=100, progress=False)
    assert err.value.reason == "non_finite" and 0 < err.value.step < 10  # 4 calls a step
