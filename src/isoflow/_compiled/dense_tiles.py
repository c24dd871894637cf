r"""IsoMP on :class:`~isoflow._compiled.dense.DenseBlas`: the fused specialization of its stage.

The generic IsoMP stage (:mod:`isoflow._compiled.stages.isomp`) on the BLAS layout forms
``P = B X``, ``T = P B`` (two full products) and then the update in a separate pass. This
specialization computes the same map with about half of the second product and one pass after
the products, measured in benchmarks 3, 10 and 12 (an iteration at ``n >= 256`` costs
0.9-1.14 times two bare products): :math:`T = BXB` lies in ``V`` (``B`` is skew), so only its
lower block triangle is computed, block row by block row, as
:math:`T_{[r_0, r_1), [0, r_1)} = -P_{[r_0,r_1)}\, \overline{B}_{[0, r_1)}^{\,T}`
(:func:`isoflow._compiled.dense.lower_blocks`); the rest (bracket, iterate, residual, mirrored
into ``V``) is one cache-blocked pass over pairs of mirrored tiles. Every iterate and state
stays in ``V`` to the last bit.

``lay.blocks`` holds the ``(nb, 2)`` row ranges of the triangular product and ``lay.rowoff[i]``
the offset of row ``i`` of the packed lower-block-triangular ``T`` in the scratch row
``work[1]`` (:func:`isoflow._compiled.dense.packed_row_offsets`). Three scratch rows: ``B``,
the packed ``T`` and ``conj(B)``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .dense import _TILE, remove_trace, remove_trace_compensated
from .flat import two_sum
from .subnormals import flush_on, flush_restore

__all__ = ["NWORK", "finish", "iterate", "iterate_from_B"]

#: Scratch rows per member.
NWORK = 3
#: Products may fuse (results differ from NumPy by rounding), but never reassociate: with
#: ``reassoc`` the new iterate's rounding depended on what else LLVM saw when it compiled the
#: pass (a loop compiled in the run's process and the same loop loaded from numba's cache gave
#: states 1e-16 apart, so a run resumed from another process did not continue bit for bit).
#: The residual's sum is split over the tile's columns by hand to vectorize in a fixed order.
_FM = {"nsz", "contract"}


@numba.njit(cache=True, inline="always")
def _load_t(A, bi, ie, bj, je, buf):  # type: ignore[no-untyped-def]
    """``buf[ii, jj] = A[bj + jj, bi + ii]``: the transposed tile, read row by row from ``A``."""
    for j in range(bj, je):
        for i in range(bi, ie):
            buf[i - bi, j - bj] = A[j, i]


@numba.njit(cache=True, inline="always")
def _store_t(buf, A, bi, ie, bj):  # type: ignore[no-untyped-def]
    """``A[bj + jj, bi + ii] = buf[ii, jj]``: the transposed tile written back row by row."""
    for jj in range(_TILE):
        dst = A[bj + jj, bi:ie]
        for ii in range(ie - bi):
            dst[ii] = buf[ii, jj]


@numba.njit(cache=True, fastmath=_FM)
def _combine(W, X, P, Tp, rowoff, G, s, half, quarter):  # type: ignore[no-untyped-def]
    """``G = W + half (P + sigma(P)) - quarter T'`` on the lower triangle, mirrored into ``V``
    (``T' = -T`` packed by rows, see :func:`iterate_blas`); returns ``|G - X|^2``.

    Works on pairs of mirrored tiles ``(bi, bj)``, ``bj < bi``: the upper tile of ``P`` is read
    row by row into a small transposed buffer, the mirrored tile of ``G`` is written back row
    by row from a buffer; the inner loops run over contiguous row pieces (they vectorize).
    Diagonal tiles are their own mirrors; on the diagonal ``T`` is projected onto ``V``.
    """
    n = W.shape[0]
    PT = np.empty((_TILE, _TILE), dtype=P.dtype)
    GT = np.empty((_TILE, _TILE), dtype=G.dtype)
    cols = np.zeros(_TILE)  # the residual's partial sums by tile column (a fixed order)
    rr = 0.0
    for bi in range(0, n, _TILE):
        ie = min(bi + _TILE, n)
        for bj in range(0, bi, _TILE):
            je = bj + _TILE
            _load_t(P, bi, ie, bj, je, PT)
            for ii in range(ie - bi):
                i = bi + ii
                p_row = P[i, bj:je]
                w_row = W[i, bj:je]
                t_row = Tp[rowoff[i] + bj : rowoff[i] + je]
                x_row = X[i, bj:je]
                g_row = G[i, bj:je]
                pt_row = PT[ii]
                gt_row = GT[ii]
                for jj in range(_TILE):
                    c = p_row[jj] + s * pt_row[jj].conjugate()
                    g = w_row[jj] + half * c - quarter * t_row[jj]
                    g_row[jj] = g
                    gt_row[jj] = s * g.conjugate()
                    d = g - x_row[jj]
                    cols[jj] += 2.0 * (d.real * d.real + d.imag * d.imag)
            _store_t(GT, G, bi, ie, bj)
        for i in range(bi, ie):  # the diagonal tile
            o = rowoff[i]
            for j in range(bi, i):
                c = P[i, j] + s * P[j, i].conjugate()
                g = W[i, j] + half * c - quarter * Tp[o + j]
                G[i, j] = g
                G[j, i] = s * g.conjugate()
                d = g - X[i, j]
                rr += 2.0 * (d.real * d.real + d.imag * d.imag)
            p = P[i, i]
            t = -Tp[o + i]
            g = W[i, i] + half * (p + s * p.conjugate()) + quarter * (0.5 * (t + s * t.conjugate()))
            G[i, i] = g
            d = g - X[i, i]
            rr += d.real * d.real + d.imag * d.imag
    for jj in range(_TILE):
        rr += cols[jj]
    return rr


@numba.njit(cache=True)
def iterate(f, fargs, lay, mp, sd, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """One IsoMP iteration; ``aux`` receives ``P = B X`` (the bracket is formed from it when
    needed)."""
    n = lay.n
    f(X.reshape((n, n)), work[0].reshape((n, n)), *fargs)
    iterate_from_B(lay, W, X, G, aux, work, hp, rr)


@numba.njit(cache=True)
def iterate_from_B(lay, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """The iteration after ``B`` (``work[0]``, ``(n, n)``) is formed: the stages that change
    ``B`` (the stochastic midpoint's noise) share the rest."""
    old = flush_on()  # subnormals flushed (isoflow._compiled.subnormals)
    _iterate_from_B(lay, W, X, G, aux, work, hp, rr)
    flush_restore(old)


@numba.njit(cache=True)
def _iterate_from_B(lay, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """:func:`iterate_from_B` with the flush bits set."""
    n = lay.n
    s = lay.s
    half = 0.5 * hp
    quarter = 0.25 * hp * hp
    rowoff = lay.rowoff
    Xm = X.reshape((n, n))
    Bm = work[0].reshape((n, n))
    P = aux.reshape((n, n))
    np.dot(Bm, Xm, P)
    # B[:, :r1] = -conj(B[:r1, :]).T (B is skew), so block row (r0, r1) of T = P B is
    # -P[r0:r1] @ conj(B[:r1]).T: both operands contiguous, the transpose is BLAS's flag
    if np.iscomplexobj(Bm):
        Bc = work[2].reshape((n, n))
        for i in range(n):
            for j in range(n):
                Bc[i, j] = Bm[i, j].conjugate()
    else:
        Bc = Bm
    Tp = work[1]
    rows = lay.blocks
    for b in range(rows.shape[0]):
        r0 = rows[b, 0]
        r1 = rows[b, 1]
        o = rowoff[r0]
        np.dot(P[r0:r1], Bc[:r1].T, Tp[o : o + (r1 - r0) * r1].reshape((r1 - r0, r1)))
    rr[0] = _combine(W.reshape((n, n)), Xm, P, Tp, rowoff, G.reshape((n, n)), s, half, quarter)


@numba.njit(cache=True, inline="always")
def close_update(lay, Wn, E, acc, fin):  # type: ignore[no-untyped-def]
    """The end of a tiled finish: the trace removed on ``su(n)`` (with the compensation ``E``
    unless it is empty), ``fin[0]`` whether the sum ``acc`` of the entries' sizes is finite."""
    if lay.traceless:
        if E.shape[0] != 0:
            remove_trace_compensated(Wn, E, lay.n)
        else:
            remove_trace(Wn, lay.n)
    fin[0] = math.isfinite(acc)


@numba.njit(cache=True)
def finish(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = Pi_V(W + h (P + sigma(P)))`` with ``P = B X`` in ``aux``, computed on the lower
    triangle and mirrored tile by tile, compensated by ``E`` (mirrored the same way) unless
    it is empty; ``fin[0]`` whether ``Wn`` is finite.

    The tile traversal is :func:`_combine`'s on purpose, with another body: passing the body
    as a function argument would cost the inlining that lets the row loops vectorize. No
    reassociation here: it would simplify the compensation's exact error away (the pass is
    one of several per step; benchmark 17 measures it).
    """
    old = flush_on()  # subnormals flushed (isoflow._compiled.subnormals)
    _finish(lay, W, aux, hp, E, Wn, fin)
    flush_restore(old)


@numba.njit(cache=True, fastmath={"nsz", "contract"}, inline="always")
def diagonal_tile_entry(Wm, Wo, Em, i, j, d, s, compensated):  # type: ignore[no-untyped-def]
    """``Wo[i, j] = Wm[i, j] + d`` (with the compensation ``Em`` carried when
    ``compensated``) and its mirror ``Wo[j, i] = s conj(Wo[i, j])``, for an entry of a diagonal
    tile of the finish (``j <= i``); returns ``|Re| + |Im|`` of the new entry. Shared by the
    complex and the planar finish."""
    if compensated:
        v, e = two_sum(Wm[i, j], d + Em[i, j])
        Em[i, j] = e
        Em[j, i] = s * e.conjugate()
    else:
        v = Wm[i, j] + d
    Wo[i, j] = v
    Wo[j, i] = s * v.conjugate()
    return abs(v.real) + abs(v.imag)


@numba.njit(cache=True, fastmath={"nsz", "contract"})
def _finish(lay, W, aux, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """:func:`finish` with the flush bits set."""
    n = lay.n
    s = lay.s
    h = hp
    Wm = W.reshape((n, n))
    P = aux.reshape((n, n))
    Wo = Wn.reshape((n, n))
    compensated = E.shape[0] != 0
    Em = E.reshape((n, n)) if compensated else E.reshape((0, 0))
    PT = np.empty((_TILE, _TILE), dtype=P.dtype)
    VT = np.empty((_TILE, _TILE), dtype=P.dtype)
    ET = np.empty((_TILE, _TILE), dtype=P.dtype)
    acc = 0.0
    for bi in range(0, n, _TILE):
        ie = min(bi + _TILE, n)
        for bj in range(0, bi, _TILE):
            je = bj + _TILE
            _load_t(P, bi, ie, bj, je, PT)
            for ii in range(ie - bi):
                i = bi + ii
                p_row = P[i, bj:je]
                w_row = Wm[i, bj:je]
                o_row = Wo[i, bj:je]
                pt_row = PT[ii]
                vt_row = VT[ii]
                if compensated:
                    e_row = Em[i, bj:je]
                    et_row = ET[ii]
                    for jj in range(_TILE):
                        d = h * (p_row[jj] + s * pt_row[jj].conjugate()) + e_row[jj]
                        v, e = two_sum(w_row[jj], d)
                        o_row[jj] = v
                        e_row[jj] = e
                        vt_row[jj] = s * v.conjugate()
                        et_row[jj] = s * e.conjugate()
                        acc += abs(v.real) + abs(v.imag)
                else:
                    for jj in range(_TILE):
                        v = w_row[jj] + h * (p_row[jj] + s * pt_row[jj].conjugate())
                        o_row[jj] = v
                        vt_row[jj] = s * v.conjugate()
                        acc += abs(v.real) + abs(v.imag)
            _store_t(VT, Wo, bi, ie, bj)
            if compensated:
                _store_t(ET, Em, bi, ie, bj)
        for i in range(bi, ie):  # the diagonal tile
            for j in range(bi, i + 1):
                d = h * (P[i, j] + s * P[j, i].conjugate())
                acc += diagonal_tile_entry(Wm, Wo, Em, i, j, d, s, compensated)
    close_update(lay, Wn, E, acc, fin)
