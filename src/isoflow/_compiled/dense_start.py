r"""The extrapolated start of a dense BLAS state from the lower triangle of its offsets.

The start :math:`X^{(0)} = W + \sum_q a_q D_q` (:func:`isoflow._compiled.flat.guess`) streams
every stored offset :math:`D_q = X_q - W_q` from memory once a step: at ``n = 512`` with the
fitted start's 16 offsets 64 MB, about a sixth of a step's time with one thread. On the dense
spaces every state and offset is an exact mirror, :math:`Y_{ji} = s\,\bar Y_{ij}` (``s`` the
sign of the space's involution, :class:`~isoflow._compiled.dense.DenseBlas`), since the
stage map and the update write each entry and its mirror through the same operations
(:mod:`isoflow._compiled.flat`). The start is formed here on the lower triangle, row segment
by row segment with :func:`~isoflow._compiled.flat.guess_range`, and mirrored: every entry
goes through the operations :func:`~isoflow._compiled.flat.guess` would apply, and the
upper triangle is the mirror that sum would have produced, so the start is the same to the
last bit while half the offsets' memory is read (``tests/test_dense_start.py``). The
fallback's check (:func:`~isoflow._compiled.flat.guess_or_fit`) measures its miss on the
lower triangle, off-diagonal entries twice, first on one row pair in :data:`FIRST_SHARE`:
where that part alone surely passes the limit, the fit is taken without the rest of the
check (the same decision). Where the offsets read fit in cache (below
:data:`LOWER_MIN_BYTES`) the flat functions run instead (:func:`start_for` chooses once per
run; the driver takes the start as a function value, so that other runs do not compile
this module's threaded pieces).

On a ``threaded`` record the rows go to numba threads in pairs ``(k, n - 1 - k)`` of equal
length together; each pair's part of the miss is kept apart and the parts are added in
order, so the start and the decision do not depend on the thread count.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from .dense import DenseBlas
from .flat import guess_range, miss_range, start

__all__ = [
    "FIRST_SHARE",
    "LOWER_MIN_BYTES",
    "SURELY_PAST",
    "first_pairs",
    "lower_start",
    "start_for",
    "start_lower",
    "start_or_fit_lower",
]

#: The lower triangle is read when the offsets a start reads take at least this many bytes;
#: below, they stay in cache, and :mod:`isoflow._compiled.flat`'s single pass is faster than
#: the rows and the mirror (``so(512)``'s interpolating start on 7 offsets, 14 MB: 3-6 % a
#: step slower by rows). Either way the start is the same to the last bit.
LOWER_MIN_BYTES = 32 * 2**20
#: :func:`start_or_fit_lower` measures the fallback's miss on one in this many row pairs
#: first, and takes the fit at once if that part passes the limit.
FIRST_SHARE = 16
#: A part of the miss that passes ``limit**2`` by this factor passes it whatever the sum the
#: rest adds it into: ``m`` non-negative terms summed in any order are within
#: ``m u / (1 - m u)`` (``u = 2**-53``) of their exact sum, below ``1e-9`` for any ``n``
#: that fits in memory.
SURELY_PAST = 1.0 + 1e-6
#: Side of the square tiles the upper triangle is mirrored in.
_MIRROR_TILE = 32


# The pieces below are compiled functions of their own, not inlined: the parallel loops'
# bodies stay one call each (numba's parallel lowering of the written-out sums took a
# minute), and each piece compiles once per dtype for every layout and run.


@numba.njit(cache=True)
def _mirror_rows(X, n, s, i0, i1):  # type: ignore[no-untyped-def]
    """``X[j, i] = s conj(X[i, j])`` for ``i0 <= i < i1`` and ``j < i``, tile by tile."""
    T = _MIRROR_TILE
    for r0 in range(i0, i1, T):
        r1 = min(r0 + T, i1)
        for c0 in range(0, r1, T):
            for i in range(r0, r1):
                for j in range(c0, min(c0 + T, i)):
                    X[j * n + i] = s * np.conj(X[i * n + j])


@numba.njit(cache=True)
def _range_start(W, ring, head, nh, coefs, X, a, b):  # type: ignore[no-untyped-def]
    guess_range(W, ring, head, nh, coefs, X, a, b)


@numba.njit(cache=True)
def _pair_start(W, ring, head, nh, coefs, X, n, k):  # type: ignore[no-untyped-def]
    """The start on the lower parts of rows ``k`` and ``n - 1 - k`` (as long together as
    any other pair)."""
    _range_start(W, ring, head, nh, coefs, X, k * n, k * n + k + 1)
    i = n - 1 - k
    if i != k:
        _range_start(W, ring, head, nh, coefs, X, i * n, i * n + i + 1)


@numba.njit(cache=True)
def _row_miss(W, ring, head, kint, c, X, n, i, ebuf):  # type: ignore[no-untyped-def]
    """The interpolating start on the lower part of row ``i`` and its miss there, the
    entries left of the diagonal counted twice (their mirrors); ``ebuf`` scratch of length
    ``n``."""
    off = miss_range(W, ring, head, kint, c, X, i * n, i * n + i, ebuf)
    return 2.0 * off + miss_range(W, ring, head, kint, c, X, i * n + i, i * n + i + 1, ebuf)


@numba.njit(cache=True)
def _pair_miss(W, ring, head, kint, c, X, n, k, ebuf):  # type: ignore[no-untyped-def]
    """:func:`_row_miss` on rows ``k`` and ``n - 1 - k``, their misses added."""
    acc = _row_miss(W, ring, head, kint, c, X, n, k, ebuf)
    if n - 1 - k != k:
        acc += _row_miss(W, ring, head, kint, c, X, n, n - 1 - k, ebuf)
    return acc


@numba.njit(cache=True, parallel=True)
def _pairs_threaded(W, ring, head, nh, coefs, kint, X, n, parts, k0, k1):  # type: ignore[no-untyped-def]
    """The row pairs ``k0 <= k < k1`` over numba threads: the start when ``kint == 0``, else
    the interpolating start on ``kint`` offsets with each pair's miss in ``parts[k]``."""
    c = coefs[coefs.shape[0] - 1]
    for t in numba.prange(k1 - k0):
        k = k0 + t
        if kint == 0:
            _pair_start(W, ring, head, nh, coefs, X, n, k)
        else:
            parts[k] = _pair_miss(W, ring, head, kint, c, X, n, k, np.empty(n, dtype=X.dtype))


@numba.njit(cache=True)
def _miss_parts(W, ring, head, kint, coefs, X, n, threaded, parts, k0, k1):  # type: ignore[no-untyped-def]
    """The interpolating start on row pairs ``k0 <= k < k1`` and their misses in
    ``parts[k]`` (over numba threads if ``threaded``)."""
    if threaded:
        _pairs_threaded(W, ring, head, 0, coefs, kint, X, n, parts, k0, k1)
        return
    c = coefs[coefs.shape[0] - 1]
    ebuf = np.empty(n, dtype=X.dtype)
    for k in range(k0, k1):
        parts[k] = _pair_miss(W, ring, head, kint, c, X, n, k, ebuf)


@numba.njit(cache=True, parallel=True)
def _mirror_threaded(X, n, s):  # type: ignore[no-untyped-def]
    """:func:`_mirror_rows` by pairs of tile rows (of equal work together) over numba
    threads."""
    T = _MIRROR_TILE
    nt = (n + T - 1) // T
    for k in numba.prange((nt + 1) // 2):
        _mirror_rows(X, n, s, k * T, min(n, (k + 1) * T))
        k2 = nt - 1 - k
        if k2 != k:
            _mirror_rows(X, n, s, k2 * T, min(n, (k2 + 1) * T))


@numba.njit(cache=True)
def _mirror(X, n, s, threaded):  # type: ignore[no-untyped-def]
    if threaded:
        _mirror_threaded(X, n, s)
    else:
        _mirror_rows(X, n, s, 0, n)


@numba.njit(cache=True)
def start_lower(W, ring, head, nh, coefs, X, n, s, threaded):  # type: ignore[no-untyped-def]
    """:func:`isoflow._compiled.flat.guess` on an ``n x n`` state from the lower triangle
    and the mirror ``X[j, i] = s conj(X[i, j])`` (row pairs over numba threads if
    ``threaded``)."""
    if threaded:
        _pairs_threaded(W, ring, head, nh, coefs, 0, X, n, np.empty(0), 0, (n + 1) // 2)
    else:
        for k in range((n + 1) // 2):
            _pair_start(W, ring, head, nh, coefs, X, n, k)
    _mirror(X, n, s, threaded)


@numba.njit(cache=True)
def start_or_fit_lower(W, ring, head, nh, coefs, kint, limit, X, n, s, threaded):  # type: ignore[no-untyped-def]
    """:func:`isoflow._compiled.flat.guess_or_fit` on an ``n x n`` state from the lower
    triangle (the miss over it, off-diagonal entries twice, added pair by pair in order
    whatever the threads): the same start, and the same decision but where the miss lies
    within rounding of ``limit``.

    The last :func:`first_pairs` row pairs (the rows about the middle) are measured first:
    the parts are squared sizes, so where their sum passes ``limit**2`` by more than the
    rounding of any sum of the parts (:data:`SURELY_PAST`), the sum of all of them in order
    does too, and the fit is formed without measuring the rest (Euler on the sphere, which
    takes the fit at every step and misses most about the middle rows, then reads the
    fallback's offsets a sixteenth of the way instead of all of it)."""
    npair = (n + 1) // 2
    parts = np.empty(npair)
    k1 = npair - first_pairs(n)
    _miss_parts(W, ring, head, kint, coefs, X, n, threaded, parts, k1, npair)
    some = 0.0
    for k in range(k1, npair):
        some += parts[k]
    limit2 = limit * limit
    if not some > SURELY_PAST * limit2:
        _miss_parts(W, ring, head, kint, coefs, X, n, threaded, parts, 0, k1)
        miss2 = 0.0
        for k in range(npair):
            miss2 += parts[k]
        if miss2 <= limit2:
            _mirror(X, n, s, threaded)
            return True
    start_lower(W, ring, head, nh, coefs, X, n, s, threaded)
    return False


@numba.njit(cache=True)
def first_pairs(n):  # type: ignore[no-untyped-def]
    """How many row pairs :func:`start_or_fit_lower` measures first: one in
    :data:`FIRST_SHARE` of the ``(n + 1) // 2``, at least one."""
    return max(1, ((n + 1) // 2) // FIRST_SHARE)


@numba.njit(cache=True)
def lower_start(lay, W, ring, head, nh, coefs, kint, limit, X):  # type: ignore[no-untyped-def]
    """The driver's start on a :class:`~isoflow._compiled.dense.DenseBlas` state (the
    signature of :func:`isoflow._compiled.flat.start`, the same start): from the lower
    triangle, over numba threads on a ``threaded`` record."""
    if kint > 0 and nh > kint:
        return start_or_fit_lower(
            W, ring, head, nh, coefs, kint, limit, X, lay.n, lay.s, lay.threaded
        )
    start_lower(W, ring, head, nh, coefs, X, lay.n, lay.s, lay.threaded)
    return False


def start_for(lay: Any, W: Any, kmax: int, kint: int) -> Any:
    """The start function of a run on the layout record ``lay`` with units ``W`` (``(U, S)``),
    ``kmax`` stored offsets and the fallback ``kint``: :func:`lower_start` on a dense BLAS
    state whose start reads at least :data:`LOWER_MIN_BYTES` (the fallback's check's
    ``kint + 1`` offsets, else ``kmax``), else :func:`isoflow._compiled.flat.start`."""
    reads = (kint + 1 if kint else kmax) * W.shape[-1] * W.itemsize
    if isinstance(lay, DenseBlas) and reads >= LOWER_MIN_BYTES:
        return lower_start
    return start
