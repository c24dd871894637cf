"""The least-squares start of IsoMP (``extrapolation_window``): its weights, its defaults, its
checks, and runs with it (compiled against NumPy, the same fixed point as interpolation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import isoflow as iso
from helpers import assert_same_run, compiled_and_numpy
from isoflow.methods import isomp
from isoflow.methods.extrapolation import (
    interpolation_weights,
    least_squares_weights,
    start_weights,
)


@pytest.mark.parametrize("p", range(8))
def test_a_fit_through_p_plus_one_offsets_is_the_interpolation(p: int) -> None:
    assert least_squares_weights(p, p + 1) == interpolation_weights(p + 1)


@pytest.mark.parametrize(("p", "m"), [(0, 5), (2, 6), (4, 10), (6, 12), (8, 16), (9, 16)])
def test_the_fit_is_exact_on_polynomials_of_its_degree(p: int, m: int) -> None:
    """sum_q c_q f(-q) = f(0) for every polynomial f of degree <= p (relative 1e-12), and not
    for degree p + 1 (a least-squares fit, not an interpolation)."""
    c = np.array(least_squares_weights(p, m))
    q = np.arange(1, m + 1, dtype=float)
    rng = np.random.default_rng(p * 100 + m)
    for deg in range(p + 1):
        coef = rng.standard_normal(deg + 1)
        values = np.polynomial.polynomial.polyval(-q, coef)
        scale = np.abs(c) @ np.abs(values)
        assert abs(c @ values - coef[0]) <= 1e-12 * scale, deg
    values = (-q) ** (p + 1)
    assert abs(c @ values) > 1.0  # the next degree is not reproduced


def test_the_noise_gains_the_docs_quote() -> None:
    """The 2-norm of the weights multiplies independent errors of the offsets: 58.6 for
    degree 6 interpolating, 13.3 for degree 8 on 16 offsets, 15.8 at degree 4, and the closed
    form (binom(2m, m) - 1)^(1/2) for interpolation."""
    assert np.linalg.norm(interpolation_weights(7)) == pytest.approx(58.6, abs=0.05)
    assert np.linalg.norm(interpolation_weights(5)) == pytest.approx(15.8, abs=0.05)
    assert np.linalg.norm(least_squares_weights(8, 16)) == pytest.approx(13.3, abs=0.05)
    for m in range(1, 9):
        gain = math.sqrt(math.comb(2 * m, m) - 1)
        assert np.linalg.norm(interpolation_weights(m)) == pytest.approx(gain, rel=1e-14)


def test_start_weights_interpolate_until_the_window_exceeds_the_degree() -> None:
    assert start_weights(None, 9) == interpolation_weights(9)
    assert start_weights(6, 5) == interpolation_weights(5)
    assert start_weights(6, 7) == interpolation_weights(7)
    assert start_weights(6, 12) == least_squares_weights(6, 12)
    with pytest.raises(ValueError, match="degree 6 needs more than 6 offsets"):
        least_squares_weights(6, 6)


def test_defaults_by_space() -> None:
    """Dense matrices from n = 512 fit their start (degree 8 on 16 offsets, degree 6 on 12
    from n = 1024) with the interpolating start of the default degree as fallback; elsewhere,
    and whenever a degree or window is given, no fallback."""
    alg = iso.algebras
    assert isomp.default_start(alg.su(64)) == (6, 7, 0)
    assert isomp.default_start(alg.su(511)) == (6, 7, 0)
    assert isomp.default_start(alg.su(512)) == (8, 16, 7)
    assert isomp.default_start(alg.so(700)) == (8, 16, 7)
    assert isomp.default_start(alg.su(1024)) == (6, 12, 5)
    assert isomp.default_start(alg.so3_vectors(4096)) == (4, 5, 0)
    m = iso.IsoMP()
    su512 = alg.su(512)
    assert (m.order_for(su512), m.window_for(su512), m.fallback_for(su512)) == (8, 16, 7)
    given = iso.IsoMP(extrapolation_order=3)  # a degree alone interpolates, as before
    assert (given.order_for(su512), given.window_for(su512), given.fallback_for(su512)) == (
        3, 4, 0,
    )  # fmt: skip
    window = iso.IsoMP(extrapolation_window=5)  # the default degree, at most window - 1
    assert (window.order_for(su512), window.window_for(su512), window.fallback_for(su512)) == (
        4, 5, 0,
    )  # fmt: skip
    wide = iso.IsoMP(extrapolation_window=16)  # a window given is always fitted
    assert (wide.order_for(alg.su(64)), wide.window_for(alg.su(64))) == (6, 16)
    assert wide.fallback_for(su512) == 0
    both = iso.IsoMP(extrapolation_order=9, extrapolation_window=16)
    assert (both.order_for(alg.su(8)), both.window_for(alg.su(8))) == (9, 16)


def _linear(alg, seed: int = 1) -> tuple:
    """Benchmark 3's field: ``B = C * W`` entrywise, a start accepted at once (1.2 iterations a
    step at ``h = 0.1``)."""
    n = alg.shape[0]
    d = np.linspace(0.5, 1.5, n)
    C = -(d[:, None] + d[None, :]) / 2
    prob = iso.IsospectralProblem(algebra=alg, kernel=iso.ElementwiseLinear(C))
    return prob, alg.random(seed=seed, scale=1.0 / n)


@pytest.fixture
def fitted_from_16(monkeypatch: pytest.MonkeyPatch) -> None:
    """The default's fitted start (with its fallback) from n = 16 instead of 512."""
    monkeypatch.setattr(isomp, "FITTED_START_MIN_N", 16)


@pytest.mark.usefixtures("fitted_from_16")
def test_the_fallback_keeps_a_start_that_suffices() -> None:
    """Where the interpolating start predicts every offset within half the tolerance, the
    default's fit falls back to it at every step: the run equals the interpolating one bit for
    bit (the fallback computes that start as the interpolating guess does), on the compiled
    path and on the NumPy path."""
    prob, W0 = _linear(iso.algebras.u(24))
    assert iso.IsoMP().fallback_for(prob.algebra) == 7
    kw = dict(dt=0.1, n_steps=40, save_every=10, progress=False)
    auto = iso.solve(prob, iso.IsoMP(), W0, **kw)
    interp = iso.solve(prob, iso.IsoMP(extrapolation_order=6), W0, **kw)
    assert auto.stats.runner.startswith("compiled")
    assert auto.ys.tobytes() == interp.ys.tobytes()
    a, b = compiled_and_numpy(prob, iso.IsoMP(), W0, 0.1, 40, save_every=10)
    assert_same_run(a, b)


@pytest.mark.usefixtures("fitted_from_16")
@pytest.mark.parametrize("N", [16, 40])
def test_the_default_fit_runs_the_same_on_both_paths(N: int) -> None:
    """Euler on the sphere, where the fit is taken (the interpolating start misses by more
    than half the tolerance): compiled and NumPy agree to 1e-13, iterations within 1 %."""
    prob, W0, h = _sphere(N)
    a, b = compiled_and_numpy(prob, iso.IsoMP(), W0, h, 40, save_every=8, chunks=(9, 13))
    assert_same_run(a, b, iters_exact=False)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"extrapolation_window": 0}, r"extrapolation_window must be an integer in \[1, 16\]"),
        ({"extrapolation_window": 17}, r"extrapolation_window must be an integer in \[1, 16\]"),
        ({"extrapolation_window": 8.0}, r"extrapolation_window must be an integer"),
        ({"extrapolation_window": True}, r"extrapolation_window must be an integer"),
        (
            {"extrapolation_order": 8, "extrapolation_window": 8},
            r"extrapolation_order must be an integer in \[0, 7\] with extrapolation_window=8",
        ),
        ({"extrapolation_order": 8}, r"extrapolation_order must be an integer in \[0, 7\]"),
    ],
)
def test_bad_windows_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(iso.ParameterError, match=message):
        iso.IsoMP(**kwargs)


def _sphere(N: int) -> tuple:
    prob, W0 = iso.models.euler_sphere(N=N, seed=1)
    h = float(0.3 / np.linalg.norm(prob.B(W0), 2))
    return prob, W0, h


@pytest.mark.parametrize("N", [16, 40])  # dense tiles (written out) and BLAS
def test_compiled_and_numpy_starts_agree(N: int) -> None:
    """A least-squares start (degree 3 on 10 offsets) runs the same on both paths: states
    and stored offsets to 1e-13, iteration counts within 1 % (a residual may land on the
    tolerance)."""
    prob, W0, h = _sphere(N)
    method = iso.IsoMP(extrapolation_order=3, extrapolation_window=10)
    a, b = compiled_and_numpy(prob, method, W0, h, 30, save_every=5, chunks=(7, 11))
    assert_same_run(a, b, iters_exact=False)


def test_the_fitted_start_reaches_the_same_states() -> None:
    """The start changes where the solve begins, not its fixed point: 40 steps of su(64) with
    the least-squares start equal those with the interpolating one to 1e-13 relative, and the
    Casimir drift stays at rounding."""
    prob, W0, h = _sphere(64)
    kw = dict(dt=h, n_steps=40, save_every=10, progress=False)
    fit = iso.solve(prob, iso.IsoMP(extrapolation_order=6, extrapolation_window=12), W0, **kw)
    interp = iso.solve(prob, iso.IsoMP(extrapolation_order=6), W0, **kw)
    scale = np.max(np.abs(interp.ys))
    assert np.max(np.abs(fit.ys - interp.ys)) <= 1e-13 * scale
    assert fit.diagnostics.casimir_drift < 1e-13


def test_where_rounding_limits_the_start_the_fit_saves_iterations() -> None:
    """su(64) Euler at ``h ||B||_2 = 0.02``: the offsets are smooth to rounding, so the
    degree-6 interpolation's error is its gain (58.6) on their rounding; fitted to 12 offsets
    (gain 7.9) the start is accepted at once more often. Measured 136 against 118 iterations in
    100 steps; asserted: at least 8 % fewer, the same states to 1e-13."""
    prob, W0, _ = _sphere(64)
    h = float(0.02 / np.linalg.norm(prob.B(W0), 2))
    kw = dict(dt=h, n_steps=100, save_every=100, progress=False)
    interp = iso.solve(prob, iso.IsoMP(extrapolation_order=6), W0, **kw)
    fit = iso.solve(prob, iso.IsoMP(extrapolation_order=6, extrapolation_window=12), W0, **kw)
    assert fit.stats.n_iterations <= 0.92 * interp.stats.n_iterations, (
        fit.stats.n_iterations,
        interp.stats.n_iterations,
    )
    assert np.max(np.abs(fit.y_final - interp.y_final)) <= 1e-13 * np.max(np.abs(W0))


@pytest.mark.usefixtures("fitted_from_16")
@pytest.mark.parametrize("case", ["sphere", "linear"])
def test_a_killed_run_with_the_fitted_start_resumes_bit_for_bit(tmp_path, case: str) -> None:
    """The start (fit or fallback) depends only on the state and the offsets a checkpoint
    keeps: a run killed at any of several writes resumes to the same file bit for bit, with
    the fit taken (Euler on the sphere) and with the fallback taken (a linear field)."""
    from helpers import disk_before_each_write
    from isoflow import io

    if case == "sphere":
        prob, W0, h = _sphere(20)
    else:
        (prob, W0), h = _linear(iso.algebras.so(20)), 0.1
    path = tmp_path / "run.h5"
    with disk_before_each_write(path) as copies:
        sol = iso.solve(
            prob, iso.IsoMP(), W0, dt=h, n_steps=40, save_every=2, progress=False,
            writer=io.HDF5Writer(path, chunk_rows=2, flush_seconds=0.0),
        )  # fmt: skip
    assert sol.success and sol.stats.runner.startswith("compiled")
    ref = io.load(path)
    kills = []  # the first copies from steps 20 and 30: past the window of 16, before the end
    for i in range(0, len(copies), 4):
        part = tmp_path / f"kill{i}.h5"
        part.write_bytes(copies[i])
        step = io.load(part).step
        if step >= (20 if not kills else 30) and step < 40:
            kills.append(part)
            if len(kills) == 2:
                break
    assert len(kills) == 2
    for part in kills:
        resumed = io.resume(part, problem=prob, method=iso.IsoMP(), progress=False)
        assert resumed.success
        assert io.load(part).ys.tobytes() == ref.ys.tobytes()
