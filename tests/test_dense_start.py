"""The start of dense BLAS states from the lower triangle of the offsets
(:mod:`isoflow._compiled.dense_start`): the same start as the flat pass to the last bit, the
same fallback decision, whatever the thread count, and in a run."""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso
from isoflow._compiled import dense_start, flat
from isoflow.methods.extrapolation import interpolation_weights, least_squares_weights
from isoflow.threads import thread_limits

K = 16


def _mirrored(rng: np.random.Generator, n: int, s: float, complex_: bool) -> np.ndarray:
    """A random ``n x n`` matrix with ``Y[j, i] = s conj(Y[i, j])`` exactly, flattened."""
    A = rng.standard_normal((n, n))
    if complex_:
        A = A + 1j * rng.standard_normal((n, n))
    Y = np.tril(A)
    Y = Y + s * np.conj(np.tril(Y, -1)).T
    d = np.diagonal(Y).copy()
    np.fill_diagonal(Y, 0.5 * (d + s * np.conj(d)))
    assert np.array_equal(Y.T, s * np.conj(Y))
    return np.ascontiguousarray(Y).reshape(-1)


def _case(n: int, s: float, complex_: bool, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A state, a full ring of offsets (scaled like a run's, 1e-3 of the state) and the weights
    of the default starts: rows ``nh - 1`` of a degree-8 fit on 16 offsets (interpolating
    below), and a last row with the degree-6 interpolating fallback."""
    rng = np.random.default_rng(seed)
    W = _mirrored(rng, n, s, complex_)
    ring = np.stack([1e-3 * _mirrored(rng, n, s, complex_) for _ in range(K)])
    coefs = np.zeros((K + 1, K))
    for m in range(1, K + 1):
        w = least_squares_weights(8, m) if m > 9 else interpolation_weights(m)
        coefs[m - 1, :m] = w
    coefs[K, :7] = interpolation_weights(7)
    return W, ring, coefs


SPACES = [(-1.0, True), (1.0, True), (-1.0, False), (1.0, False)]  # u/su, herm, so, sym


@pytest.mark.parametrize(("s", "complex_"), SPACES)
@pytest.mark.parametrize("n", [17, 40, 33])
@pytest.mark.parametrize("threaded", [False, True])
def test_the_start_from_the_lower_triangle_is_the_flat_start(
    s: float, complex_: bool, n: int, threaded: bool
) -> None:
    """For every count of offsets (0 to 16, the ring's head anywhere): the same start to the
    last bit, the mirrored half included."""
    W, ring, coefs = _case(n, s, complex_, seed=n)
    for nh in range(K + 1):
        head = (3 * nh) % K
        want = np.empty_like(W)
        flat.guess(W, ring, head, nh, coefs, want)
        got = np.full_like(W, np.nan)
        with thread_limits(numba=2 if threaded else 1):
            dense_start.start_lower(W, ring, head, nh, coefs, got, n, s, threaded)
        assert np.array_equal(got, want), nh


@pytest.mark.parametrize(("s", "complex_"), SPACES)
@pytest.mark.parametrize("threaded", [False, True])
@pytest.mark.parametrize("kint", [5, 7])
def test_the_fallback_decides_as_the_flat_pass(
    s: float, complex_: bool, threaded: bool, kint: int
) -> None:
    """The interpolating start's miss of the newest offset, measured on the lower triangle
    (off-diagonal entries twice), decides as the flat pass does for limits 1e-6 (relative)
    on either side of it; either start is the flat one to the last bit."""
    n = 29
    W, ring, coefs = _case(n, s, complex_, seed=kint)
    coefs[K, :] = 0.0
    coefs[K, :kint] = interpolation_weights(kint)
    head = 5
    d = [ring[(head - q) % K] for q in range(kint + 1)]
    pairs = zip(coefs[K, :kint], d[1:], strict=True)
    miss = np.linalg.norm(d[0] - sum(c * dq for c, dq in pairs))
    for limit, taken in ((miss * (1 - 1e-6), False), (miss * (1 + 1e-6), True)):
        want = np.empty_like(W)
        assert flat.guess_or_fit(W, ring, head, K, coefs, kint, limit, want) is taken
        got = np.full_like(W, np.nan)
        with thread_limits(numba=2 if threaded else 1):
            took = dense_start.start_or_fit_lower(
                W, ring, head, K, coefs, kint, limit, got, n, s, threaded
            )
        assert took is taken
        assert np.array_equal(got, want)


@pytest.mark.parametrize(("s", "complex_"), SPACES)
@pytest.mark.parametrize("threaded", [False, True])
def test_the_fallback_stops_measuring_once_the_miss_passes_the_limit(
    s: float, complex_: bool, threaded: bool
) -> None:
    """Both passes measure a part of the miss first (the lower triangle: the last row pairs,
    about the middle rows; the flat pass: its first chunk) and take the fit at once when that
    part passes the limit.
    For a limit below that part, one between it and the whole miss, and one above: the
    decision of the whole miss (computed here with NumPy) and, to the last bit, the fit's
    or the interpolation's start as :func:`isoflow._compiled.flat.guess` forms them."""
    n, kint, head = 120, 7, 11
    W, ring, coefs = _case(n, s, complex_, seed=3)
    d = [ring[(head - q) % K] for q in range(kint + 1)]
    c = interpolation_weights(kint)
    e = (d[0] - sum(cq * dq for cq, dq in zip(c, d[1:], strict=False))).reshape(n, n)
    rows = np.abs(np.tril(e)) ** 2
    lower2 = 2 * rows.sum(axis=1) - np.diagonal(rows)  # each row's part, mirrors counted
    npair = (n + 1) // 2
    m = dense_start.first_pairs(n)
    assert 1 <= m < npair
    firsts = [k for k in range(npair - m, npair)] + [n - 1 - k for k in range(npair - m, npair)]
    firsts = sorted(set(firsts))  # the middle row of an odd n is its own pair
    parts = {
        "lower": (float(lower2[firsts].sum()), float(lower2.sum())),
        "flat": (float(np.sum(np.abs(e.reshape(-1)[:2048]) ** 2)), float(np.sum(np.abs(e) ** 2))),
    }
    interp_coefs = np.zeros_like(coefs)
    interp_coefs[kint - 1, :kint] = c
    fit = np.empty_like(W)
    flat.guess(W, ring, head, K, coefs, fit)
    interp = np.empty_like(W)
    flat.guess(W, ring, head, kint, interp_coefs, interp)
    for name, (first, whole) in parts.items():
        assert 4 * first < whole, name  # the three limits below are apart
        for limit2 in (0.5 * first, np.sqrt(first * whole), 2 * whole):
            limit = float(np.sqrt(limit2))
            taken = bool(whole <= limit2)
            got = np.full_like(W, np.nan)
            with thread_limits(numba=2 if threaded else 1):
                if name == "lower":
                    took = dense_start.start_or_fit_lower(
                        W, ring, head, K, coefs, kint, limit, got, n, s, threaded
                    )
                else:
                    took = flat.guess_or_fit(W, ring, head, K, coefs, kint, limit, got)
            assert took is taken, (name, limit2 / whole)
            assert np.array_equal(got, interp if taken else fit), (name, limit2 / whole)


def _linear_field(n: int) -> tuple[iso.IsospectralProblem, np.ndarray]:
    alg = iso.algebras.u(n)
    d = np.linspace(0.5, 1.5, n)
    C = -(d[:, None] + d[None, :]) / 2
    return iso.IsospectralProblem(algebra=alg, kernel=iso.ElementwiseLinear(C)), alg.random(
        seed=1, scale=1.0 / n
    )


def test_runs_choose_the_start_by_what_it_reads() -> None:
    """The lower triangle where the start reads at least ``LOWER_MIN_BYTES`` on a dense BLAS
    state (``u(512)``: the fallback's 8 offsets of 4 MB), the flat start below (``u(64)``)
    and on other layouts (a spin chain)."""
    from isoflow._compiled import compiled_runner

    prob, W0 = _linear_field(512)
    assert 8 * 512 * 512 * 16 >= dense_start.LOWER_MIN_BYTES
    assert compiled_runner(prob, iso.IsoMP(), W0, 0.1).start is dense_start.lower_start
    prob, W0 = _linear_field(64)
    assert compiled_runner(prob, iso.IsoMP(), W0, 0.1).start is flat.start
    chain, s0 = iso.models.heisenberg_chain(N=64, seed=0)
    assert compiled_runner(chain, iso.IsoMP(), s0, 0.1).start is flat.start


def test_a_large_run_from_the_lower_triangle_keeps_its_states() -> None:
    """``u(512)`` under a linear field (the fallback's check each step, its interpolating
    start taken): one and two threads give the same states to the last bit, and the NumPy
    path's to 1e-13."""
    from helpers import FAST_TOL, assert_same_run, compiled_and_numpy

    prob, W0 = _linear_field(512)
    kw = dict(dt=0.1, n_steps=12, save_every=12, progress=False, diagnostics=False)
    one = iso.solve(prob, iso.IsoMP(), W0, threads=1, **kw)
    two = iso.solve(prob, iso.IsoMP(), W0, threads=2, **kw)
    assert np.array_equal(np.asarray(one.ys), np.asarray(two.ys))
    compiled, numpy_path = compiled_and_numpy(prob, iso.IsoMP(), W0, 0.1, 12, save_every=12)
    assert_same_run(compiled, numpy_path)
    assert np.array_equal(np.asarray(compiled.y), np.asarray(one.ys[-1]))
    assert FAST_TOL == 1e-13
