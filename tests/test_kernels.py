"""The kernel protocol: built-in fields equal their NumPy formulas and the models' B; checks."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import isoflow as iso
from isoflow.kernels import Kernel


def _model_cases():
    rng = np.random.default_rng(0)
    pos = rng.standard_normal((5, 3))
    pos /= np.linalg.norm(pos, axis=1, keepdims=True)
    sphere, x = iso.models.sphere_vortices(positions=pos, circulations=rng.uniform(0.5, 2, 5))
    hyper, w = iso.models.hyperbolic_vortices(config=2)
    N = np.diag([1.0, 2.0, 4.0, 3.0]) + 0.3 * np.ones((4, 4))
    return {
        "rigid body": iso.models.rigid_body(7),
        "toda": iso.models.toda(6),
        "brockett": iso.models.brockett(5),
        "brockett in a frame": iso.models.brockett(4, N=N),
        "spin chain": iso.models.heisenberg_chain(9, initial="random", seed=1),
        "damped spin chain": iso.models.heisenberg_chain(9, initial="random", seed=1, damping=0.3),
        "sphere vortices": (sphere, x),
        "hyperbolic vortices": (hyper, w),
    }


@pytest.mark.parametrize("name", list(_model_cases()))
def test_compiled_field_equals_numpy_formula_and_the_models_B(name: str) -> None:
    """The kernel's compiled ``f`` (through the generic member loop), its NumPy formula and the
    model's Python ``B`` agree on an ensemble of states."""
    prob, y0 = _model_cases()[name]
    alg = prob.algebra
    y = np.stack([y0, 0.7 * y0, 1.3 * y0])
    numpy_form = prob.kernel.evaluate(y, alg)
    compiled = Kernel.evaluate(prob.kernel, y, alg)
    scale = float(np.max(np.abs(numpy_form)))
    # the hyperbolic configuration 2 has a close pair: its pair factor 1/((D-1)(D+1)) loses a
    # few digits, differently in the two orders of summation
    tol = 1e-13 if name == "hyperbolic vortices" else 1e-14
    assert np.max(np.abs(compiled - numpy_form)) <= tol * scale
    assert np.max(np.abs(prob.B(y) - numpy_form)) <= tol * scale
    prob.check_B(y)


def test_builtin_kernels_validate_their_parameters() -> None:
    with pytest.raises(iso.ParameterError, match="geometry"):
        iso.PairwiseVortex([1.0, 2.0], "torus")  # type: ignore[arg-type]
    with pytest.raises(iso.ParameterError, match="shape"):
        iso.PairwiseVortex(np.ones((2, 2)), "sphere")
    with pytest.raises(iso.ParameterError, match="shape"):
        iso.PairwiseVortex([], "sphere")
    with pytest.raises(iso.ParameterError, match="finite"):
        iso.PairwiseVortex([1.0, np.nan], "sphere")
    with pytest.raises(iso.ParameterError, match="real"):
        iso.PairwiseVortex([1.0 + 1j, 2.0], "hyperbolic")
    k = iso.PairwiseVortex([1, 2, 3], "sphere")
    assert k.circulations.dtype == np.float64 and k.N == 3 and not k.circulations.flags.writeable
    assert k.coefficient == 1.0 / (4.0 * np.pi)
    with pytest.raises(iso.ShapeError, match="shape"):
        k.evaluate(np.ones((4, 3)))
    with pytest.raises(iso.ParameterError, match="square"):
        iso.ElementwiseLinear(np.ones((2, 3)))
    with pytest.raises(iso.ParameterError, match="non-finite"):
        iso.ElementwiseLinear(np.full((2, 2), np.inf))
    with pytest.raises(iso.ParameterError, match="unitary"):
        iso.ElementwiseLinear(np.ones((2, 2)), frame=np.ones((2, 2)))
    with pytest.raises(iso.ParameterError, match="coupling"):
        iso.SpinNeighbourSum("strong")  # type: ignore[arg-type]
    for bad in (-0.1, np.nan, np.inf, True, "0.1"):
        with pytest.raises(iso.ParameterError, match="damping"):
            iso.SpinNeighbourSum(-1.0, damping=bad)  # type: ignore[arg-type]


def test_the_damped_neighbour_sum_is_the_llg_field() -> None:
    """``SpinNeighbourSum(c, damping=lam)``: ``h_i + lam w_i x h_i`` with ``h_i = c (w_{i-1} +
    w_{i+1})``, written out here per spin; zero damping is the plain sum."""
    rng = np.random.default_rng(3)
    W = rng.standard_normal((2, 7, 3))
    h = -0.7 * (np.roll(W, 1, axis=-2) + np.roll(W, -1, axis=-2))
    want = np.empty_like(h)
    for m in range(2):
        for i in range(7):
            s0, s1, s2 = W[m, i]
            h0, h1, h2 = h[m, i]
            cross = np.array([s1 * h2 - s2 * h1, s2 * h0 - s0 * h2, s0 * h1 - s1 * h0])
            want[m, i] = h[m, i] + 0.25 * cross
    alg = iso.algebras.so3_vectors(7)
    damped = iso.SpinNeighbourSum(-0.7, damping=0.25)
    assert np.max(np.abs(damped.evaluate(W) - want)) < 1e-15
    assert np.max(np.abs(Kernel.evaluate(damped, W, alg) - want)) < 1e-15
    plain = iso.SpinNeighbourSum(-0.7)
    assert np.array_equal(plain.evaluate(W), h)
    assert iso.SpinNeighbourSum(-0.7, damping=0).field() == plain.field()


def test_a_kernel_must_fit_its_space() -> None:
    """Wrong space or size: rejected when the problem is built, naming both."""
    prob, _ = _model_cases()["sphere vortices"]
    G = prob.kernel.circulations
    for wrong, match in (
        (iso.PairwiseVortex(G, "hyperbolic"), "describes B on"),
        (iso.PairwiseVortex(G[:3], "sphere"), "circulations for"),
    ):
        with pytest.raises(iso.InvalidBError, match=match):
            dataclasses.replace(prob, kernel=wrong)
    rb, _ = iso.models.rigid_body(4)
    with pytest.raises(iso.InvalidBError, match="coeff has shape"):
        dataclasses.replace(rb, kernel=iso.ElementwiseLinear(np.ones((5, 5))))
    with pytest.raises(iso.InvalidBError, match="not on sp"):
        iso.IsospectralProblem(
            algebra=iso.algebras.sp(4), kernel=iso.ElementwiseLinear(np.ones((4, 4)))
        )
    with pytest.raises(TypeError, match="isoflow kernel"):
        dataclasses.replace(rb, kernel="fast")


def test_a_kernel_that_is_not_the_problems_B_is_rejected_at_the_start() -> None:
    prob, x0 = _model_cases()["sphere vortices"]
    bad = dataclasses.replace(
        prob, kernel=iso.PairwiseVortex(2.0 * prob.kernel.circulations, "sphere")
    )
    with pytest.raises(iso.InvalidBError, match="does not describe its B"):
        iso.solve(bad, iso.IsoMP(), x0, dt=0.01, n_steps=2)


def test_problem_needs_B_or_kernel() -> None:
    with pytest.raises(TypeError, match="give B, or a kernel"):
        iso.IsospectralProblem(algebra=iso.algebras.so(3))


def test_an_object_mode_function_is_refused_with_what_to_write() -> None:
    import numba

    from isoflow._kernel_fields import field_type

    @numba.jit(forceobj=True)
    def object_mode_field(W, out, C):  # type: ignore[no-untyped-def]
        out[:, :] = -C * W

    C = np.ones((3, 3))
    with pytest.raises(iso.InvalidBError, match=r"CompiledB needs a nopython function, and "
                       r"object_mode_field is compiled in object mode .*@numba\.njit"):  # fmt: skip
        iso.CompiledB(object_mode_field, (C,))
    # the compiled loops' own check, for a dispatcher that says nothing about its mode
    with pytest.raises(iso.InvalidBError, match=r"object_mode_field compiled in object mode; "
                       r"compiled loops call only nopython functions"):  # fmt: skip
        field_type(object_mode_field, (C,), np.float64, np.float64)
