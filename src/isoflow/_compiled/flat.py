r"""The layout-free pieces of a compiled step, on one member's state as a flat vector.

Every state layout (a dense matrix, an ``(N, 3)`` particle array, a spin chain in its
``(3, N)`` layout) is one C-contiguous block of memory, so the parts of a step that act on
whole states entry by entry are written once, here, on flat vectors:

* the extrapolated initial guess :math:`X^{(0)} = W + \sum_q a_q D_q` from the ring of the last
  stage offsets :math:`D = X - W` (:func:`guess`), and the ring itself (:func:`push`);
* Anderson mixing of the fixed-point iterates (:func:`anderson`), the same algorithm as
  :class:`isoflow.FixedPoint` (see :mod:`isoflow.nonlinear`);
* sums of squares and real inner products (:func:`sumsq`, :func:`rdot`);
* the exact sum of two numbers, :func:`two_sum`, for the compensated update of a state
  (:mod:`isoflow.methods.isomp`).

Element-wise loops are compiled *without* reassociation, so an entry and its mirror in a
matrix space (``X[j, i] = s * conj(X[i, j])``) go through the same operations and stay exact
mirrors. Only the norms reassociate (to vectorize): they decide when to stop, and a last-bit
difference in one changes a decision only when it sits exactly at the tolerance. Anything that
moves a state (the inner products of Anderson mixing included) is free of reassociation, so
that a loop compiled in a run's process and one loaded from numba's cache give the same
states to the last bit.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "anderson",
    "copy",
    "guess",
    "guess_or_fit",
    "guess_range",
    "miss_range",
    "no_mixing",
    "push",
    "rdot",
    "start",
    "sumsq",
    "two_sum",
]

#: Reassociation for the norms only (sums of squares).
_REDUCE = {"reassoc", "nsz", "contract"}


@numba.njit(cache=True, fastmath=_REDUCE)
def sumsq(a):  # type: ignore[no-untyped-def]
    """``sum |a_i|^2``."""
    acc = 0.0
    for i in range(a.shape[0]):
        v = a[i]
        acc += v.real * v.real + v.imag * v.imag
    return acc


@numba.njit(cache=True, fastmath={"nsz"})
def rdot(a, b):  # type: ignore[no-untyped-def]
    r"""The real inner product :math:`\operatorname{Re} \sum \bar a_i b_i`, in four partial sums
    of a fixed order.

    Not reassociated, unlike the norms: Anderson's coefficients come from these products, so
    their rounding moves the iterates, and with ``reassoc`` it could depend on how LLVM
    compiled the loop in a given process (a run and its resume would then differ in the last
    bit; see :mod:`isoflow._compiled.dense_tiles`).
    """
    n = a.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    m = n - n % 4
    for i in range(0, m, 4):
        s0 += a[i].real * b[i].real + a[i].imag * b[i].imag
        s1 += a[i + 1].real * b[i + 1].real + a[i + 1].imag * b[i + 1].imag
        s2 += a[i + 2].real * b[i + 2].real + a[i + 2].imag * b[i + 2].imag
        s3 += a[i + 3].real * b[i + 3].real + a[i + 3].imag * b[i + 3].imag
    for i in range(m, n):
        s0 += a[i].real * b[i].real + a[i].imag * b[i].imag
    return (s0 + s1) + (s2 + s3)


@numba.njit(cache=True)
def two_sum(a, b):  # type: ignore[no-untyped-def]
    """``(s, e)`` with ``s = fl(a + b)`` and ``a + b = s + e`` exactly (Knuth's TwoSum; real
    or complex, part by part).

    Compiled on its own without reassociation, which would simplify ``e`` to zero: the
    callers in loops compiled with ``fastmath`` call it (LLVM keeps each instruction's flags
    when it inlines), and ``tests/test_compensated.py`` checks that the error survives in
    every layout.
    """
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


@numba.njit(cache=True)
def copy(dst, src):  # type: ignore[no-untyped-def]
    """``dst[:] = src``."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


#: Entries of a chunk of :func:`guess` beyond seven offsets (32 KiB of complex entries).
_GUESS_CHUNK = 2048


@numba.njit(cache=True, inline="always")
def _back(head, q, K):  # type: ignore[no-untyped-def]
    """``(head - q) % K`` for ``0 <= q < K`` without a division (the ring's older slots)."""
    j = head - q
    return j + K if j < 0 else j


@numba.njit(cache=True, inline="always")
def guess_range(W, ring, head, nh, coefs, X, a, b):  # type: ignore[no-untyped-def]
    r""":func:`guess` on the entries ``a <= i < b`` only (a dense layout's start reads the
    lower triangle of each offset, row by row: :mod:`isoflow._compiled.dense_start`).

    Every entry goes through the same operations whatever the range, so a start assembled
    from ranges equals :func:`guess`'s to the last bit.
    """
    K = ring.shape[0]
    if nh == 0:
        for i in range(a, b):
            X[i] = W[i]
        return
    a0 = coefs[nh - 1, 0]
    d0 = ring[head]
    if nh == 1:
        for i in range(a, b):
            X[i] = W[i] + a0 * d0[i]
        return
    a1 = coefs[nh - 1, 1]
    d1 = ring[_back(head, 1, K)]
    if nh == 2:
        for i in range(a, b):
            X[i] = W[i] + (a0 * d0[i] + a1 * d1[i])
        return
    a2 = coefs[nh - 1, 2]
    d2 = ring[_back(head, 2, K)]
    if nh == 3:
        for i in range(a, b):
            X[i] = W[i] + (a0 * d0[i] + a1 * d1[i] + a2 * d2[i])
        return
    a3 = coefs[nh - 1, 3]
    d3 = ring[_back(head, 3, K)]
    if nh == 4:
        for i in range(a, b):
            X[i] = W[i] + (a0 * d0[i] + a1 * d1[i] + a2 * d2[i] + a3 * d3[i])
        return
    a4 = coefs[nh - 1, 4]
    d4 = ring[_back(head, 4, K)]
    if nh == 5:  # IsoMP's order 4 (the default on particle states and large matrices)
        for i in range(a, b):
            X[i] = W[i] + (a0 * d0[i] + a1 * d1[i] + a2 * d2[i] + a3 * d3[i] + a4 * d4[i])
        return
    a5 = coefs[nh - 1, 5]
    d5 = ring[_back(head, 5, K)]
    if nh == 6:
        for i in range(a, b):
            e = a0 * d0[i] + a1 * d1[i] + a2 * d2[i] + a3 * d3[i] + a4 * d4[i] + a5 * d5[i]
            X[i] = W[i] + e
        return
    a6 = coefs[nh - 1, 6]
    d6 = ring[_back(head, 6, K)]
    if nh == 7:  # IsoMP's default order 6 on matrix states
        for i in range(a, b):
            e = a0 * d0[i] + a1 * d1[i] + a2 * d2[i] + a3 * d3[i] + a4 * d4[i] + a5 * d5[i]
            X[i] = W[i] + (e + a6 * d6[i])
        return
    # more offsets (a least-squares start fits up to 16): the first seven written out as
    # above, each further one added in turn, chunk by chunk so that X's chunk stays in cache
    for c0 in range(a, b, _GUESS_CHUNK):
        c1 = min(b, c0 + _GUESS_CHUNK)
        for i in range(c0, c1):
            e = a0 * d0[i] + a1 * d1[i] + a2 * d2[i] + a3 * d3[i] + a4 * d4[i] + a5 * d5[i]
            X[i] = e + a6 * d6[i]
        for q in range(7, nh):
            aq = coefs[nh - 1, q]
            dq = ring[_back(head, q, K)]
            for i in range(c0, c1):
                X[i] = X[i] + aq * dq[i]
        for i in range(c0, c1):
            X[i] = W[i] + X[i]


@numba.njit(cache=True)
def guess(W, ring, head, nh, coefs, X):  # type: ignore[no-untyped-def]
    r"""``X = W + sum_q coefs[nh-1, q] ring[(head - q) % K]`` (newest offset first), or
    ``X = W`` when ``nh = 0``.

    The sum is evaluated left to right from the newest offset, as the NumPy path does
    (:meth:`isoflow.IsoMP.initial_stage`); up to seven offsets are written out in one loop
    and each further one is added in turn over chunks of ``X`` that stay in cache, so every
    loop vectorizes and each offset is read once.
    """
    guess_range(W, ring, head, nh, coefs, X, 0, W.shape[0])


@numba.njit(cache=True, inline="always")
def miss_range(W, ring, head, kint, c, X, a, b, ebuf):  # type: ignore[no-untyped-def]
    """The interpolating start ``X = W + sum_{q < kint} c_q D_q`` (newest offset first) on the
    entries ``a <= i < b`` and, returned, the squared size there of
    ``D_0 - sum_{q < kint} c_q D_{q+1}``: how far the same start would have missed the newest
    offset from the ones before it. ``kint`` is 5 or 7 (the fallbacks of IsoMP's default
    starts, ``records.Plan``); every offset is loaded once per entry. ``X`` is formed as
    :func:`guess_range` forms it with these weights; the miss goes through ``ebuf`` in
    chunks of its length and is measured by :func:`sumsq` (a norm, reassociated: the module
    docstring)."""
    K = ring.shape[0]
    d0 = ring[head]
    d1 = ring[_back(head, 1, K)]
    d2 = ring[_back(head, 2, K)]
    d3 = ring[_back(head, 3, K)]
    d4 = ring[_back(head, 4, K)]
    d5 = ring[_back(head, 5, K)]
    d6 = ring[_back(head, 6 if kint == 7 else 0, K)]
    d7 = ring[_back(head, 7 if kint == 7 else 0, K)]
    c0, c1, c2, c3, c4 = c[0], c[1], c[2], c[3], c[4]
    c5, c6 = (c[5], c[6]) if kint == 7 else (0.0, 0.0)
    acc = 0.0
    for j0 in range(a, b, ebuf.shape[0]):
        j1 = min(b, j0 + ebuf.shape[0])
        if kint == 5:
            for i in range(j0, j1):
                X[i] = W[i] + (c0 * d0[i] + c1 * d1[i] + c2 * d2[i] + c3 * d3[i] + c4 * d4[i])
                ebuf[i - j0] = d0[i] - (
                    c0 * d1[i] + c1 * d2[i] + c2 * d3[i] + c3 * d4[i] + c4 * d5[i]
                )
        else:
            for i in range(j0, j1):
                x = c0 * d0[i] + c1 * d1[i] + c2 * d2[i] + c3 * d3[i] + c4 * d4[i] + c5 * d5[i]
                X[i] = W[i] + (x + c6 * d6[i])
                y = c0 * d1[i] + c1 * d2[i] + c2 * d3[i] + c3 * d4[i] + c4 * d5[i] + c5 * d6[i]
                ebuf[i - j0] = d0[i] - (y + c6 * d7[i])
        acc += sumsq(ebuf[: j1 - j0])
    return acc


@numba.njit(cache=True)
def guess_or_fit(W, ring, head, nh, coefs, kint, limit, X):  # type: ignore[no-untyped-def]
    """The start of a fitted stage (:func:`guess` with the fit's weights ``coefs[nh - 1]``),
    unless the interpolating start on the newest ``kint`` offsets (weights ``coefs[-1]``,
    ``kint`` 5 or 7) would have predicted the newest offset from the ``kint`` before it within
    ``limit`` (half the solve's tolerance): then that start, which reads fewer offsets. Needs
    ``nh > kint``. Returns whether the interpolating start was taken.

    The miss is summed chunk by chunk, and the pass stops at the first chunk that takes the
    sum past ``limit**2`` (the rest could only add to it): the same decision and start as the
    whole pass, at the cost of a few chunks where the fit is taken."""
    S = W.shape[0]
    L = min(S, _GUESS_CHUNK)
    ebuf = np.empty(L, dtype=X.dtype)
    c = coefs[coefs.shape[0] - 1]
    limit2 = limit * limit
    # chunk by chunk, the sums added in the order miss_range adds them over the whole state;
    # once the sum passes the limit (adding a squared size never lowers it), the fit is taken
    miss2 = 0.0
    for j0 in range(0, S, L):
        miss2 += miss_range(W, ring, head, kint, c, X, j0, min(S, j0 + L), ebuf)
        if miss2 > limit2:
            break
    if miss2 <= limit2:
        return True
    guess_range(W, ring, head, nh, coefs, X, 0, S)
    return False


@numba.njit(cache=True)
def start(lay, W, ring, head, nh, coefs, kint, limit, X):  # type: ignore[no-untyped-def]
    """The driver's start on the flat state (any layout ``lay``): :func:`guess_or_fit` when
    ``kint > 0`` and more than ``kint`` offsets are stored, else :func:`guess`; whether the
    interpolating fallback was taken. A run's start is passed to the driver as a function
    value (:mod:`isoflow._compiled.signatures`), so a layout with a start of its own
    (:mod:`isoflow._compiled.dense_start`) costs other runs no compilation."""
    if kint > 0 and nh > kint:
        return guess_or_fit(W, ring, head, nh, coefs, kint, limit, X)
    guess(W, ring, head, nh, coefs, X)
    return False


@numba.njit(cache=True)
def push(ring, slot, X, W):  # type: ignore[no-untyped-def]
    """Store the stage offset ``X - W`` in ``ring[slot]`` (the driver passes the map's value
    at the accepted stage as ``X``, see :class:`isoflow.IsoMP`)."""
    d = ring[slot]
    for i in range(W.shape[0]):
        d[i] = X[i] - W[i]


@numba.njit(cache=True)
def _solve_small(A, b, k, x):  # type: ignore[no-untyped-def]
    """``x[:k]`` solving ``A[:k, :k] x = b[:k]`` (Gaussian elimination, partial pivoting)."""
    M = np.empty((k, k + 1))
    for i in range(k):
        for j in range(k):
            M[i, j] = A[i, j]
        M[i, k] = b[i]
    for c in range(k):
        p = c
        for r in range(c + 1, k):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        if M[p, c] == 0.0:
            for i in range(k):
                x[i] = 0.0
            return
        if p != c:
            for j in range(k + 1):
                t = M[c, j]
                M[c, j] = M[p, j]
                M[p, j] = t
        for r in range(c + 1, k):
            fac = M[r, c] / M[c, c]
            for j in range(c, k + 1):
                M[r, j] -= fac * M[c, j]
    for i in range(k - 1, -1, -1):
        acc = M[i, k]
        for j in range(i + 1, k):
            acc -= M[i, j] * x[j]
        x[i] = acc / M[i, i]


@numba.njit(cache=True)
def no_mixing(it, X, G, dF, dG, gram, fprev, gprev, fcur, gamma, reg):  # type: ignore[no-untyped-def]
    """:func:`anderson`'s place in the driver of a run without Anderson mixing (never called:
    the driver calls it only with a memory)."""


@numba.njit(cache=True)
def anderson(it, X, G, dF, dG, gram, fprev, gprev, fcur, gamma, reg):  # type: ignore[no-untyped-def]
    r"""Anderson mixing (type II): the next iterate into ``X`` from ``X`` and ``G = G(X)``.

    ``it`` is the 1-based iteration; ``dF``, ``dG`` (``(m, S)``) hold the differences of the
    last ``min(m, it - 1)`` residuals and values of ``G``, oldest first (shifted when full),
    ``gram`` their Gram matrix, ``fprev``/``gprev`` the previous residual and ``G``. Solves the
    regularized normal equations ``(A + reg max(diag A) I) gamma = (<dF_j, f>)`` and sets
    :math:`X = G - \sum_j \gamma_j \Delta G_j` (:class:`isoflow.FixedPoint` does the same).
    """
    m = dF.shape[0]
    S = X.shape[0]
    for i in range(S):
        fcur[i] = G[i] - X[i]
    if it == 1:
        copy(fprev, fcur)
        copy(gprev, G)
        copy(X, G)
        return
    k = min(it - 1, m)
    if it - 1 > m:  # drop the oldest pair: shift the history and its Gram matrix
        for j in range(m - 1):
            copy(dF[j], dF[j + 1])
            copy(dG[j], dG[j + 1])
            for i in range(m - 1):
                gram[j, i] = gram[j + 1, i + 1]
    new = k - 1
    dfn = dF[new]
    dgn = dG[new]
    for i in range(S):
        dfn[i] = fcur[i] - fprev[i]
        dgn[i] = G[i] - gprev[i]
    for j in range(k):
        v = rdot(dF[j], dfn)
        gram[j, new] = v
        gram[new, j] = v
    copy(fprev, fcur)
    copy(gprev, G)
    big = 0.0
    for j in range(k):
        big = max(big, gram[j, j])
    if big <= 0.0:
        copy(X, G)
        return
    A = np.empty((k, k))
    b = np.empty(k)
    for j in range(k):
        b[j] = rdot(dF[j], fcur)
        for i in range(k):
            A[j, i] = gram[j, i]
        A[j, j] += reg * big
    _solve_small(A, b, k, gamma)
    for i in range(S):
        acc = G[i]
        for j in range(k):
            acc = acc - gamma[j] * dG[j, i]
        X[i] = acc
