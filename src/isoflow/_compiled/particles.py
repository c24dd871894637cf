r"""Compiled stages on the particle spaces: ``N`` particles in :math:`\mathbb{R}^3`, ``(N, 3)``.

IsoMP on :math:`(\mathbb{R}^3,\times)^N` (:class:`~isoflow.algebras.SpinVectors`) and on
:math:`(\mathbb{R}^3,\times_L)^N` (:class:`~isoflow.algebras.SL2Vectors`, the hyperbolic
midpoint) uses the vector forms of the bracket and of the triple product, per particle with
``b = B_i(X)``, ``x = X_i``:

.. math::

    (C_i, T_i) = \begin{cases}
        \bigl(b \times x,\; -(b\cdot x)\, b\bigr) & (\mathbb{R}^3, \times), \\
        \bigl(-2L(b \times x),\; 2 (b\cdot_L x)\, b - (b\cdot_L b)\, x\bigr)
            & (\mathbb{R}^3, \times_L),
    \end{cases}
    \qquad G_i = w_i + \tfrac h2 C_i + \tfrac{h^2}{4} T_i,

and :math:`w_{k+1} = w + h\,C` (the same formulas as
:meth:`SpinVectors.bracket_and_triple <isoflow.algebras.SpinVectors.bracket_and_triple>` and
:meth:`SL2Vectors.bracket_and_triple <isoflow.algebras.SL2Vectors.bracket_and_triple>`).

The spherical midpoint (:class:`~isoflow.SphericalMidpoint`, on :math:`(\mathbb{R}^3,\times)^N`)
iterates on the plain average ``M``:

.. math::

    m_i = \sqrt{|w_i|\,|2M_i - w_i|}\; M_i/|M_i|, \qquad
    G_i = w_i + \tfrac h2\, B_i(m) \times m_i, \qquad w_{k+1} = w + h\, B(m) \times m .

``B`` is the kernel's ``f(X, B, *args)`` on the ``(N, 3)`` arrays; ``sp = (N,)``. The
interface is that of :mod:`isoflow._compiled.driver`; ``aux`` receives ``C``.
"""

from __future__ import annotations

import math

import numba

__all__ = ["finish", "iterate_sl2", "iterate_smm", "iterate_so3"]


@numba.njit(cache=True)
def iterate_so3(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    """One IsoMP iteration on :math:`(\\mathbb{R}^3,\\times)^N`."""
    N = sp[0]
    Xm = X.reshape((N, 3))
    Bm = work[0].reshape((N, 3))
    f(Xm, Bm, *fargs)
    rr = 0.0
    for i in range(N):
        b0, b1, b2 = Bm[i, 0], Bm[i, 1], Bm[i, 2]
        x0, x1, x2 = Xm[i, 0], Xm[i, 1], Xm[i, 2]
        c0 = b1 * x2 - b2 * x1
        c1 = b2 * x0 - b0 * x2
        c2 = b0 * x1 - b1 * x0
        d = -(b0 * x0 + b1 * x1 + b2 * x2)
        j = 3 * i
        g0 = W[j] + half * c0 + quarter * (d * b0)
        g1 = W[j + 1] + half * c1 + quarter * (d * b1)
        g2 = W[j + 2] + half * c2 + quarter * (d * b2)
        G[j] = g0
        G[j + 1] = g1
        G[j + 2] = g2
        aux[j] = c0
        aux[j + 1] = c1
        aux[j + 2] = c2
        rr += (g0 - x0) ** 2 + (g1 - x1) ** 2 + (g2 - x2) ** 2
    return rr


@numba.njit(cache=True)
def iterate_sl2(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    """One IsoMP iteration on :math:`(\\mathbb{R}^3,\\times_L)^N` (the hyperbolic midpoint)."""
    N = sp[0]
    Xm = X.reshape((N, 3))
    Bm = work[0].reshape((N, 3))
    f(Xm, Bm, *fargs)
    rr = 0.0
    for i in range(N):
        b0, b1, b2 = Bm[i, 0], Bm[i, 1], Bm[i, 2]
        x0, x1, x2 = Xm[i, 0], Xm[i, 1], Xm[i, 2]
        c0 = -2.0 * (b1 * x2 - b2 * x1)
        c1 = -2.0 * (b2 * x0 - b0 * x2)
        c2 = 2.0 * (b0 * x1 - b1 * x0)
        bx = b0 * x0 + b1 * x1 - b2 * x2
        bb = b0 * b0 + b1 * b1 - b2 * b2
        j = 3 * i
        g0 = W[j] + half * c0 + quarter * (2.0 * bx * b0 - bb * x0)
        g1 = W[j + 1] + half * c1 + quarter * (2.0 * bx * b1 - bb * x1)
        g2 = W[j + 2] + half * c2 + quarter * (2.0 * bx * b2 - bb * x2)
        G[j] = g0
        G[j + 1] = g1
        G[j + 2] = g2
        aux[j] = c0
        aux[j + 1] = c1
        aux[j + 2] = c2
        rr += (g0 - x0) ** 2 + (g1 - x1) ** 2 + (g2 - x2) ** 2
    return rr


@numba.njit(cache=True)
def iterate_smm(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    """One spherical-midpoint iteration on the average ``M = X``; ``work[1]`` holds ``m``."""
    N = sp[0]
    Bm = work[0].reshape((N, 3))
    mid = work[1]
    for i in range(N):
        j = 3 * i
        w0, w1, w2 = W[j], W[j + 1], W[j + 2]
        a0, a1, a2 = X[j], X[j + 1], X[j + 2]
        nw = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        v0, v1, v2 = 2.0 * a0 - w0, 2.0 * a1 - w1, 2.0 * a2 - w2
        nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        nm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        fac = math.sqrt(nw * nv) / nm if nm > 0 else 0.0
        mid[j] = fac * a0
        mid[j + 1] = fac * a1
        mid[j + 2] = fac * a2
    Mm = mid.reshape((N, 3))
    f(Mm, Bm, *fargs)
    rr = 0.0
    for i in range(N):
        b0, b1, b2 = Bm[i, 0], Bm[i, 1], Bm[i, 2]
        m0, m1, m2 = Mm[i, 0], Mm[i, 1], Mm[i, 2]
        c0 = b1 * m2 - b2 * m1
        c1 = b2 * m0 - b0 * m2
        c2 = b0 * m1 - b1 * m0
        j = 3 * i
        g0 = W[j] + half * c0
        g1 = W[j + 1] + half * c1
        g2 = W[j + 2] + half * c2
        G[j] = g0
        G[j + 1] = g1
        G[j + 2] = g2
        aux[j] = c0
        aux[j + 1] = c1
        aux[j + 2] = c2
        rr += (g0 - X[j]) ** 2 + (g1 - X[j + 1]) ** 2 + (g2 - X[j + 2]) ** 2
    return rr


@numba.njit(cache=True)
def finish(f, fargs, sp, W, X, aux, work, h, Wn):  # type: ignore[no-untyped-def]
    """``Wn = W + h C`` (every real ``(N, 3)`` array lies in the space); returns finiteness."""
    acc = 0.0
    for i in range(W.shape[0]):
        v = W[i] + h * aux[i]
        Wn[i] = v
        acc += abs(v)
    return math.isfinite(acc)
