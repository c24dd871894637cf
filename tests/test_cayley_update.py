"""IsoMP's Cayley update (``IsoMP(update="cayley")``): isospectral to rounding whatever the
stage tolerance, IsoMP itself at a tight one, second order, the same on the compiled and the
NumPy paths, and refused where it does not apply."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import isoflow as iso
from helpers import check_cayley_keeps_lengths, eigenvalue_drift
from isoflow import io
from isoflow.methods.isomp import cayley_increment
from isoflow.reference import reference_solution


def cayley(rtol: float = 1e-8, **kw: Any) -> iso.IsoMP:
    return iso.IsoMP(update="cayley", solver=iso.FixedPoint(rtol=rtol), **kw)


def _elementwise(alg: Any, seed: int = 0) -> tuple[Any, Any]:
    """``B = C o W`` with ``C`` symmetric (skew spaces) or antisymmetric (Hermitian ones)."""
    rng = np.random.default_rng(seed)
    n = alg.shape[0]
    A = rng.standard_normal((n, n))
    C = A - A.T if alg.name.startswith(("sym", "herm")) else A + A.T
    prob = iso.IsospectralProblem(algebra=alg, kernel=iso.ElementwiseLinear(C))
    return prob, alg.random(seed + 1)


@pytest.mark.parametrize(
    "make",
    [
        lambda: iso.models.rigid_body(n=6),  # so(6), compiled small dense (written out)
        lambda: iso.models.euler_sphere(N=24, seed=2),  # su(24), compiled BLAS tiles
        lambda: _elementwise(iso.algebras.herm(20)),  # Hermitian states, compiled tiles
        lambda: iso.models.toda(6, seed=3),  # sym(6), compiled small dense
        lambda: iso.models.toda(20, seed=3),  # sym(20), compiled real tiles
    ],
    ids=["so(6)", "su(24)", "herm(20)", "sym(6)", "sym(20)"],
)
def test_the_spectrum_stays_at_rounding_whatever_the_tolerance(make: Any) -> None:
    """At ``rtol = 1e-6`` the midpoint update moves the eigenvalues by the stage's residual
    (above 1e-9 here); the Cayley update keeps them to 1e-13 over 200 steps."""
    prob, y0 = make()
    h = float(0.3 / np.linalg.norm(prob.B(y0), 2))
    loose = iso.FixedPoint(rtol=1e-6)
    mid = iso.solve(prob, iso.IsoMP(solver=loose), y0, dt=h, n_steps=200, progress=False)
    cay = iso.solve(prob, cayley(1e-6), y0, dt=h, n_steps=200, progress=False)
    assert eigenvalue_drift(mid.ys) > 1e-9  # what the update is for
    assert eigenvalue_drift(cay.ys) < 1e-13
    # the same flow (over the first steps: some of these flows are chaotic)
    assert np.max(np.abs(cay.ys[:21] - mid.ys[:21])) < 1e-4 * np.max(np.abs(y0))


@pytest.mark.parametrize("compensated", [True, False])
def test_at_a_tight_tolerance_it_is_isomp(compensated: bool) -> None:
    """At the fixed point, ``C W C^H = W + h [B, X]``: the two updates agree to rounding."""
    for prob, y0 in (iso.models.euler_sphere(N=24, seed=2), iso.models.rigid_body(n=6)):
        h = float(0.3 / np.linalg.norm(prob.B(y0), 2))
        kw = dict(dt=h, n_steps=40, progress=False)
        mid = iso.solve(prob, iso.IsoMP(compensated=compensated), y0, **kw)
        cay = iso.solve(prob, cayley(1e-14, compensated=compensated), y0, **kw)
        assert np.max(np.abs(cay.ys - mid.ys)) <= 1e-12 * np.max(np.abs(y0))


def test_second_order_against_dop853() -> None:
    """Global error at ``t = 1`` of the so(4) rigid body against DOP853 (rtol 1e-13): fitted
    order within 0.15 of 2 with a stage tolerance of 1e-10."""
    prob, y0 = iso.models.rigid_body(n=4)
    ref = reference_solution(prob, y0, [1.0])[0]
    hs = np.array([0.1, 0.05, 0.025, 0.0125])
    errs = []
    for h in hs:
        sol = iso.solve(prob, cayley(1e-10), y0, dt=float(h), n_steps=round(1 / h),
                        progress=False)  # fmt: skip
        errs.append(np.max(np.abs(sol.ys[-1] - ref)))
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert abs(slope - 2.0) < 0.15, (slope, errs)


@pytest.mark.parametrize("N", [24, 130])  # complex tiles; real planes (N >= 128)
def test_the_compiled_finish_is_the_numpy_one(N: int) -> None:
    prob, y0 = iso.models.euler_sphere(N=N, seed=1)
    h = float(0.3 / np.linalg.norm(prob.B(y0), 2))
    kw = dict(dt=h, n_steps=12 if N > 100 else 40, progress=False)
    fast = iso.solve(prob, cayley(1e-8), y0, **kw)
    slow = iso.solve(dataclasses.replace(prob, kernel=None), cayley(1e-8), y0, **kw)
    assert "Cayley update" in fast.stats.runner and slow.stats.runner == "NumPy"
    # the same iterates; the finishes' solves round differently
    assert np.max(np.abs(fast.ys - slow.ys)) <= 1e-12 * np.max(np.abs(y0))
    assert fast.stats.iterations_mean == slow.stats.iterations_mean
    assert eigenvalue_drift(fast.ys) < 1e-13


def test_an_ensemble_and_a_composition_run_it() -> None:
    prob, y0 = iso.models.euler_sphere(N=20, seed=1)
    alg = prob.algebra
    ys = np.stack([alg.project(y0 + 1e-2 * alg.random(s)) for s in range(3)])
    h = float(0.3 / np.linalg.norm(prob.B(y0), 2))
    ens = iso.solve(prob, cayley(1e-8), ys, dt=h, n_steps=20, progress=False)
    for m in range(3):
        one = iso.solve(prob, cayley(1e-8), ys[m], dt=h, n_steps=20, progress=False)
        assert np.max(np.abs(ens.ys[:, m] - one.ys)) <= 1e-13 * np.max(np.abs(y0))
    comp = iso.solve(prob, iso.Composition(cayley(1e-8), "suzuki-4"), y0, dt=h, n_steps=20,
                     progress=False)  # fmt: skip
    assert "Cayley update" in comp.stats.runner
    assert eigenvalue_drift(comp.ys) < 1e-13


def test_the_default_solver_follows_the_update() -> None:
    assert iso.IsoMP(update="cayley").solver == iso.FixedPoint(rtol=1e-8)
    assert iso.IsoMP().solver == iso.FixedPoint()  # 1e-14, as before
    given = iso.FixedPoint(rtol=1e-12, anderson=2)
    assert iso.IsoMP(update="cayley", solver=given).solver is given


def test_bad_input_is_refused() -> None:
    with pytest.raises(iso.ParameterError, match="update must be one of 'midpoint', 'cayley'"):
        iso.IsoMP(update="exact")  # type: ignore[arg-type]
    for prob, y0 in (
        iso.models.hyperbolic_vortices(1),  # (R^3, x_L)^N particles
        (iso.IsospectralProblem(B=lambda W: W @ W, algebra=iso.algebras.gl(3)),
         iso.algebras.gl(3).random(0, scale=0.3)),
    ):  # fmt: skip
        with pytest.raises(iso.ParameterError, match=r"update='cayley'\) needs a dense matrix"):
            iso.solve(prob, cayley(), y0, dt=0.01, n_steps=2, progress=False)


def test_the_name_keeps_a_run_on_its_update(tmp_path: Path) -> None:
    assert cayley().name == "IsoMP (Cayley update)" and iso.IsoMP().name == "IsoMP"
    prob, y0 = iso.models.rigid_body(n=5)
    path = tmp_path / "mid.h5"
    iso.solve(prob, iso.IsoMP(), y0, dt=0.1, n_steps=8, progress=False,
              writer=io.HDF5Writer(path))  # fmt: skip
    with pytest.raises(iso.ResultFileError, match="the run used 'IsoMP', not 'IsoMP \\(Cayley"):
        io.resume(path, problem=prob, method=cayley(), progress=False)


@pytest.mark.parametrize("N", [24, 130])
def test_the_split_step_runs_it_compiled(N: int) -> None:
    """``Strang(IsoMP(update="cayley"))`` with a viscosity: the compiled split stage with the
    Cayley finish gives the NumPy path's states, and the flow of the midpoint split step."""
    prob, y0 = iso.models.euler_sphere(N=N, seed=1, viscosity=1e-3)
    h = float(0.3 / np.linalg.norm(prob.B(y0), 2))
    method = iso.Strang(cayley(1e-8))
    kw = dict(dt=h, n_steps=8 if N > 100 else 30, progress=False)
    fast = iso.solve(prob, method, y0, **kw)
    slow = iso.solve(dataclasses.replace(prob, kernel=None), method, y0, **kw)
    assert fast.stats.runner.endswith("Strang split, Cayley update"), fast.stats.runner
    assert slow.stats.runner == "NumPy"
    assert np.max(np.abs(fast.ys - slow.ys)) <= 1e-12 * np.max(np.abs(y0))
    plain = iso.solve(prob, iso.Strang(iso.IsoMP()), y0, **kw)  # the same flow
    assert np.max(np.abs(fast.ys - plain.ys)) <= 1e-6 * np.max(np.abs(y0))


def test_the_named_method_defaults_to_a_loose_tolerance() -> None:
    """``isomp-cayley`` in a configuration (the command line, sweeps): ``rtol = 1e-8`` unless
    given, recorded in the normalized configuration (so a resume rebuilds the same solver)."""
    from isoflow.registry import build, normalize_config

    cfg = {"model": "rigid-body", "method": "isomp-cayley", "dt": 0.1, "n_steps": 3}
    assert normalize_config(cfg)["rtol"] == 1e-8
    assert normalize_config(cfg | {"rtol": 1e-12})["rtol"] == 1e-12
    assert normalize_config(cfg | {"method": "isomp"})["rtol"] is None  # the solver's 1e-14
    _prob, _y0, method, _kw = build(cfg)
    assert method.name == "IsoMP (Cayley update)" and method.solver.rtol == 1e-8


def _spins() -> dict[str, Any]:
    return {
        "spin chain (fused)": iso.models.heisenberg_chain(200, initial="random", seed=1),
        "spin lattice (R^3, x)^N": iso.models.spin_lattice((10, 10), seed=2),
        "vortices on the sphere": iso.models.sphere_vortices(
            np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0.6, 0, 0.8]]),
            [1.0, 2.0, -0.5, 0.7],
        ),
    }


@pytest.mark.parametrize("name", list(_spins()))
def test_particles_keep_every_length_whatever_the_tolerance(name: str) -> None:
    """On (R^3, x)^N the Cayley factor is a rotation per particle: at ``rtol = 1e-6`` every
    ``|w_i|`` stays to 1e-14 over 200 steps while the midpoint update moves them by more than
    1e-10; at ``rtol = 1e-14`` it is the midpoint update to 1e-12; the compiled finish (the
    chain's fused sweeps, the particle blocks, the vortex layout) is the NumPy one."""
    prob, y0 = _spins()[name]
    check_cayley_keeps_lengths(prob, y0, iso.IsoMP, n_steps=200, n_short=40)


def _ensemble_of(prob: Any, y0: Any, M: int) -> Any:
    alg = prob.algebra
    return np.stack([alg.project(y0 + 1e-2 * alg.random(s)) for s in range(M)])


@pytest.mark.parametrize(
    ("make", "members", "kind"),
    [
        (lambda: iso.models.rigid_body(n=6), 0, "written-out products"),
        (lambda: iso.models.rigid_body(n=6), 20, "lanes"),
        (lambda: iso.models.toda(6, seed=3), 0, "written-out products"),
        (lambda: _elementwise(iso.algebras.herm(5)), 0, "written-out products"),
        (lambda: _elementwise(iso.algebras.su(4)), 11, "lanes"),
    ],
    ids=["so(6)", "so(6) lanes", "sym(6)", "herm(5)", "su(4) lanes"],
)
def test_the_small_dense_finish_is_the_numpy_one(make: Any, members: int, kind: str) -> None:
    """Small dense states (``n <= 16``, one member a unit or 16 as SIMD lanes): the written-out
    inverse and products of the compiled finish give the NumPy path's batched inverse's
    states to 1e-12, and the spectrum stays at rounding."""
    prob, y0 = make()
    if members:
        y0 = _ensemble_of(prob, y0, members)
    h = float(0.3 / np.max(np.linalg.norm(prob.B(y0), 2, axis=(-2, -1))))
    kw = dict(dt=h, n_steps=40, progress=False)
    fast = iso.solve(prob, cayley(1e-8), y0, **kw)
    slow = iso.solve(dataclasses.replace(prob, kernel=None), cayley(1e-8), y0, **kw)
    assert kind in fast.stats.runner and "Cayley update" in fast.stats.runner
    assert slow.stats.runner == "NumPy"
    assert np.max(np.abs(fast.ys - slow.ys)) <= 1e-12 * np.max(np.abs(y0))
    assert eigenvalue_drift(fast.ys) < 1e-13


@pytest.mark.parametrize(
    ("alg", "dtype"),
    [
        (iso.algebras.so(5), np.float64),
        (iso.algebras.so(6), np.float64),
        (iso.algebras.u(5), np.complex128),
    ],
    ids=["so(5)", "so(6)", "u(5)"],
)
def test_the_written_out_inverse_holds_at_any_step(alg: Any, dtype: Any) -> None:
    """The small layouts' Gauss–Jordan inverse (partial pivoting, lane by lane): its
    increment equals the NumPy path's (LAPACK's inverse) to 1e-12 relative, for
    ``||h/2 B||_2`` from 1e-2 to 1e3, three lanes at once (odd ``n`` included: without
    pivoting the entries grew like ``||h/2 B||^2`` and so(5) lost 5e-11 at 1e3)."""
    from isoflow._compiled.cayley_small import unit_increment

    rng = np.random.default_rng(4)
    for size in (1e-2, 1.0, 1e2, 1e3):
        Bs, Ws = [], []
        for _ in range(3):
            B = alg.random(int(rng.integers(1000)))
            Bs.append(B * (2 * size / np.linalg.norm(B, 2)))
            Ws.append(alg.random(int(rng.integers(1000))))
        B, W = np.stack(Bs), np.stack(Ws)
        ref = cayley_increment(alg, B, W, 1.0)
        lanes = lambda a: np.ascontiguousarray(np.moveaxis(a, 0, -1))  # noqa: E731
        D = np.empty_like(lanes(W))
        unit_increment(-1.0, lanes(B), lanes(W), 0.5, D, np.empty((4, *D.shape), dtype=dtype))
        got = np.moveaxis(D, -1, 0)
        assert np.max(np.abs(got - ref)) <= 1e-12 * max(1.0, np.max(np.abs(ref)))
