r"""The Cayley update's increment on small dense states (``n <= 16``): the ``cayley_increment``
block of :class:`~isoflow._compiled.dense.DenseSmall` and of the lanes of
:class:`~isoflow._compiled.lanes.ElementwiseLanes`.

As on the BLAS layout (:mod:`isoflow._compiled.cayley`), with ``A = I - h/2 B``:

.. math::

    Y = A^{-1} W, \qquad Z = \big(A^{-1} Y^\dagger\big)^\dagger, \qquad
    D = 4Z - 2Y - 2 s Y^\dagger,

formed on the lower triangle and mirrored (``D[j, i] = s conj(D[i, j])``, the diagonal in
``V``), so that the finish's ``advance_state`` adds an exact mirror. The inverse is
Gauss–Jordan elimination with partial pivoting, written out: LAPACK through numba's
``np.linalg.inv`` costs about a microsecond a call in allocation and dispatch, as much as a
whole iteration of a small member (benchmark 2's so(10) members: 0.6 us a member and
iteration), and a step would call it once a member. ``A = I - K`` with ``K`` skew is normal
with singular values :math:`\sqrt{1 + \lambda^2} \ge 1`, so the elimination is well
conditioned at any step.
"""

from __future__ import annotations

import numba
import numpy as np

from . import blocks
from .dense import DenseSmall
from .lanes import ElementwiseLanes

__all__ = ["member_increment"]


@numba.njit(cache=True, inline="always")
def _invert(A, Ai):  # type: ignore[no-untyped-def]
    """``Ai = A^{-1}`` by Gauss–Jordan elimination with partial pivoting (``A`` is spent)."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            Ai[i, j] = 1.0 if i == j else 0.0
    for c in range(n):
        p = c
        for r in range(c + 1, n):
            if abs(A[r, c]) > abs(A[p, c]):
                p = r
        if p != c:
            for j in range(n):
                t = A[c, j]
                A[c, j] = A[p, j]
                A[p, j] = t
                t = Ai[c, j]
                Ai[c, j] = Ai[p, j]
                Ai[p, j] = t
        inv = 1.0 / A[c, c]
        for j in range(n):
            A[c, j] *= inv
            Ai[c, j] *= inv
        for r in range(n):
            if r != c:
                fac = A[r, c]
                if fac != 0.0:
                    for j in range(n):
                        A[r, j] -= fac * A[c, j]
                        Ai[r, j] -= fac * Ai[c, j]


@numba.njit(cache=True)
def member_increment(s, B, W, half, D, scratch):  # type: ignore[no-untyped-def]
    """``D = C W C^H - W`` for one member (``(n, n)`` arrays), ``C`` the Cayley factor of
    ``half * B``; ``D`` an exact mirror with the sign ``s`` of sigma. ``scratch``: four
    ``(n, n)`` arrays of the state's dtype (``(4, n, n)``), reused across members."""
    n = W.shape[0]
    A = scratch[0]
    Ai = scratch[1]
    Y = scratch[2]
    Z = scratch[3]
    for i in range(n):
        for j in range(n):
            A[i, j] = (1.0 if i == j else 0.0) - half * B[i, j]
    _invert(A, Ai)
    for i in range(n):
        for j in range(n):
            Y[i, j] = 0.0
            Z[i, j] = 0.0
    for i in range(n):
        for k in range(n):
            a = Ai[i, k]
            for j in range(n):
                Y[i, j] += a * W[k, j]
    for i in range(n):  # Z = A^{-1} Y^H
        for k in range(n):
            a = Ai[i, k]
            for j in range(n):
                Z[i, j] += a * np.conj(Y[j, k])
    for i in range(n):
        for j in range(i + 1):
            d = 4.0 * np.conj(Z[j, i]) - 2.0 * Y[i, j] - 2.0 * s * np.conj(Y[j, i])
            if i == j:
                d = 0.5 * (d + s * np.conj(d))  # the diagonal of an element of V
            D[i, j] = d
            if i != j:
                D[j, i] = s * np.conj(d)


@numba.njit(cache=True, inline="always")
def _small_increment(lay, B, W, h, D):  # type: ignore[no-untyped-def]
    n = lay.n
    scratch = np.empty((4, n, n), dtype=W.dtype)
    member_increment(lay.s, B.reshape((n, n)), W.reshape((n, n)), 0.5 * h, D.reshape((n, n)),
                     scratch)  # fmt: skip


@numba.njit(cache=True, inline="always")
def _lanes_increment(lay, B, W, h, D):  # type: ignore[no-untyped-def]
    """Lane by lane: each member gathered from the ``(n, n, L)`` unit, its increment
    scattered back."""
    n, L = lay.n, lay.L
    Bm = B.reshape((n, n, L))
    Wm = W.reshape((n, n, L))
    Dm = D.reshape((n, n, L))
    Bq = np.empty((n, n), dtype=W.dtype)
    Wq = np.empty((n, n), dtype=W.dtype)
    Dq = np.empty((n, n), dtype=W.dtype)
    scratch = np.empty((4, n, n), dtype=W.dtype)
    for q in range(L):
        for i in range(n):
            for j in range(n):
                Bq[i, j] = Bm[i, j, q]
                Wq[i, j] = Wm[i, j, q]
        member_increment(lay.s, Bq, Wq, 0.5 * h, Dq, scratch)
        for i in range(n):
            for j in range(n):
                Dm[i, j, q] = Dq[i, j]


blocks.provide(blocks.cayley_increment, DenseSmall)(_small_increment)
blocks.provide(blocks.cayley_increment, ElementwiseLanes)(_lanes_increment)
