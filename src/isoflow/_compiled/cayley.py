r"""IsoMP's Cayley update on :class:`~isoflow._compiled.dense.DenseBlas` states, and on the
layouts that provide the ``cayley_increment`` block (:func:`finish_blocks`: particles on
:math:`(\mathbb{R}^3,\times)^N`, where the factor is a rotation per particle).

The finish of ``IsoMP(update="cayley")`` (:mod:`isoflow.methods.isomp`, "The Cayley update"):
with ``A = I - h/2 B`` for the ``B`` of the accepted stage, left in the scratch rows by the last
iteration,

.. math::

    Y = A^{-1} W, \qquad Z = \big(A^{-1} Y^\dagger\big)^\dagger, \qquad
    W_{k+1} = W + 4Z - 2Y - 2 s Y^\dagger,

``s`` the sign of the space's involution (``W^\dagger = s W``: ``-1`` on skew, ``+1`` on
Hermitian states). The increment is mirrored into ``V`` from its lower triangle and added
with the compensation ``E`` (unless empty) as the midpoint finish adds its own
(:func:`isoflow._compiled.dense_tiles.finish`), so every state lies in ``V`` to the last bit
and the trace is removed on ``su(n)``.

:math:`A^{-1}` is formed once (numba's ``np.linalg.inv``: LAPACK's LU and inverse, in the
library the BLAS layout calls) and applied by two products: 1.43 ms against 1.84 for two
solves with ``n`` right-hand sides at ``n = 128`` (complex, one thread; 10.6 against 12.6 ms
at ``n = 256``), since LAPACK's triangular solves run well below the product's speed at these
sizes. ``A = I - K`` with ``K = h/2 B`` skew-Hermitian, so normal with imaginary eigenvalues
:math:`i\lambda`: the singular values of ``A`` are :math:`\sqrt{1 + \lambda^2} \ge 1` and
:math:`\kappa_2(A) = \sqrt{1 + \|K\|_2^2}`, whatever the step, and the inverse is as
accurate as the solves.
"""

from __future__ import annotations

import numba
import numpy as np

from . import blocks
from .dense_planar import _planes
from .dense_tiles import close_update
from .flat import two_sum

__all__ = ["finish_blocks", "finish_planar", "finish_tiles"]


@numba.njit(cache=True)
def _cayley_update(lay, B, W, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = W + C W C^H - W`` for the ``(n, n)`` field ``B`` (module docstring)."""
    n = lay.n
    s = lay.s
    Wm = W.reshape((n, n))
    Wo = Wn.reshape((n, n))
    compensated = E.shape[0] != 0
    Em = E.reshape((n, n)) if compensated else E.reshape((0, 0))
    A = -0.5 * hp * B
    for i in range(n):
        A[i, i] += 1.0
    Ai = np.linalg.inv(A)  # A = I - K with ||K|| < 1: well conditioned (module docstring)
    Y = np.dot(Ai, Wm)
    Z = np.dot(Ai, np.ascontiguousarray(np.conj(Y.T)))
    acc = 0.0
    for i in range(n):
        for j in range(i + 1):
            d = 4.0 * np.conj(Z[j, i]) - 2.0 * Y[i, j] - 2.0 * s * np.conj(Y[j, i])
            if i == j:
                d = 0.5 * (d + s * np.conj(d))  # the diagonal of an element of V
            if compensated:
                v, e = two_sum(Wm[i, j], d + Em[i, j])
                Em[i, j] = e
                if i != j:
                    Em[j, i] = s * np.conj(e)
            else:
                v = Wm[i, j] + d
            Wo[i, j] = v
            if i != j:
                Wo[j, i] = s * np.conj(v)
            acc += abs(v.real) + abs(v.imag)
    close_update(lay, Wn, E, acc, fin)


@numba.njit(cache=True)
def finish_tiles(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """The Cayley update after :func:`isoflow._compiled.dense_tiles.iterate` (``B`` is
    ``work[0]``)."""
    n = lay.n
    _cayley_update(lay, work[0].reshape((n, n)).copy(), W, hp, E, Wn, fin)


@numba.njit(cache=True)
def finish_planar(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """The Cayley update after :func:`isoflow._compiled.dense_planar.iterate` (``B``'s real
    and imaginary planes are ``work[1]``)."""
    n = lay.n
    Br, Bi = _planes(work[1], n)
    B = np.empty((n, n), dtype=np.complex128)
    for i in range(n):
        for j in range(n):
            B[i, j] = complex(Br[i, j], Bi[i, j])
    _cayley_update(lay, B, W, hp, E, Wn, fin)


@numba.njit(cache=True)
def finish_blocks(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """The Cayley update after a generic iteration (``B`` of the accepted stage in
    ``work[0]``, ``work[1]`` spent): the increment by the layout's ``cayley_increment`` block
    into ``work[1]``, added by its ``advance_state`` with step 1 (compensated as the midpoint
    finish is)."""
    D = work[1]
    blocks.cayley_increment(lay, work[0], W, hp, D)
    blocks.advance_state(lay, W, 1.0, D, E, Wn, fin)
