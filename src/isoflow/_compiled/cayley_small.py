r"""The Cayley update's increment on small dense states (``n <= 16``): the ``cayley_increment``
block of :class:`~isoflow._compiled.dense.DenseSmall` and of the lanes of
:class:`~isoflow._compiled.lanes.ElementwiseLanes`.

As on the BLAS layout (:mod:`isoflow._compiled.cayley`), with ``A = I - h/2 B``:

.. math::

    Y = A^{-1} W, \qquad Z = \big(A^{-1} Y^\dagger\big)^\dagger, \qquad
    D = 4Z - 2Y - 2 s Y^\dagger,

formed on the lower triangle and mirrored (``D[j, i] = s conj(D[i, j])``, the diagonal in
``V``), so that the finish's ``advance_state`` adds an exact mirror. The inverse is Gauss–Jordan
elimination with partial pivoting, written out, on all the members of a unit at once (each lane
picks its own pivot rows; the eliminations run with the lanes innermost, as every loop of
:mod:`isoflow._compiled.lanes`): LAPACK through numba's ``np.linalg.inv`` costs about a
microsecond a call in allocation and dispatch, as much as a whole iteration of a small member
(benchmark 2's so(10) members: 0.6 us a member and iteration), and a step would call it once a
member. ``A = I - K`` with ``K`` skew is normal with singular values :math:`\sqrt{1 +
\lambda^2} \ge 1`, so it is well conditioned at the steps a solve converges at
(:math:`h\|B\|_2 \lesssim 3`); ``tests/test_cayley_update.py`` checks the increment against
LAPACK's inverse up to :math:`\|\tfrac h2 B\|_2 = 10^3`.
"""

from __future__ import annotations

import numba
import numpy as np

from . import blocks
from .dense import DenseSmall
from .lanes import ElementwiseLanes

__all__ = ["unit_increment"]


@numba.njit(cache=True, inline="always")
def _invert(A, Ai):  # type: ignore[no-untyped-def]
    """``Ai = A^{-1}`` lane by lane (``(n, n, L)``) by Gauss–Jordan elimination with partial
    pivoting, each lane its own pivot rows (the eliminations run over all lanes at once);
    ``A`` is spent."""
    n, L = A.shape[0], A.shape[2]
    for i in range(n):
        for j in range(n):
            for q in range(L):
                Ai[i, j, q] = 1.0 if i == j else 0.0
    fac = np.empty(L, dtype=A.dtype)
    for c in range(n):
        for q in range(L):
            p = c
            for r in range(c + 1, n):
                if abs(A[r, c, q]) > abs(A[p, c, q]):
                    p = r
            if p != c:
                for j in range(n):
                    t = A[c, j, q]
                    A[c, j, q] = A[p, j, q]
                    A[p, j, q] = t
                    t = Ai[c, j, q]
                    Ai[c, j, q] = Ai[p, j, q]
                    Ai[p, j, q] = t
            fac[q] = 1.0 / A[c, c, q]
        for j in range(n):
            for q in range(L):
                A[c, j, q] *= fac[q]
                Ai[c, j, q] *= fac[q]
        for r in range(n):
            if r == c:
                continue
            for q in range(L):
                fac[q] = A[r, c, q]
            for j in range(n):
                for q in range(L):
                    A[r, j, q] -= fac[q] * A[c, j, q]
                    Ai[r, j, q] -= fac[q] * Ai[c, j, q]


@numba.njit(cache=True)
def unit_increment(s, B, W, half, D, scratch):  # type: ignore[no-untyped-def]
    """``D = C W C^H - W`` for the ``L`` members of a unit (``(n, n, L)`` views), ``C`` the
    Cayley factor of ``half * B``; ``D`` exact mirrors with the sign ``s`` of sigma.
    ``scratch``: ``(4, n, n, L)`` of the state's dtype."""
    n, L = W.shape[0], W.shape[2]
    A = scratch[0]
    Ai = scratch[1]
    Y = scratch[2]
    Z = scratch[3]
    for i in range(n):
        for j in range(n):
            e = 1.0 if i == j else 0.0
            for q in range(L):
                A[i, j, q] = e - half * B[i, j, q]
                Y[i, j, q] = 0.0
                Z[i, j, q] = 0.0
    _invert(A, Ai)
    for i in range(n):
        for k in range(n):
            for j in range(n):
                for q in range(L):
                    Y[i, j, q] += Ai[i, k, q] * W[k, j, q]
    for i in range(n):  # Z = A^{-1} Y^H
        for k in range(n):
            for j in range(n):
                for q in range(L):
                    Z[i, j, q] += Ai[i, k, q] * np.conj(Y[j, k, q])
    for i in range(n):
        for j in range(i + 1):
            for q in range(L):
                d = 4.0 * np.conj(Z[j, i, q]) - 2.0 * Y[i, j, q] - 2.0 * s * np.conj(Y[j, i, q])
                if i == j:
                    d = 0.5 * (d + s * np.conj(d))  # the diagonal of an element of V
                D[i, j, q] = d
                if i != j:
                    D[j, i, q] = s * np.conj(d)


@numba.njit(cache=True, inline="always")
def _increment(lay, B, W, h, D):  # type: ignore[no-untyped-def]
    """The block: the unit's ``L`` members (``1`` on the small dense layout) at once."""
    n = lay.n
    L = blocks.lanes(lay)
    scratch = np.empty((4, n, n, L), dtype=W.dtype)
    shape = (n, n, L)
    unit_increment(lay.s, B.reshape(shape), W.reshape(shape), 0.5 * h, D.reshape(shape),
                   scratch)  # fmt: skip


blocks.provide(blocks.cayley_increment, DenseSmall, ElementwiseLanes)(_increment)
