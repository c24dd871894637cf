r"""IsoMP on complex :class:`~isoflow._compiled.dense.DenseBlas` states at large ``n``: real
planes and three real products per complex one (3M).

A complex product costs four real ones; with :math:`B = B_r + i B_i`, :math:`X = X_r + i X_i`
three suffice (the 3M scheme):

.. math::

    m_1 = B_r X_r, \quad m_2 = B_i X_i, \quad m_3 = (B_r + B_i)(X_r + X_i), \qquad
    BX = (m_1 - m_2) + i\,(m_3 - m_1 - m_2).

``B`` is skew-Hermitian (the skew normalizer of every complex dense space), so :math:`B_r` is
antisymmetric and :math:`B_i` symmetric, and the columns ``[0, r_1)`` of ``B`` are rows of its
planes transposed: :math:`B_r[:, :r_1] = -B_r[:r_1]^T`, :math:`B_i[:, :r_1] = B_i[:r_1]^T`,
:math:`(B_r + B_i)[:, :r_1] = (B_i - B_r)[:r_1]^T`. The triple product :math:`T = B X B = P B`
(``P = BX``) lies in ``V``, so only its lower block triangle is formed, block row by block
row, again with three real products (:func:`isoflow._compiled.dense.lower_blocks`). One
iteration is then about ``3 + 3/2`` real products instead of ``4 + 2`` of
:mod:`isoflow._compiled.dense_tiles` (benchmark 12 measures it). The pass after the products
(bracket, iterate, residual, mirrored into ``V``) reads the planes and writes the complex
iterate tile by tile as :func:`isoflow._compiled.dense_tiles._combine` does, so every iterate
and state stays in ``V`` to the last bit.

Accuracy: 3M's error in the imaginary part is bounded by
:math:`\|B_r + B_i\|\,\|X_r + X_i\|` instead of :math:`\|B_r\|\|X_i\| + \|B_i\|\|X_r\|`, at
most a small factor more than the complex product's; the states agree with the four-product
path to rounding, and the Casimirs, which the stage preserves by its structure, stay at rounding.

Scratch: five complex rows, used as ten real ``n x n`` planes (``work[r]`` viewed as two
float planes); ``aux`` holds the planes of ``P`` (real, imaginary) for the finish.

Threads: on a ``threaded`` record (a single system from
:data:`~isoflow._compiled.dense.THREADED_MIN_N`) the iteration and the finish run over numba
threads in pieces fixed by ``n``: the three full products as six products of half the rows,
the triangular products as three times ``nb / 2`` tasks (block ``k`` with block
``nb - 1 - k``: equal work, since numba hands each thread an equal share of a loop's
iterations before they start), the splits and the gather by row chunks, the combine and the
finish by pairs of tile rows, each pair's residual (or size sum) apart and the pairs added in
order. The pieces and their calls are the same whatever the thread count, so the states do
not depend on it (tested bit for bit); they agree with the serial stage an ensemble member
runs (whole products, one running residual sum) to rounding.
Subnormal results and operands are flushed to zero inside (:mod:`isoflow._compiled.
subnormals`).
"""

from __future__ import annotations

import numba
import numpy as np

from .dense import _TILE
from .dense_tiles import _load_t, _store_t, close_update, diagonal_tile_entry
from .flat import two_sum
from .subnormals import flush_on, flush_restore

__all__ = ["NWORK", "finish", "iterate", "iterate_from_B"]

#: Scratch rows (complex) per member: ten real planes.
NWORK = 5
#: Products may fuse, never reassociate (see :mod:`isoflow._compiled.dense_tiles`: with
#: ``reassoc`` the states depended on whether the pass was compiled in the run's process or
#: loaded from numba's cache); the residual's sum is split by tile column by hand.
_FM = {"nsz", "contract"}


@numba.njit(cache=True, inline="always")
def _planes(row, n):  # type: ignore[no-untyped-def]
    """The two real ``n x n`` planes of a complex scratch row."""
    f = row.view(np.float64)
    nn = n * n
    return f[:nn].reshape((n, n)), f[nn:].reshape((n, n))


@numba.njit(cache=True, fastmath=_FM)
def _split_x(X, Xr, Xi, Xs):  # type: ignore[no-untyped-def]
    """``Xr, Xi = Re X, Im X``; ``Xs = Xr + Xi``."""
    for i in range(X.shape[0]):
        x = X[i]
        Xr[i] = x.real
        Xi[i] = x.imag
        Xs[i] = x.real + x.imag


@numba.njit(cache=True, fastmath=_FM)
def _split_b(B, Br, Bi, Bs, D):  # type: ignore[no-untyped-def]
    """``Br, Bi = Re B, Im B``; ``Bs = Br + Bi``; ``D = Bi - Br``."""
    for i in range(B.shape[0]):
        b = B[i]
        Br[i] = b.real
        Bi[i] = b.imag
        Bs[i] = b.real + b.imag
        D[i] = b.imag - b.real


@numba.njit(cache=True, fastmath=_FM)
def _gather_p(m1, m2, m3, Ps):  # type: ignore[no-untyped-def]
    """``P = (m1 - m2) + i (m3 - m1 - m2)`` into ``m1`` (real) and ``m3`` (imaginary);
    ``Ps = Re P + Im P``."""
    for i in range(m1.shape[0]):
        a = m1[i]
        b = m2[i]
        pr = a - b
        pi = m3[i] - a - b
        m1[i] = pr
        m3[i] = pi
        Ps[i] = pr + pi


@numba.njit(cache=True, fastmath=_FM, inline="always")
def _combine_row(W, X, Pr, Pi, T1, T2, T3, rowoff, G, s, half, quarter, bi, PrT, PiT, GT, cols, rr):  # type: ignore[no-untyped-def]
    """:func:`_combine` on the tile row from row ``bi``: the tiles left of the diagonal add
    their residual to ``cols`` (by tile column), the diagonal tile to ``rr``, returned."""
    n = W.shape[0]
    ie = min(bi + _TILE, n)
    for bj in range(0, bi, _TILE):
        je = bj + _TILE
        _load_t(Pr, bi, ie, bj, je, PrT)
        _load_t(Pi, bi, ie, bj, je, PiT)
        for ii in range(ie - bi):
            i = bi + ii
            o = rowoff[i]
            pr_row = Pr[i, bj:je]
            pi_row = Pi[i, bj:je]
            t1_row = T1[o + bj : o + je]
            t2_row = T2[o + bj : o + je]
            t3_row = T3[o + bj : o + je]
            w_row = W[i, bj:je]
            x_row = X[i, bj:je]
            g_row = G[i, bj:je]
            prt_row = PrT[ii]
            pit_row = PiT[ii]
            gt_row = GT[ii]
            for jj in range(_TILE):
                t1 = t1_row[jj]
                t2 = t2_row[jj]
                cr = pr_row[jj] + s * prt_row[jj]
                ci = pi_row[jj] - s * pit_row[jj]
                tr = -(t1 + t2)
                ti = t3_row[jj] + t1 - t2
                w = w_row[jj]
                gr = w.real + half * cr + quarter * tr
                gi = w.imag + half * ci + quarter * ti
                g_row[jj] = complex(gr, gi)
                gt_row[jj] = complex(s * gr, -s * gi)
                x = x_row[jj]
                dr = gr - x.real
                di = gi - x.imag
                cols[jj] += 2.0 * (dr * dr + di * di)
        _store_t(GT, G, bi, ie, bj)
    for i in range(bi, ie):  # the diagonal tile
        o = rowoff[i]
        for j in range(bi, i):
            t1 = T1[o + j]
            t2 = T2[o + j]
            cr = Pr[i, j] + s * Pr[j, i]
            ci = Pi[i, j] - s * Pi[j, i]
            gr = W[i, j].real + half * cr - quarter * (t1 + t2)
            gi = W[i, j].imag + half * ci + quarter * (T3[o + j] + t1 - t2)
            G[i, j] = complex(gr, gi)
            G[j, i] = complex(s * gr, -s * gi)
            x = X[i, j]
            dr = gr - x.real
            di = gi - x.imag
            rr += 2.0 * (dr * dr + di * di)
        t1 = T1[o + i]
        t2 = T2[o + i]
        # P + sigma(P) and T projected onto V on the diagonal: (t + s conj t) / 2
        gr = W[i, i].real + (1.0 + s) * (half * Pr[i, i] - 0.5 * quarter * (t1 + t2))
        gi = W[i, i].imag + (1.0 - s) * (half * Pi[i, i] + 0.5 * quarter * (T3[o + i] + t1 - t2))
        G[i, i] = complex(gr, gi)
        x = X[i, i]
        dr = gr - x.real
        di = gi - x.imag
        rr += dr * dr + di * di
    return rr


@numba.njit(cache=True, fastmath=_FM)
def _combine(W, X, Pr, Pi, T1, T2, T3, rowoff, G, s, half, quarter):  # type: ignore[no-untyped-def]
    r"""``G = W + half (P + sigma(P)) + quarter T`` on the lower triangle, mirrored into ``V``;
    returns ``|G - X|^2``.

    ``P = Pr + i Pi``; ``T = -(T1 + T2) + i (T3 + T1 - T2)`` packed by rows (the three real
    products of :func:`iterate`). The tile traversal is
    :func:`isoflow._compiled.dense_tiles._combine`'s.
    """
    n = W.shape[0]
    PrT = np.empty((_TILE, _TILE))
    PiT = np.empty((_TILE, _TILE))
    GT = np.empty((_TILE, _TILE), dtype=G.dtype)
    cols = np.zeros(_TILE)  # the residual's partial sums by tile column (a fixed order)
    rr = 0.0
    for bi in range(0, n, _TILE):
        rr = _combine_row(
            W, X, Pr, Pi, T1, T2, T3, rowoff, G, s, half, quarter, bi, PrT, PiT, GT, cols, rr
        )
    for jj in range(_TILE):
        rr += cols[jj]
    return rr


#: Row chunks of the threaded passes (a fixed number: the work of a chunk does not depend on
#: the threads, and neither does any result).
_ROW_CHUNKS = 16


@numba.njit(cache=True, parallel=True, fastmath=_FM)
def _split_threaded(B, X, Br, Bi, Bs, D, Xr, Xi, Xs, n):  # type: ignore[no-untyped-def]
    """:func:`_split_b` and :func:`_split_x` by row chunks (flat planes)."""
    for c in numba.prange(_ROW_CHUNKS):
        old = flush_on()  # this thread's subnormals flushed (module docstring)
        a = c * n // _ROW_CHUNKS * n
        b = (c + 1) * n // _ROW_CHUNKS * n
        _split_b(B[a:b], Br[a:b], Bi[a:b], Bs[a:b], D[a:b])
        _split_x(X[a:b], Xr[a:b], Xi[a:b], Xs[a:b])
        flush_restore(old)


@numba.njit(cache=True, parallel=True, fastmath=_FM)
def _gather_threaded(m1, m2, m3, Ps, n):  # type: ignore[no-untyped-def]
    """:func:`_gather_p` by row chunks (flat planes)."""
    for c in numba.prange(_ROW_CHUNKS):
        old = flush_on()  # this thread's subnormals flushed (module docstring)
        a = c * n // _ROW_CHUNKS * n
        b = (c + 1) * n // _ROW_CHUNKS * n
        _gather_p(m1[a:b], m2[a:b], m3[a:b], Ps[a:b])
        flush_restore(old)


@numba.njit(cache=True, parallel=True)
def _products_threaded(Br, Xr, Pr, Bi, Xi, M2, Bs, Xs, Pi):  # type: ignore[no-untyped-def]
    """The three full real products of :func:`iterate_from_B`, each as two products of half
    the rows: six calls of equal size, three a thread on two threads (numba splits a
    ``prange`` statically)."""
    n = Br.shape[0]
    m = n // 2
    for t in numba.prange(6):
        old = flush_on()  # this thread's subnormals flushed (module docstring)
        lo = 0 if t % 2 == 0 else m
        hi = m if t % 2 == 0 else n
        p = t // 2
        if p == 0:
            np.dot(Br[lo:hi], Xr, Pr[lo:hi])
        elif p == 1:
            np.dot(Bi[lo:hi], Xi, M2[lo:hi])
        else:
            np.dot(Bs[lo:hi], Xs, Pi[lo:hi])
        flush_restore(old)


@numba.njit(cache=True, inline="always")
def _lower_block(p, b, Pr, Pi, Ps, Br, Bi, D, T1, T2, T3, rows, rowoff):  # type: ignore[no-untyped-def]
    """Product ``p`` (0, 1, 2: ``T1``, ``T2``, ``T3``) of the lower block triangle on block
    ``b`` (rows ``[r0, r1)`` by ``r1`` columns, packed by rows)."""
    r0 = rows[b, 0]
    r1 = rows[b, 1]
    o = rowoff[r0]
    size = (r1 - r0) * r1
    if p == 0:
        np.dot(Pr[r0:r1], Br[:r1].T, T1[o : o + size].reshape((r1 - r0, r1)))
    elif p == 1:
        np.dot(Pi[r0:r1], Bi[:r1].T, T2[o : o + size].reshape((r1 - r0, r1)))
    else:
        np.dot(Ps[r0:r1], D[:r1].T, T3[o : o + size].reshape((r1 - r0, r1)))


@numba.njit(cache=True, parallel=True)
def _lower_threaded(Pr, Pi, Ps, Br, Bi, D, T1, T2, T3, rows, rowoff):  # type: ignore[no-untyped-def]
    """The lower block triangle of :func:`iterate_from_B` over numba threads: a task is one
    of the three products on block ``k`` and block ``nb - 1 - k`` (blocks of equal height:
    equal work a task)."""
    nb = rows.shape[0]
    npair = (nb + 1) // 2
    for t in numba.prange(3 * npair):
        old = flush_on()  # this thread's subnormals flushed (module docstring)
        p = t // npair
        k = t % npair
        _lower_block(p, k, Pr, Pi, Ps, Br, Bi, D, T1, T2, T3, rows, rowoff)
        if nb - 1 - k != k:
            _lower_block(p, nb - 1 - k, Pr, Pi, Ps, Br, Bi, D, T1, T2, T3, rows, rowoff)
        flush_restore(old)


@numba.njit(cache=True, parallel=True, fastmath=_FM)
def _combine_threaded(W, X, Pr, Pi, T1, T2, T3, rowoff, G, s, half, quarter):  # type: ignore[no-untyped-def]
    """:func:`_combine` over numba threads: tile row ``k`` paired with tile row ``nt - 1 - k``
    (equal work a task), each task's residual summed apart and the parts added in task
    order, so the residual does not depend on the threads."""
    n = W.shape[0]
    nt = -(-n // _TILE)
    npair = (nt + 1) // 2
    parts = np.zeros(npair)
    for k in numba.prange(npair):
        old = flush_on()  # this thread's subnormals flushed (module docstring)
        PrT = np.empty((_TILE, _TILE))
        PiT = np.empty((_TILE, _TILE))
        GT = np.empty((_TILE, _TILE), dtype=G.dtype)
        cols = np.zeros(_TILE)
        rr = _combine_row(
            W, X, Pr, Pi, T1, T2, T3, rowoff, G, s, half, quarter, k * _TILE, PrT, PiT, GT,
            cols, 0.0,
        )  # fmt: skip
        if nt - 1 - k != k:
            rr = _combine_row(
                W, X, Pr, Pi, T1, T2, T3, rowoff, G, s, half, quarter, (nt - 1 - k) * _TILE,
                PrT, PiT, GT, cols, rr,
            )  # fmt: skip
        for jj in range(_TILE):
            rr += cols[jj]
        parts[k] = rr
        flush_restore(old)
    total = 0.0
    for k in range(npair):
        total += parts[k]
    return total


@numba.njit(cache=True)
def iterate(f, fargs, lay, mp, sd, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """One IsoMP iteration with 3M products; ``aux`` receives the planes of ``P = B X``."""
    n = lay.n
    f(X.reshape((n, n)), work[0].reshape((n, n)), *fargs)
    iterate_from_B(lay, W, X, G, aux, work, hp, rr)


@numba.njit(cache=True)
def iterate_from_B(lay, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """The iteration after ``B`` (``work[0]``, ``(n, n)`` complex) is formed: the stages that
    change ``B`` (the stochastic midpoint's noise) share the rest."""
    old = flush_on()  # subnormals flushed (isoflow._compiled.subnormals)
    _iterate_from_B(lay, W, X, G, aux, work, hp, rr)
    flush_restore(old)


@numba.njit(cache=True)
def _iterate_from_B(lay, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """:func:`iterate_from_B` with the flush bits set."""
    n = lay.n
    nn = n * n
    Xm = X.reshape((n, n))
    B = work[0]
    Br, Bi = _planes(work[1], n)
    D, Bs = _planes(work[2], n)
    Xr, Xi = _planes(work[3], n)
    Xs, M2 = _planes(work[4], n)
    Pr, Pi = _planes(aux, n)
    Ps = Bs  # B_r + B_i is spent once the products are formed
    Bf = B.view(np.float64)  # B is spent (its planes are kept): T1, T2 packed in its row
    T1 = Bf[:nn]
    T2 = Bf[nn:]
    T3 = Xr.reshape(nn)  # so is X's real plane
    rowoff = lay.rowoff
    rows = lay.blocks
    Wm = W.reshape((n, n))
    Gm = G.reshape((n, n))
    if lay.threaded:
        _split_threaded(
            B, X, Br.reshape(nn), Bi.reshape(nn), Bs.reshape(nn), D.reshape(nn), Xr.reshape(nn),
            Xi.reshape(nn), Xs.reshape(nn), n,
        )  # fmt: skip
        _products_threaded(Br, Xr, Pr, Bi, Xi, M2, Bs, Xs, Pi)
        _gather_threaded(Pr.reshape(nn), M2.reshape(nn), Pi.reshape(nn), Ps.reshape(nn), n)
        _lower_threaded(Pr, Pi, Ps, Br, Bi, D, T1, T2, T3, rows, rowoff)
        rr[0] = _combine_threaded(
            Wm, Xm, Pr, Pi, T1, T2, T3, rowoff, Gm, lay.s, 0.5 * hp, 0.25 * hp * hp
        )
        return
    _split_b(B, Br.reshape(nn), Bi.reshape(nn), Bs.reshape(nn), D.reshape(nn))
    _split_x(X, Xr.reshape(nn), Xi.reshape(nn), Xs.reshape(nn))
    np.dot(Br, Xr, Pr)  # m1
    np.dot(Bi, Xi, M2)  # m2
    np.dot(Bs, Xs, Pi)  # m3
    _gather_p(Pr.reshape(nn), M2.reshape(nn), Pi.reshape(nn), Ps.reshape(nn))
    # the lower block triangle of T = P B, three real products per block row (module docstring)
    for b in range(rows.shape[0]):
        for p in range(3):
            _lower_block(p, b, Pr, Pi, Ps, Br, Bi, D, T1, T2, T3, rows, rowoff)
    rr[0] = _combine(Wm, Xm, Pr, Pi, T1, T2, T3, rowoff, Gm, lay.s, 0.5 * hp, 0.25 * hp * hp)


@numba.njit(cache=True, fastmath={"nsz", "contract"}, inline="always")
def _finish_row(Wm, Wo, Em, Pr, Pi, s, h, compensated, bi, PrT, PiT, VT, ET, acc):  # type: ignore[no-untyped-def]
    """:func:`finish` on the tile row from row ``bi``; returns ``acc`` plus the sizes of the
    entries written."""
    n = Wm.shape[0]
    ie = min(bi + _TILE, n)
    for bj in range(0, bi, _TILE):
        je = bj + _TILE
        _load_t(Pr, bi, ie, bj, je, PrT)
        _load_t(Pi, bi, ie, bj, je, PiT)
        for ii in range(ie - bi):
            i = bi + ii
            pr_row = Pr[i, bj:je]
            pi_row = Pi[i, bj:je]
            w_row = Wm[i, bj:je]
            o_row = Wo[i, bj:je]
            prt_row = PrT[ii]
            pit_row = PiT[ii]
            vt_row = VT[ii]
            if compensated:
                e_row = Em[i, bj:je]
                et_row = ET[ii]
                for jj in range(_TILE):
                    d = complex(
                        h * (pr_row[jj] + s * prt_row[jj]), h * (pi_row[jj] - s * pit_row[jj])
                    )
                    v, e = two_sum(w_row[jj], d + e_row[jj])
                    o_row[jj] = v
                    e_row[jj] = e
                    vt_row[jj] = s * v.conjugate()
                    et_row[jj] = s * e.conjugate()
                    acc += abs(v.real) + abs(v.imag)
            else:
                for jj in range(_TILE):
                    w = w_row[jj]
                    vr = w.real + h * (pr_row[jj] + s * prt_row[jj])
                    vi = w.imag + h * (pi_row[jj] - s * pit_row[jj])
                    o_row[jj] = complex(vr, vi)
                    vt_row[jj] = complex(s * vr, -s * vi)
                    acc += abs(vr) + abs(vi)
        _store_t(VT, Wo, bi, ie, bj)
        if compensated:
            _store_t(ET, Em, bi, ie, bj)
    for i in range(bi, ie):  # the diagonal tile
        for j in range(bi, i + 1):
            d = complex(h * (Pr[i, j] + s * Pr[j, i]), h * (Pi[i, j] - s * Pi[j, i]))
            acc += diagonal_tile_entry(Wm, Wo, Em, i, j, d, s, compensated)
    return acc


@numba.njit(cache=True, parallel=True, fastmath={"nsz", "contract"})
def _finish_threaded(Wm, Wo, Em, Pr, Pi, s, h, compensated):  # type: ignore[no-untyped-def]
    """:func:`_finish_row` on every tile row, the rows paired as :func:`_combine_threaded`
    pairs them; the sum of the entries' sizes."""
    n = Wm.shape[0]
    nt = -(-n // _TILE)
    npair = (nt + 1) // 2
    parts = np.zeros(npair)
    for k in numba.prange(npair):
        old = flush_on()  # this thread's subnormals flushed (module docstring)
        PrT = np.empty((_TILE, _TILE))
        PiT = np.empty((_TILE, _TILE))
        VT = np.empty((_TILE, _TILE), dtype=Wm.dtype)
        ET = np.empty((_TILE, _TILE), dtype=Wm.dtype)
        acc = _finish_row(Wm, Wo, Em, Pr, Pi, s, h, compensated, k * _TILE, PrT, PiT, VT, ET, 0.0)
        if nt - 1 - k != k:
            acc = _finish_row(
                Wm, Wo, Em, Pr, Pi, s, h, compensated, (nt - 1 - k) * _TILE, PrT, PiT, VT, ET,
                acc,
            )  # fmt: skip
        parts[k] = acc
        flush_restore(old)
    total = 0.0
    for k in range(npair):
        total += parts[k]
    return total


@numba.njit(cache=True)
def finish(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = Pi_V(W + h (P + sigma(P)))`` from the planes of ``P`` in ``aux``, on the lower
    triangle and mirrored tile by tile, compensated by ``E`` (mirrored the same way) unless it
    is empty, as :func:`isoflow._compiled.dense_tiles.finish`; ``fin[0]`` whether ``Wn`` is
    finite; tile rows over numba threads on a ``threaded`` record. No reassociation here: it
    would simplify the compensation's exact error away."""
    old = flush_on()  # subnormals flushed (isoflow._compiled.subnormals)
    _finish(lay, W, aux, hp, E, Wn, fin)
    flush_restore(old)


@numba.njit(cache=True, fastmath={"nsz", "contract"})
def _finish(lay, W, aux, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """:func:`finish` with the flush bits set."""
    n = lay.n
    s = lay.s
    h = hp
    Wm = W.reshape((n, n))
    Wo = Wn.reshape((n, n))
    compensated = E.shape[0] != 0
    Em = E.reshape((n, n)) if compensated else E.reshape((0, 0))
    Pr, Pi = _planes(aux, n)
    if lay.threaded:
        acc = _finish_threaded(Wm, Wo, Em, Pr, Pi, s, h, compensated)
    else:
        PrT = np.empty((_TILE, _TILE))
        PiT = np.empty((_TILE, _TILE))
        VT = np.empty((_TILE, _TILE), dtype=W.dtype)
        ET = np.empty((_TILE, _TILE), dtype=W.dtype)
        acc = 0.0
        for bi in range(0, n, _TILE):
            acc = _finish_row(Wm, Wo, Em, Pr, Pi, s, h, compensated, bi, PrT, PiT, VT, ET, acc)
    close_update(lay, Wn, E, acc, fin)
