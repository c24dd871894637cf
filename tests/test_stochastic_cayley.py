"""The stochastic midpoint's Cayley update (``StochasticIsoMP(update="cayley")``): every path's
spectrum at rounding whatever the stage tolerance, the midpoint update itself at a tight one,
strong order 1/2, the same on the compiled and the NumPy paths, and refused where it does not
apply."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import isoflow as iso
from helpers import check_cayley_keeps_lengths, eigenvalue_drift
from isoflow import io


def cayley(rtol: float = 1e-8, **kw: Any) -> iso.StochasticIsoMP:
    return iso.StochasticIsoMP(update="cayley", solver=iso.FixedPoint(rtol=rtol), **kw)


def _h(prob: Any, y0: Any) -> float:
    return float(0.3 / np.linalg.norm(prob.B(y0), 2))


CASES = {
    "so(6) small dense": lambda: iso.models.rigid_body(6, noise=0.2, noise_seed=3),
    "su(24) BLAS tiles": lambda: iso.models.euler_sphere(24, seed=1, noise=0.02, noise_seed=3),
}


@pytest.mark.parametrize("make", CASES.values(), ids=CASES.keys())
def test_every_paths_spectrum_stays_at_rounding_whatever_the_tolerance(make: Any) -> None:
    """At ``rtol = 1e-6`` the midpoint update moves the eigenvalues by the stage's residual
    (above 1e-9 here); the Cayley update keeps them to 1e-13 over 100 noisy steps."""
    prob, y0 = make()
    kw = dict(dt=_h(prob, y0), n_steps=100, progress=False)
    loose = iso.FixedPoint(rtol=1e-6)
    mid = iso.solve(prob, iso.StochasticIsoMP(solver=loose), y0, **kw)
    cay = iso.solve(prob, cayley(1e-6), y0, **kw)
    assert eigenvalue_drift(mid.ys) > 1e-9  # what the update is for
    assert eigenvalue_drift(cay.ys) < 1e-13
    assert np.max(np.abs(cay.ys[-1] - y0)) > 1e-2 * np.max(np.abs(y0))  # the noise moved it
    # the same path (over the first steps: the loose midpoint run wanders off the spectrum)
    assert np.max(np.abs(cay.ys[:11] - mid.ys[:11])) < 1e-4 * np.max(np.abs(y0))


@pytest.mark.parametrize("make", CASES.values(), ids=CASES.keys())
def test_at_a_tight_tolerance_it_is_the_midpoint_update(make: Any) -> None:
    """At the fixed point ``C W C^H = W + [B~, X]``: the updates agree to rounding on the
    same increments."""
    prob, y0 = make()
    kw = dict(dt=_h(prob, y0), n_steps=30, progress=False)
    mid = iso.solve(prob, iso.StochasticIsoMP(), y0, **kw)
    cay = iso.solve(prob, cayley(1e-14), y0, **kw)
    assert np.max(np.abs(cay.ys - mid.ys)) <= 1e-12 * np.max(np.abs(y0))


@pytest.mark.parametrize("N", [24, 130])  # complex tiles; real planes (N >= 128)
def test_the_compiled_finish_is_the_numpy_one(N: int) -> None:
    prob, y0 = iso.models.euler_sphere(N, seed=1, noise=0.01, noise_seed=3)
    kw = dict(dt=_h(prob, y0), n_steps=6 if N > 100 else 30, progress=False)
    fast = iso.solve(prob, cayley(), y0, **kw)
    slow = iso.solve(dataclasses.replace(prob, kernel=None), cayley(), y0, **kw)
    assert fast.stats.runner.endswith("stochastic IsoMP, Cayley update"), fast.stats.runner
    assert slow.stats.runner == "NumPy"
    assert np.max(np.abs(fast.ys - slow.ys)) <= 1e-12 * np.max(np.abs(y0))
    assert fast.stats.iterations_mean == slow.stats.iterations_mean
    assert eigenvalue_drift(fast.ys) < 1e-13


def test_each_member_of_an_ensemble_takes_its_own_path() -> None:
    prob, y0 = iso.models.euler_sphere(20, seed=1, noise=0.02, noise_seed=5)
    ys = np.stack([y0] * 3)
    kw = dict(dt=_h(prob, y0), n_steps=20, progress=False)
    ens = iso.solve(prob, cayley(), ys, **kw)
    assert "Cayley update" in ens.stats.runner
    one = iso.solve(prob, cayley(), y0, **kw)  # member 0's increments
    assert np.max(np.abs(ens.ys[:, 0] - one.ys)) <= 1e-13 * np.max(np.abs(y0))
    assert np.max(np.abs(ens.ys[-1, 1] - ens.ys[-1, 0])) > 1e-3 * np.max(np.abs(y0))
    assert eigenvalue_drift(ens.ys) < 1e-13


@pytest.mark.slow
def test_strong_order_one_half_on_the_fine_brownian_paths() -> None:
    """The stochastic rigid body on so(3) (three non-commuting fields of amplitude 1), 2000
    paths (seed 1) to ``T = 1``, Gaussian increments, each coarse step on the fine path
    (``substeps``, as ``tests/test_noise_orders.py``): the root-mean-square error's fitted
    slope over ``h = 2^-3 .. 2^-6`` against the fine run (``h = 2^-8``) within 0.15 of 1/2."""
    fine, M = 2**8, 2000
    prob, W0 = iso.models.rigid_body(3, noise=1.0, noise_seed=1)
    Y0 = np.stack([W0] * M)

    def final(j: int) -> np.ndarray:
        method = cayley(1e-8, truncation=None, substeps=fine // 2**j)
        sol = iso.solve(prob, method, Y0, dt=2.0**-j, n_steps=2**j, save_every=2**j,
                        diagnostics=False, progress=False)  # fmt: skip
        return sol.ys[-1]

    ref = final(8)
    hs = 2.0 ** -np.arange(3, 7)
    strong = [np.sqrt(np.mean(np.sum((final(j) - ref) ** 2, axis=(1, 2)))) for j in range(3, 7)]
    slope = np.polyfit(np.log(hs - 1.0 / fine), np.log(strong), 1)[0]
    assert abs(slope - 0.5) < 0.15, (slope, strong)


def test_the_default_solver_and_the_name_follow_the_update(tmp_path: Path) -> None:
    assert iso.StochasticIsoMP(update="cayley").solver == iso.FixedPoint(rtol=1e-8)
    assert iso.StochasticIsoMP().solver == iso.FixedPoint()  # 1e-14, as before
    given = iso.FixedPoint(rtol=1e-12, anderson=2)
    assert iso.StochasticIsoMP(update="cayley", solver=given).solver is given
    assert cayley().name == "stochastic IsoMP (Cayley update)"
    assert iso.StochasticIsoMP().name == "stochastic IsoMP"
    prob, y0 = iso.models.rigid_body(4, noise=0.2, noise_seed=1)
    path = tmp_path / "mid.h5"
    iso.solve(prob, iso.StochasticIsoMP(), y0, dt=0.05, n_steps=6, progress=False,
              writer=io.HDF5Writer(path))  # fmt: skip
    with pytest.raises(iso.ResultFileError, match="not 'stochastic IsoMP \\(Cayley update\\)'"):
        io.resume(path, problem=prob, method=cayley(), progress=False)


def test_bad_input_is_refused() -> None:
    with pytest.raises(iso.ParameterError, match="update must be one of 'midpoint', 'cayley'"):
        iso.StochasticIsoMP(update="exact")  # type: ignore[arg-type]
    prob, W0 = iso.models.rigid_body(4, noise=0.2, noise_seed=1)
    gl = iso.IsospectralProblem(B=lambda W: W @ W, algebra=iso.algebras.gl(4), noise=prob.noise)
    with pytest.raises(
        iso.ParameterError, match=r"^StochasticIsoMP\(update='cayley'\) needs a dense matrix"
    ):
        iso.solve(gl, cayley(), 0.1 * W0, dt=0.01, n_steps=2, progress=False)


def test_the_named_method_defaults_to_a_loose_tolerance() -> None:
    """``stochastic-isomp-cayley`` in a configuration (the command line, sweeps): ``rtol =
    1e-8`` unless given, recorded in the normalized configuration."""
    from isoflow.registry import build, normalize_config

    cfg = {"model": "rigid-body", "method": "stochastic-isomp-cayley", "dt": 0.1, "n_steps": 3,
           "params": {"noise": 0.2, "noise_seed": 1}}  # fmt: skip
    assert normalize_config(cfg)["rtol"] == 1e-8
    assert normalize_config(cfg | {"rtol": 1e-12})["rtol"] == 1e-12
    _prob, _y0, method, _kw = build(cfg)
    assert method.name == "stochastic IsoMP (Cayley update)" and method.solver.rtol == 1e-8


@pytest.mark.parametrize(
    "make",
    [
        lambda: iso.models.heisenberg_chain(
            100, initial="random", seed=1, temperature=0.5, damping=0.1, noise_seed=2
        ),
        lambda: iso.models.spin_lattice((8, 8), seed=2, temperature=0.5, damping=0.1, noise_seed=3),
    ],
    ids=["thermal chain", "thermal lattice"],
)
def test_thermal_spins_keep_every_length_whatever_the_tolerance(make: Any) -> None:
    """Spins at finite temperature (stochastic LLG): with the Cayley update every ``|S_i|``
    stays to 1e-14 at ``rtol = 1e-6`` (the midpoint update: more than 1e-10 off), the
    midpoint's paths at ``rtol = 1e-14``, and the compiled finish is the NumPy one."""
    prob, y0 = make()
    check_cayley_keeps_lengths(prob, y0, iso.StochasticIsoMP, n_steps=100, n_short=30)


def test_an_ensemble_of_small_members_runs_it_on_the_lanes() -> None:
    """The stochastic rigid body on so(4), 20 members (16 as SIMD lanes and a partial unit):
    the compiled finish gives the NumPy path's states to 1e-12, every spectrum at rounding."""
    prob, W0 = iso.models.rigid_body(4, noise=0.3, noise_seed=2)
    Y0 = np.stack([W0 + 0.01 * k * prob.algebra.random(k) for k in range(20)])
    kw = dict(dt=0.02, n_steps=40, progress=False)
    fast = iso.solve(prob, cayley(), Y0, **kw)
    slow = iso.solve(dataclasses.replace(prob, kernel=None), cayley(), Y0, **kw)
    assert "lanes" in fast.stats.runner and "Cayley update" in fast.stats.runner
    assert slow.stats.runner == "NumPy"
    assert np.max(np.abs(fast.ys - slow.ys)) <= 1e-12
    assert eigenvalue_drift(fast.ys) < 1e-13
    assert np.max(np.abs(fast.ys[-1] - Y0)) > 0.01  # the noise moved them
