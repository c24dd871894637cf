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


def test_the_default_interpolates_and_a_window_fits() -> None:
    """Without a window the start interpolates (as before the window existed); a window fits
    the default degree (at most window - 1) or the one given."""
    alg = iso.algebras
    m = iso.IsoMP()
    assert (m.order_for(alg.su(512)), m.window_for(alg.su(512))) == (6, 7)
    assert (m.order_for(alg.su(1024)), m.window_for(alg.su(1024))) == (4, 5)
    given = iso.IsoMP(extrapolation_order=3)
    assert (given.order_for(alg.su(512)), given.window_for(alg.su(512))) == (3, 4)
    window = iso.IsoMP(extrapolation_window=5)  # the default degree, at most window - 1
    assert (window.order_for(alg.su(512)), window.window_for(alg.su(512))) == (4, 5)
    wide = iso.IsoMP(extrapolation_window=16)
    assert (wide.order_for(alg.su(64)), wide.window_for(alg.su(64))) == (6, 16)
    both = iso.IsoMP(extrapolation_order=9, extrapolation_window=16)
    assert (both.order_for(alg.su(8)), both.window_for(alg.su(8))) == (9, 16)
    assert isomp.resolve_extrapolation(None, None, alg.so3_vectors(10)) == (4, 5)  # particle states


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
