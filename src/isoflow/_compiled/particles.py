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


@numba.njit(cache=True, inline="always")
def _so3(b0, b1, b2, x0, x1, x2):  # type: ignore[no-untyped-def]
    r"""``(C, T)`` on :math:`(\mathbb{R}^3,\times)`: ``b x x`` and ``-(b . x) b``."""
    d = -(b0 * x0 + b1 * x1 + b2 * x2)
    return (
        b1 * x2 - b2 * x1, b2 * x0 - b0 * x2, b0 * x1 - b1 * x0,
        d * b0, d * b1, d * b2,
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def _sl2(b0, b1, b2, x0, x1, x2):  # type: ignore[no-untyped-def]
    r"""``(C, T)`` on :math:`(\mathbb{R}^3,\times_L)`: ``-2L(b x x)`` and
    ``2 (b ._L x) b - (b ._L b) x``."""
    bx = b0 * x0 + b1 * x1 - b2 * x2
    bb = b0 * b0 + b1 * b1 - b2 * b2
    return (
        -2.0 * (b1 * x2 - b2 * x1), -2.0 * (b2 * x0 - b0 * x2), 2.0 * (b0 * x1 - b1 * x0),
        2.0 * bx * b0 - bb * x0, 2.0 * bx * b1 - bb * x1, 2.0 * bx * b2 - bb * x2,
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def _put(W, G, aux, j, c0, c1, c2, g0, g1, g2, x0, x1, x2):  # type: ignore[no-untyped-def]
    """Store ``G`` and ``C`` of particle ``j // 3``; its contribution to ``|G - X|^2``."""
    G[j] = g0
    G[j + 1] = g1
    G[j + 2] = g2
    aux[j] = c0
    aux[j + 1] = c1
    aux[j + 2] = c2
    return (g0 - x0) ** 2 + (g1 - x1) ** 2 + (g2 - x2) ** 2


@numba.njit(cache=True, inline="always")
def _isomp(form, f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    """One IsoMP iteration with the products ``form`` (:func:`_so3` or :func:`_sl2`)."""
    N = sp[0]
    Xm = X.reshape((N, 3))
    Bm = work[0].reshape((N, 3))
    f(Xm, Bm, *fargs)
    rr = 0.0
    for i in range(N):
        x0, x1, x2 = Xm[i, 0], Xm[i, 1], Xm[i, 2]
        c0, c1, c2, t0, t1, t2 = form(Bm[i, 0], Bm[i, 1], Bm[i, 2], x0, x1, x2)
        j = 3 * i
        g0 = W[j] + half * c0 + quarter * t0
        g1 = W[j + 1] + half * c1 + quarter * t1
        g2 = W[j + 2] + half * c2 + quarter * t2
        rr += _put(W, G, aux, j, c0, c1, c2, g0, g1, g2, x0, x1, x2)
    return rr


@numba.njit(cache=True)
def iterate_so3(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    r"""One IsoMP iteration on :math:`(\mathbb{R}^3,\times)^N`."""
    return _isomp(_so3, f, fargs, sp, W, X, G, aux, work, half, quarter)


@numba.njit(cache=True)
def iterate_sl2(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    r"""One IsoMP iteration on :math:`(\mathbb{R}^3,\times_L)^N` (the hyperbolic midpoint)."""
    return _isomp(_sl2, f, fargs, sp, W, X, G, aux, work, half, quarter)


@numba.njit(cache=True, inline="always")
def spherical_factor(w0, w1, w2, a0, a1, a2):  # type: ignore[no-untyped-def]
    """The factor ``sqrt(|w| |2a - w|) / |a|`` that puts the midpoint ``a`` of ``w`` on the
    spherical midpoint's sphere (``0`` where ``a = 0``)."""
    nw = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    v0, v1, v2 = 2.0 * a0 - w0, 2.0 * a1 - w1, 2.0 * a2 - w2
    nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    nm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    return math.sqrt(nw * nv) / nm if nm > 0 else 0.0


@numba.njit(cache=True, inline="always")
def spherical_point(W, M, mid, N):  # type: ignore[no-untyped-def]
    """``mid_i = sqrt(|w_i| |2M_i - w_i|) M_i / |M_i|`` (``0`` where ``M_i = 0``), flat."""
    for i in range(N):
        j = 3 * i
        w0, w1, w2 = W[j], W[j + 1], W[j + 2]
        a0, a1, a2 = M[j], M[j + 1], M[j + 2]
        fac = spherical_factor(w0, w1, w2, a0, a1, a2)
        mid[j] = fac * a0
        mid[j + 1] = fac * a1
        mid[j + 2] = fac * a2


@numba.njit(cache=True, inline="always")
def smm_update(W, X, G, aux, B, mid, N, half):  # type: ignore[no-untyped-def]
    """``C = B x m``, ``G = W + h/2 C`` from the field ``B`` at the points ``mid`` (flat);
    returns ``|G - X|^2``."""
    rr = 0.0
    for i in range(N):
        j = 3 * i
        m0, m1, m2 = mid[j], mid[j + 1], mid[j + 2]
        b0, b1, b2 = B[j], B[j + 1], B[j + 2]
        c0 = b1 * m2 - b2 * m1
        c1 = b2 * m0 - b0 * m2
        c2 = b0 * m1 - b1 * m0
        g0 = W[j] + half * c0
        g1 = W[j + 1] + half * c1
        g2 = W[j + 2] + half * c2
        rr += _put(W, G, aux, j, c0, c1, c2, g0, g1, g2, X[j], X[j + 1], X[j + 2])
    return rr


@numba.njit(cache=True)
def iterate_smm(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    """One spherical-midpoint iteration on the average ``M = X``; ``work[1]`` holds ``m``."""
    N = sp[0]
    mid = work[1]
    spherical_point(W, X, mid, N)
    f(mid.reshape((N, 3)), work[0].reshape((N, 3)), *fargs)
    return smm_update(W, X, G, aux, work[0], mid, N, half)


@numba.njit(cache=True)
def finish(f, fargs, sp, W, X, aux, work, h, Wn):  # type: ignore[no-untyped-def]
    """``Wn = W + h C`` (every real ``(N, 3)`` array lies in the space); returns finiteness."""
    acc = 0.0
    for i in range(W.shape[0]):
        v = W[i] + h * aux[i]
        Wn[i] = v
        acc += abs(v)
    return math.isfinite(acc)
