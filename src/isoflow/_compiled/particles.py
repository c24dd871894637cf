r"""The particle layouts: ``N`` particles in :math:`\mathbb{R}^3`, an ``(N, 3)`` array.

On :math:`(\mathbb{R}^3,\times)^N` (:class:`~isoflow.algebras.SpinVectors`, record
:class:`Particles3`) and :math:`(\mathbb{R}^3,\times_L)^N` (:class:`~isoflow.algebras.SL2Vectors`,
record :class:`ParticlesL`) the bracket and the triple product act per particle, with
``b = B_i(X)``, ``x = X_i``:

.. math::

    (C_i, T_i) = \begin{cases}
        \bigl(b \times x,\; -(b\cdot x)\, b\bigr) & (\mathbb{R}^3, \times), \\
        \bigl(-2L(b \times x),\; 2 (b\cdot_L x)\, b - (b\cdot_L b)\, x\bigr)
            & (\mathbb{R}^3, \times_L),
    \end{cases}

the formulas of :meth:`SpinVectors.bracket_and_triple
<isoflow.algebras.SpinVectors.bracket_and_triple>` and :meth:`SL2Vectors.bracket_and_triple
<isoflow.algebras.SL2Vectors.bracket_and_triple>`. Every real ``(N, 3)`` array lies in these
spaces: no projection. The spherical midpoint's point of a particle (on
:math:`(\mathbb{R}^3,\times)` only) is :math:`m_i = \sqrt{|w_i|\,|2M_i - w_i|}\; M_i/|M_i|`.

The per-particle formulas (:func:`so3_forms`, :func:`sl2_forms`, :func:`spherical_factor`) are
shared with the point-vortex and spin-chain layouts, so every layout gives the same iterates.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba
import numpy as np

from ..algebras import SL2Vectors, SpinVectors
from . import blocks
from .flat import two_sum
from .layout import Layout, member_layout

__all__ = [
    "Particles3",
    "ParticlesL",
    "particle_layout",
    "sl2_forms",
    "so3_cayley",
    "so3_forms",
    "so3_stage",
    "spherical_factor",
]


class Particles3(NamedTuple):
    r""":math:`(\mathbb{R}^3,\times)^N`, the kernel's field."""

    N: int


class ParticlesL(NamedTuple):
    r""":math:`(\mathbb{R}^3,\times_L)^N`, the kernel's field."""

    N: int


@numba.njit(cache=True, inline="always")
def so3_forms(b0, b1, b2, x0, x1, x2):  # type: ignore[no-untyped-def]
    r"""``(C, T)`` on :math:`(\mathbb{R}^3,\times)`: ``b x x`` and ``-(b . x) b``."""
    d = -(b0 * x0 + b1 * x1 + b2 * x2)
    return (
        b1 * x2 - b2 * x1, b2 * x0 - b0 * x2, b0 * x1 - b1 * x0,
        d * b0, d * b1, d * b2,
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def so3_cayley(b0, b1, b2, w0, w1, w2, half):  # type: ignore[no-untyped-def]
    r"""The Cayley rotation's increment :math:`C w - w` on :math:`(\mathbb{R}^3,\times)`,
    :math:`C = (I - \hat u)^{-1}(I + \hat u)` with :math:`u = \tfrac h2 b` (``half`` is
    :math:`\tfrac h2`): :math:`\tfrac{2}{1 + |u|^2}\,(u \times w + u \times (u \times w))`,
    without the cancellation of ``C w - w``. ``C`` is a rotation, so ``|w|`` is kept."""
    u0, u1, u2 = half * b0, half * b1, half * b2
    c0, c1, c2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
    k = np.divide(2.0, 1.0 + (u0 * u0 + u1 * u1 + u2 * u2))  # no zero check: see so3_stage
    return (
        k * (c0 + (u1 * c2 - u2 * c1)),
        k * (c1 + (u2 * c0 - u0 * c2)),
        k * (c2 + (u0 * c1 - u1 * c0)),
    )


@numba.njit(cache=True, inline="always")
def so3_stage(b0, b1, b2, w0, w1, w2, half):  # type: ignore[no-untyped-def]
    r"""IsoMP's stage of one particle on :math:`(\mathbb{R}^3,\times)` for the field ``b``, in
    closed form, and the bracket the finish adds: ``(g, b x g)``.

    The stage equation :math:`w = (I - \hat u)\,\hat g\,(I + \hat u)`, :math:`u = \tfrac h2 b`
    (``half`` is :math:`\tfrac h2`), reads :math:`w = g - u \times g + (u \cdot g)\, u` in
    vector form, a linear map whose inverse is :math:`(I + \hat u) / (1 + |u|^2)`:

    .. math::

        g = \frac{w + u \times w}{1 + |u|^2}, \qquad
        w + h\, b \times g = w + \frac{2}{1 + |u|^2}\,\big(u \times w + u \times (u \times w)\big),

    the Cayley rotation of ``w`` (:func:`so3_cayley`): whatever ``b``, the step's finish
    :math:`w + h\,b \times g` keeps :math:`|w|`."""
    u0, u1, u2 = half * b0, half * b1, half * b2
    # numpy's division: no zero check (``1 + |u|^2 >= 1``), which would keep loops scalar
    k = np.divide(1.0, 1.0 + (u0 * u0 + u1 * u1 + u2 * u2))
    g0 = k * (w0 + (u1 * w2 - u2 * w1))
    g1 = k * (w1 + (u2 * w0 - u0 * w2))
    g2 = k * (w2 + (u0 * w1 - u1 * w0))
    return g0, g1, g2, b1 * g2 - b2 * g1, b2 * g0 - b0 * g2, b0 * g1 - b1 * g0


@numba.njit(cache=True, inline="always")
def sl2_forms(b0, b1, b2, x0, x1, x2):  # type: ignore[no-untyped-def]
    r"""``(C, T)`` on :math:`(\mathbb{R}^3,\times_L)`: ``-2L(b x x)`` and
    ``2 (b ._L x) b - (b ._L b) x``."""
    bx = b0 * x0 + b1 * x1 - b2 * x2
    bb = b0 * b0 + b1 * b1 - b2 * b2
    return (
        -2.0 * (b1 * x2 - b2 * x1), -2.0 * (b2 * x0 - b0 * x2), 2.0 * (b0 * x1 - b1 * x0),
        2.0 * bx * b0 - bb * x0, 2.0 * bx * b1 - bb * x1, 2.0 * bx * b2 - bb * x2,
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def spherical_factor(w0, w1, w2, a0, a1, a2):  # type: ignore[no-untyped-def]
    """The factor ``sqrt(|w| |2a - w|) / |a|`` that puts the midpoint ``a`` of ``w`` on the
    spherical midpoint's sphere (``0`` where ``a = 0``)."""
    nw = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    v0, v1, v2 = 2.0 * a0 - w0, 2.0 * a1 - w1, 2.0 * a2 - w2
    nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    nm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    return math.sqrt(nw * nv) / nm if nm > 0 else 0.0


# ---- blocks (flat (N, 3) arrays: particle i at 3i, 3i+1, 3i+2) --------------------------------


@numba.njit(cache=True, inline="always")
def _evaluate_B(lay, f, fargs, X, B):  # type: ignore[no-untyped-def]
    N = lay.N
    f(X.reshape((N, 3)), B.reshape((N, 3)), *fargs)


@numba.njit(cache=True, inline="always")
def _forms_into(form, N, B, X, C, T):  # type: ignore[no-untyped-def]
    for i in range(N):
        j = 3 * i
        c0, c1, c2, t0, t1, t2 = form(B[j], B[j + 1], B[j + 2], X[j], X[j + 1], X[j + 2])
        C[j] = c0
        C[j + 1] = c1
        C[j + 2] = c2
        T[j] = t0
        T[j + 1] = t1
        T[j + 2] = t2


@numba.njit(cache=True, inline="always")
def _bracket_into(form, N, B, X, C):  # type: ignore[no-untyped-def]
    for i in range(N):
        j = 3 * i
        c0, c1, c2, _, _, _ = form(B[j], B[j + 1], B[j + 2], X[j], X[j + 1], X[j + 2])
        C[j] = c0
        C[j + 1] = c1
        C[j + 2] = c2


@numba.njit(cache=True, inline="always")
def so3_bracket_triple(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    """The block on :math:`(\\mathbb{R}^3,\\times)^N` (any record with ``N``)."""
    _forms_into(so3_forms, lay.N, B, X, C, T)


@numba.njit(cache=True, inline="always")
def sl2_bracket_triple(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    """The block on :math:`(\\mathbb{R}^3,\\times_L)^N`."""
    _forms_into(sl2_forms, lay.N, B, X, C, T)


@numba.njit(cache=True, inline="always")
def so3_bracket(lay, B, X, C):  # type: ignore[no-untyped-def]
    """``C = B x X`` per particle."""
    _bracket_into(so3_forms, lay.N, B, X, C)


@numba.njit(cache=True, inline="always")
def sl2_bracket(lay, B, X, C):  # type: ignore[no-untyped-def]
    """``C = -2L(B x X)`` per particle."""
    _bracket_into(sl2_forms, lay.N, B, X, C)


@numba.njit(cache=True, inline="always")
def so3_cayley_increment(lay, B, W, h, D):  # type: ignore[no-untyped-def]
    """``D_i`` the Cayley rotation's increment of every particle (:func:`so3_cayley`)."""
    half = 0.5 * h
    for i in range(lay.N):
        j = 3 * i
        d0, d1, d2 = so3_cayley(B[j], B[j + 1], B[j + 2], W[j], W[j + 1], W[j + 2], half)
        D[j] = d0
        D[j + 1] = d1
        D[j + 2] = d2


@numba.njit(cache=True, inline="always")
def so3_stage_map(lay, W, h, B, X, G, C, T, rr):  # type: ignore[no-untyped-def]
    """The stage of every particle for the field ``B`` in closed form (:func:`so3_stage`);
    ``C_i = b_i x g_i``; ``T`` is not used."""
    half = 0.5 * h
    acc = 0.0
    for i in range(lay.N):
        j = 3 * i
        g0, g1, g2, c0, c1, c2 = so3_stage(B[j], B[j + 1], B[j + 2], W[j], W[j + 1], W[j + 2],
                                           half)  # fmt: skip
        acc += (g0 - X[j]) ** 2 + (g1 - X[j + 1]) ** 2 + (g2 - X[j + 2]) ** 2  # X before G
        G[j] = g0
        G[j + 1] = g1
        G[j + 2] = g2
        C[j] = c0
        C[j + 1] = c1
        C[j + 2] = c2
    rr[0] = acc


@numba.njit(cache=True, inline="always")
def flat_stage_update(lay, W, a, C, b, T, G, X, rr):  # type: ignore[no-untyped-def]
    """``G = W + a C + b T`` (no projection: every real array is in the space)."""
    acc = 0.0
    for i in range(W.shape[0]):
        g = W[i] + a * C[i] + b * T[i]
        G[i] = g
        acc += (g - X[i]) ** 2
    rr[0] = acc


@numba.njit(cache=True, inline="always")
def flat_stage_update1(lay, W, a, C, G, X, rr):  # type: ignore[no-untyped-def]
    """``G = W + a C``."""
    acc = 0.0
    for i in range(W.shape[0]):
        g = W[i] + a * C[i]
        G[i] = g
        acc += (g - X[i]) ** 2
    rr[0] = acc


@numba.njit(cache=True, inline="always")
def flat_advance_state(lay, W, h, C, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = W + h C`` (compensated by ``E`` unless it is empty); ``fin[0]`` whether it is
    finite."""
    acc = 0.0
    if E.shape[0] == 0:
        for i in range(W.shape[0]):
            v = W[i] + h * C[i]
            Wn[i] = v
            acc += abs(v)
    else:
        for i in range(W.shape[0]):
            v, E[i] = two_sum(W[i], h * C[i] + E[i])
            Wn[i] = v
            acc += abs(v)
    fin[0] = math.isfinite(acc)


@numba.njit(cache=True, inline="always")
def so3_spherical_point(lay, W, M, mid):  # type: ignore[no-untyped-def]
    """``mid_i = sqrt(|w_i| |2M_i - w_i|) M_i / |M_i|`` (``0`` where ``M_i = 0``)."""
    for i in range(lay.N):
        j = 3 * i
        fac = spherical_factor(W[j], W[j + 1], W[j + 2], M[j], M[j + 1], M[j + 2])
        mid[j] = fac * M[j]
        mid[j + 1] = fac * M[j + 1]
        mid[j + 2] = fac * M[j + 2]


def provide_particle_blocks(so3: tuple[type, ...], sl2: tuple[type, ...]) -> None:
    """Register the particle blocks (all but ``evaluate_B``) for particle layout records."""
    for cls in so3 + sl2:
        blocks.provide(blocks.stage_update, cls)(flat_stage_update)
        blocks.provide(blocks.stage_update1, cls)(flat_stage_update1)
        blocks.provide(blocks.advance_state, cls)(flat_advance_state)
    for cls in so3:
        blocks.provide(blocks.bracket_triple, cls)(so3_bracket_triple)
        blocks.provide(blocks.bracket, cls)(so3_bracket)
        blocks.provide(blocks.spherical_point, cls)(so3_spherical_point)
        blocks.provide(blocks.cayley_increment, cls)(so3_cayley_increment)
        blocks.provide(blocks.stage_map, cls)(so3_stage_map)
    for cls in sl2:
        blocks.provide(blocks.bracket_triple, cls)(sl2_bracket_triple)
        blocks.provide(blocks.bracket, cls)(sl2_bracket)
    blocks.provide_generic_stage_map(*sl2)
    blocks.provide_member_defaults(*so3, *sl2)


blocks.provide(blocks.evaluate_B, Particles3, ParticlesL)(_evaluate_B)
provide_particle_blocks((Particles3,), (ParticlesL,))


def particle_layout(problem: Any, members: int) -> Layout | None:
    """The generic particle layout (the kernel's field on ``(N, 3)`` views), or ``None``."""
    alg = problem.algebra
    N = alg.shape[0]
    if type(alg) is SpinVectors:
        return member_layout("(R^3, x)^N", Particles3(N), alg.shape, np.float64)
    if type(alg) is SL2Vectors:
        return member_layout("(R^3, x_L)^N", ParticlesL(N), alg.shape, np.float64)
    return None
