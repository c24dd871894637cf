"""Fields written the way a user writes them (``iso.CompiledB``), for the tests.

Module-level ``@numba.njit(cache=True)`` functions, so that numba caches them (and the compiled
loops specialized on their types) across test runs.
"""

from __future__ import annotations

import numba
import numpy as np

import isoflow as iso


@numba.njit(cache=True)
def cubic_elementwise(W, out, C):  # type: ignore[no-untyped-def]
    """``B_ij = C_ij W_ij (1 + |W_ij|^2)``: nonlinear, in the normalizer when ``C`` is symmetric
    (skew spaces) or antisymmetric (symmetric spaces)."""
    n = W.shape[0]
    for i in range(n):
        for j in range(n):
            w = W[i, j]
            out[i, j] = C[i, j] * w * (1.0 + (w.real * w.real + w.imag * w.imag))


def cubic_elementwise_numpy(C: np.ndarray):
    """The same ``B`` in NumPy (broadcasting over leading axes)."""

    def B(W):
        return C * W * (1.0 + np.abs(W) ** 2)

    return B


@numba.njit(cache=True)
def neighbours(W, out, c):  # type: ignore[no-untyped-def]
    """``B_i = c (w_{i-1} + w_{i+1})`` on ``(N, 3)``, written plainly (AoS, no fusion)."""
    N = W.shape[0]
    for i in range(N):
        im = i - 1 if i > 0 else N - 1
        ip = i + 1 if i < N - 1 else 0
        for a in range(3):
            out[i, a] = c * (W[im, a] + W[ip, a])


@numba.njit(cache=True)
def precession(W, out, axis, strength):  # type: ignore[no-untyped-def]
    """``B_i = strength * (axis . w_i) axis``: a nonlinear field on ``(N, 3)`` particles."""
    for i in range(W.shape[0]):
        d = axis[0] * W[i, 0] + axis[1] * W[i, 1] + axis[2] * W[i, 2]
        for a in range(3):
            out[i, a] = strength * d * axis[a]


def precession_numpy(axis: np.ndarray, strength: float):
    def B(W):
        return strength * (W @ axis)[..., None] * axis

    return B


@numba.njit(cache=True)
def returns_nothing_useful(W):  # type: ignore[no-untyped-def]
    """Wrong signature for a field (one argument)."""
    return W


@numba.njit(cache=True)
def raises_when_large(W, out, C, limit):  # type: ignore[no-untyped-def]
    """``C * W``, raising once an entry exceeds ``limit`` (a user error mid-run)."""
    n = W.shape[0]
    for i in range(n):
        for j in range(n):
            if abs(W[i, j]) > limit:
                raise ValueError("entry too large")
            out[i, j] = C[i, j] * W[i, j]


def raises_when_large_numpy(C: np.ndarray, limit: float):
    """:func:`raises_when_large` in NumPy, vectorized: it raises if any member has an entry
    beyond ``limit``."""

    def B(W):
        if np.any(np.abs(W) > limit):
            raise ValueError("entry too large")
        return C * W

    return B


@numba.njit(cache=True)
def leaves_when_large(W, out, C, limit):  # type: ignore[no-untyped-def]
    """``C * W``, plus ``0.1 diag(0, 1, ..., n - 1)`` (symmetric: outside the skew normalizer)
    once an entry exceeds ``limit``: a user's ``B`` that leaves the normalizer mid-run."""
    n = W.shape[0]
    large = False
    for i in range(n):
        for j in range(n):
            out[i, j] = C[i, j] * W[i, j]
            large = large or abs(W[i, j]) > limit
    if large:
        for i in range(n):
            out[i, i] += 0.1 * i


def leaves_when_large_numpy(C: np.ndarray, limit: float):
    """:func:`leaves_when_large` in NumPy, member by member over leading axes."""

    def B(W):
        large = np.abs(W).max(axis=(-2, -1)) > limit
        return C * W + 0.1 * large[..., None, None] * np.diag(np.arange(W.shape[-1]))

    return B


def cubic_problem(alg: iso.algebras.Algebra, seed: int = 0, scale: float = 1.0):
    """A nonlinear ``CompiledB`` problem on a dense space, with the matching NumPy ``B``."""
    rng = np.random.default_rng(seed)
    n = alg.shape[0]
    A = rng.uniform(0.5, 1.5, (n, n))
    symmetric_space = isinstance(alg, (iso.algebras.Symmetric, iso.algebras.Hermitian))
    C = scale * (0.5 * (A - A.T) if symmetric_space else 0.5 * (A + A.T))
    kernel = iso.CompiledB(cubic_elementwise, (C,))
    return iso.IsospectralProblem(B=cubic_elementwise_numpy(C), algebra=alg, kernel=kernel)


@numba.njit(cache=True)
def writes_complex_into_real(W, out, c):  # type: ignore[no-untyped-def]
    """A user error numba only finds when typing: a complex value into a real ``out``."""
    for i in range(W.shape[0]):
        for j in range(W.shape[1]):
            out[i, j] = c * W[i, j]


@numba.njit("void(float64[:, :], float64[:, :])", cache=True)
def declared_any_layout(W, out):  # type: ignore[no-untyped-def]
    """An explicit signature without C-contiguity: compiled loops cannot call this one."""
    out[...] = -W


@numba.njit(cache=True)
def modifies_its_state(W, out, C):  # type: ignore[no-untyped-def]
    """A user error: ``B = C * W``, and ``W`` scaled in place (each call sees another W)."""
    n = W.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = -C[i, j] * W[i, j]
            W[i, j] *= 1.0 + 1e-6


@numba.njit(cache=True)
def skips_the_diagonal(W, out, C):  # type: ignore[no-untyped-def]
    """A user error: ``B = -C * W`` on so(n), the zero diagonal left to ``out`` starting at 0."""
    n = W.shape[0]
    for i in range(n):
        for j in range(n):
            if i != j:
                out[i, j] = -C[i, j] * W[i, j]


@numba.njit(cache=True)
def adds_into_out(W, out, C):  # type: ignore[no-untyped-def]
    """A user error: ``B = -C * W`` accumulated into ``out`` as if it started at 0."""
    n = W.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] += -C[i, j] * W[i, j]
