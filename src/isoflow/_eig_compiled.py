"""The compiled loops of :mod:`isoflow._eig` (imported on first use)."""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "eigh_diagonal_stack",
    "eigvalsh_stack",
    "eigvalsh_stack_parallel",
    "skew_eigvalsh_stack",
    "skew_eigvalsh_stack_parallel",
]


def _loop(A, out):  # type: ignore[no-untyped-def]
    for m in numba.prange(A.shape[0]):
        out[m] = np.linalg.eigvalsh(A[m])


# two compilations of one loop (numba's cache key ignores ``parallel=``: separate functions)
eigvalsh_stack = numba.njit(cache=True, nogil=True)(_loop)
eigvalsh_stack.__doc__ = "``out[m] = eigvalsh(A[m])`` for every matrix, without the GIL."


def _loop_parallel(A, out):  # type: ignore[no-untyped-def]
    for m in numba.prange(A.shape[0]):
        out[m] = np.linalg.eigvalsh(A[m])


eigvalsh_stack_parallel = numba.njit(cache=True, nogil=True, parallel=True)(_loop_parallel)
eigvalsh_stack_parallel.__doc__ = "The same over numba threads (large stacks, main thread)."


@numba.njit(cache=True, nogil=True)
def skew_to_tridiagonal(A, v, w, T):  # type: ignore[no-untyped-def]
    r"""The real symmetric tridiagonal ``T`` similar to :math:`iA`, for a real skew ``A``.

    Householder reflections :math:`H_k = I - \beta_k v_k v_k^T` make :math:`Q^T A Q` skew
    tridiagonal, with subdiagonal :math:`\alpha_k`; the update of the trailing block uses
    :math:`v^T A v = 0` (skew ``A``): :math:`H A H = A + \beta (v w^T - w v^T)`,
    :math:`w = A v`. The Hermitian :math:`iA` is then similar (by :math:`\mathrm{diag}(i^k)`)
    to the real symmetric tridiagonal ``T`` with zero diagonal and off-diagonal
    :math:`\alpha_k`: the same eigenvalues, in real arithmetic. Backward stable, like LAPACK's
    reductions. ``A`` is overwritten; ``v`` and ``w`` are work vectors of length ``n``.
    """
    n = A.shape[0]
    T[:] = 0.0
    for k in range(n - 2):
        m = n - k - 1  # the column below the subdiagonal entry, and the trailing block
        s = 0.0
        for i in range(m):
            s += A[k + 1 + i, k] * A[k + 1 + i, k]
        alpha = np.sqrt(s)
        if A[k + 1, k] >= 0.0:
            alpha = -alpha  # the reflection that avoids cancellation in v[0]
        T[k + 1, k] = T[k, k + 1] = alpha
        for i in range(m):
            v[i] = A[k + 1 + i, k]
        v[0] -= alpha
        vv = 0.0
        for i in range(m):
            vv += v[i] * v[i]
        if vv == 0.0:  # the column is zero already
            continue
        beta = 2.0 / vv
        for i in range(m):
            acc = 0.0
            for j in range(m):
                acc += A[k + 1 + i, k + 1 + j] * v[j]
            w[i] = acc
        for i in range(m):
            for j in range(m):
                A[k + 1 + i, k + 1 + j] += beta * (v[i] * w[j] - w[i] * v[j])
    if n >= 2:
        T[n - 1, n - 2] = T[n - 2, n - 1] = A[n - 1, n - 2]


@numba.njit(cache=True, nogil=True)
def _skew_eigenvalues(W, out, A, T, v, w):  # type: ignore[no-untyped-def]
    """``out = eigvalsh(1j * W)`` for one real skew ``W``, with the work arrays given.

    ``W`` is scaled by the power of two nearest its largest entry (exact), so that the sums
    of squares neither overflow nor underflow; non-finite entries reach LAPACK's check. The
    eigenvalues of the real symmetric tridiagonal matrix are LAPACK's (``syevd``).
    """
    n = W.shape[0]
    big = 0.0
    for i in range(n):
        for j in range(n):
            big = max(big, abs(W[i, j]))
    if not np.isfinite(big):
        out[:] = np.linalg.eigvalsh(1j * W)  # raises LinAlgError, like the complex route
        return
    scale = 1.0 if big == 0.0 else math.ldexp(1.0, math.frexp(big)[1])
    inv = 1.0 / scale
    for i in range(n):
        for j in range(n):
            A[i, j] = W[i, j] * inv
    skew_to_tridiagonal(A, v, w, T)
    out[:] = np.linalg.eigvalsh(T)
    for i in range(n):
        out[i] *= scale


def _skew_loop(W, out):  # type: ignore[no-untyped-def]
    n = W.shape[1]
    A, T, v, w = np.empty((n, n)), np.empty((n, n)), np.empty(n), np.empty(n)
    for m in range(W.shape[0]):
        _skew_eigenvalues(W[m], out[m], A, T, v, w)


skew_eigvalsh_stack = numba.njit(cache=True, nogil=True)(_skew_loop)
skew_eigvalsh_stack.__doc__ = (
    "``out[m] = eigvalsh(1j * W[m])`` for real skew matrices, in real arithmetic, without the GIL."
)


def _skew_loop_parallel(W, out):  # type: ignore[no-untyped-def]
    n = W.shape[1]
    for m in numba.prange(W.shape[0]):  # work arrays per member: threads share nothing
        A, T, v, w = np.empty((n, n)), np.empty((n, n)), np.empty(n), np.empty(n)
        _skew_eigenvalues(W[m], out[m], A, T, v, w)


skew_eigvalsh_stack_parallel = numba.njit(cache=True, nogil=True, parallel=True)(
    _skew_loop_parallel
)
skew_eigvalsh_stack_parallel.__doc__ = "The same over numba threads (large stacks, main thread)."


@numba.njit(cache=True, nogil=True)
def eigh_diagonal_stack(A, B, lam, d):  # type: ignore[no-untyped-def]
    """``lam[m], U = eigh(A[m])`` and ``d[m, i] = Re (U^H B[m] U)_ii`` for every matrix, without
    the GIL (see :func:`isoflow._eig.eigh_diagonal`)."""
    n = A.shape[1]
    for m in range(A.shape[0]):
        w, U = np.linalg.eigh(A[m])
        BU = B[m] @ U
        for i in range(n):
            acc = 0.0
            for k in range(n):
                acc += (U[k, i].conjugate() * BU[k, i]).real
            lam[m, i] = w[i]
            d[m, i] = acc
