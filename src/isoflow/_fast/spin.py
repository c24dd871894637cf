r"""Compiled IsoMP and spherical-midpoint loops for spin chains :math:`(\mathbb{R}^3,\times)^N`.

``B_i(w) = c\,(w_{i-1} + w_{i+1})`` (periodic; the Heisenberg chain is ``c = -1``). The state
``(*batch, N, 3)`` is copied once per call into the structure-of-arrays layout ``(3, N)``
(unit-stride, vectorizable), advanced by many steps, and copied back.

IsoMP (one sweep over the chain per iteration, 72 bytes per spin moved: read ``x`` and ``w``,
write ``G``):

.. math::

    b_i = c\,(x_{i-1} + x_{i+1}), \qquad
    G_i = w_i + \tfrac h2\, b_i \times x_i - \tfrac{h^2}{4} (b_i\cdot x_i)\, b_i,

and :math:`w_{k+1,i} = w_i + h\, b_i \times x_i` at the accepted ``x``.

Spherical midpoint (unknown ``M = (w_k + w_{k+1})/2``, two sweeps per iteration):

.. math::

    m_i = \sqrt{|w_i|\,|2M_i - w_i|}\; M_i/|M_i|, \qquad
    G_i = w_i + \tfrac h2\, B_i(m) \times m_i,

and :math:`w_{k+1} = w_k + h\, B(m)\times m`. Both use the stopping rules of
:mod:`isoflow.nonlinear` (per ensemble member; the residual is the Euclidean norm over the
chain) and the same stage-offset extrapolation as the NumPy paths. Chains with at least
``PARALLEL_MIN_SPINS`` spins are split into chunks over numba threads.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

__all__ = ["advance_spin", "to_aos", "to_soa"]

from ._rules import STATUS_CONVERGED as _CONVERGED
from ._rules import STATUS_MAX_ITER as _MAX_ITER
from ._rules import STATUS_RUNNING, stopping_step

_ISOMP, _SMM = 0, 1
#: Reassociation (and no signed zeros) only: lets LLVM vectorize the residual reductions
#: (2.4x faster sweeps); results differ from the NumPy path at the last bit, not more.
_FM = {"reassoc", "nsz"}


@numba.njit(cache=True, inline="always", fastmath=_FM)
def _iso_one(X, W, G, i, im, ip, c, half, quarter):  # type: ignore[no-untyped-def]
    x0, x1, x2 = X[0, i], X[1, i], X[2, i]
    b0 = c * (X[0, im] + X[0, ip])
    b1 = c * (X[1, im] + X[1, ip])
    b2 = c * (X[2, im] + X[2, ip])
    d = b0 * x0 + b1 * x1 + b2 * x2
    g0 = W[0, i] + half * (b1 * x2 - b2 * x1) + quarter * (-d * b0)
    g1 = W[1, i] + half * (b2 * x0 - b0 * x2) + quarter * (-d * b1)
    g2 = W[2, i] + half * (b0 * x1 - b1 * x0) + quarter * (-d * b2)
    G[0, i] = g0
    G[1, i] = g1
    G[2, i] = g2
    return (g0 - x0) ** 2 + (g1 - x1) ** 2 + (g2 - x2) ** 2


@numba.njit(cache=True, inline="always", fastmath=_FM)
def _smm_one(m, W, G, i, im, ip, c, half):  # type: ignore[no-untyped-def]
    x0, x1, x2 = m[0, i], m[1, i], m[2, i]
    b0 = c * (m[0, im] + m[0, ip])
    b1 = c * (m[1, im] + m[1, ip])
    b2 = c * (m[2, im] + m[2, ip])
    G[0, i] = W[0, i] + half * (b1 * x2 - b2 * x1)
    G[1, i] = W[1, i] + half * (b2 * x0 - b0 * x2)
    G[2, i] = W[2, i] + half * (b0 * x1 - b1 * x0)


@numba.njit(cache=True, inline="always", fastmath=_FM)
def _point_one(M, W, m, i):  # type: ignore[no-untyped-def]
    w0, w1, w2 = W[0, i], W[1, i], W[2, i]
    a0, a1, a2 = M[0, i], M[1, i], M[2, i]
    nw = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    v0, v1, v2 = 2.0 * a0 - w0, 2.0 * a1 - w1, 2.0 * a2 - w2
    nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    nm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    f = math.sqrt(nw * nv) / nm if nm > 0 else 0.0
    m[0, i] = f * a0
    m[1, i] = f * a1
    m[2, i] = f * a2


@numba.njit(cache=True, inline="always", fastmath=_FM)
def _res_one(G, X, i):  # type: ignore[no-untyped-def]
    return (G[0, i] - X[0, i]) ** 2 + (G[1, i] - X[1, i]) ** 2 + (G[2, i] - X[2, i]) ** 2


# ---- one sweep, serial and threaded (textually the same loops) -------------------------------
# The *_ser / *_par pairs below are separate functions on purpose: numba's on-disk cache keys
# an entry by signature, machine and bytecode only (not by ``parallel=``), so one body
# compiled twice with ``cache=True`` would share a cache entry.
@numba.njit(cache=True, fastmath=_FM)
def _sweep_ser(kind, X, W, G, m, c, half, quarter):  # type: ignore[no-untyped-def]
    N = X.shape[1]
    rr = 0.0
    if kind == _ISOMP:
        rr += _iso_one(X, W, G, 0, N - 1, 1 % N, c, half, quarter)
        for i in range(1, N - 1):
            rr += _iso_one(X, W, G, i, i - 1, i + 1, c, half, quarter)
        if N > 1:
            rr += _iso_one(X, W, G, N - 1, N - 2, 0, c, half, quarter)
        return rr
    _point_range(X, W, m, 0, N)
    _smm_one(m, W, G, 0, N - 1, 1 % N, c, half)
    rr = _res_one(G, X, 0)
    if N > 1:
        _smm_one(m, W, G, N - 1, N - 2, 0, c, half)
        rr += _res_one(G, X, N - 1)
        rr += _smm_range(X, W, G, m, c, half, 1, N - 1)
    return rr


@numba.njit(cache=True, fastmath=_FM)
def _iso_range(X, W, G, c, half, quarter, lo, hi):  # type: ignore[no-untyped-def]
    """IsoMP sweep over the interior particles ``lo <= i < hi`` (``1 <= lo``, ``hi <= N - 1``)."""
    acc = 0.0
    for i in range(lo, hi):
        acc += _iso_one(X, W, G, i, i - 1, i + 1, c, half, quarter)
    return acc


@numba.njit(cache=True, fastmath=_FM)
def _point_range(X, W, m, lo, hi):  # type: ignore[no-untyped-def]
    for i in range(lo, hi):
        _point_one(X, W, m, i)


@numba.njit(cache=True, fastmath=_FM)
def _smm_range(X, W, G, m, c, half, lo, hi):  # type: ignore[no-untyped-def]
    acc = 0.0
    for i in range(lo, hi):
        _smm_one(m, W, G, i, i - 1, i + 1, c, half)
        acc += _res_one(G, X, i)
    return acc


@numba.njit(cache=True, parallel=True)
def _sweep_par(kind, X, W, G, m, c, half, quarter, nch):  # type: ignore[no-untyped-def]
    """:func:`_sweep_ser` with the chain cut into ``nch`` chunks over numba threads.

    Each chunk is a call of a separately compiled (vectorized) range kernel.
    """
    N = X.shape[1]
    size = (N + nch - 1) // nch
    part = np.zeros(nch)
    if kind == _ISOMP:
        for ch in numba.prange(nch):
            lo = max(ch * size, 1)
            hi = min((ch + 1) * size, N - 1)
            if lo < hi:
                part[ch] = _iso_range(X, W, G, c, half, quarter, lo, hi)
        rr = part.sum()
        rr += _iso_one(X, W, G, 0, N - 1, 1, c, half, quarter)
        rr += _iso_one(X, W, G, N - 1, N - 2, 0, c, half, quarter)
        return rr
    for ch in numba.prange(nch):
        lo = ch * size
        hi = min((ch + 1) * size, N)
        if lo < hi:
            _point_range(X, W, m, lo, hi)
    for ch in numba.prange(nch):
        lo = max(ch * size, 1)
        hi = min((ch + 1) * size, N - 1)
        if lo < hi:
            part[ch] = _smm_range(X, W, G, m, c, half, lo, hi)
    _smm_one(m, W, G, 0, N - 1, 1, c, half)
    _smm_one(m, W, G, N - 1, N - 2, 0, c, half)
    return part.sum() + _res_one(G, X, 0) + _res_one(G, X, N - 1)


@numba.njit(cache=True, fastmath=_FM)
def _guess_range(out, W, hist, m, head, nh, coefs, lo, hi):  # type: ignore[no-untyped-def]
    """``out = W + sum_q a_q D_q`` on particles ``[lo, hi)`` (ring ``hist[:, m]``);
    returns ``|W|^2`` there. The slots and weights are resolved outside the loops (branches
    for up to four offsets) so that the loops vectorize."""
    K = hist.shape[0] - 1
    acc = 0.0
    if nh == 0:
        for a in range(3):
            for i in range(lo, hi):
                w = W[a, i]
                acc += w * w
                out[a, i] = w
        return acc
    a0 = coefs[nh - 1, 0]
    D0 = hist[head, m]
    if nh == 1:
        for a in range(3):
            for i in range(lo, hi):
                w = W[a, i]
                acc += w * w
                out[a, i] = w + a0 * D0[a, i]
        return acc
    a1 = coefs[nh - 1, 1]
    D1 = hist[(head - 1) % K, m]
    if nh == 2:
        for a in range(3):
            for i in range(lo, hi):
                w = W[a, i]
                acc += w * w
                out[a, i] = w + (a0 * D0[a, i] + a1 * D1[a, i])
        return acc
    a2 = coefs[nh - 1, 2]
    D2 = hist[(head - 2) % K, m]
    if nh == 3:
        for a in range(3):
            for i in range(lo, hi):
                w = W[a, i]
                acc += w * w
                out[a, i] = w + (a0 * D0[a, i] + a1 * D1[a, i] + a2 * D2[a, i])
        return acc
    a3 = coefs[nh - 1, 3]
    D3 = hist[(head - 3) % K, m]
    for a in range(3):
        for i in range(lo, hi):
            w = W[a, i]
            acc += w * w
            e = a0 * D0[a, i] + a1 * D1[a, i] + a2 * D2[a, i] + a3 * D3[a, i]
            for q in range(4, nh):
                e += coefs[nh - 1, q] * hist[(head - q) % K, m, a, i]
            out[a, i] = w + e
    return acc


@numba.njit(cache=True, parallel=True)
def _guess_par(out, W, hist, m, head, nh, coefs, nch):  # type: ignore[no-untyped-def]
    """:func:`_guess_range` over chunks of the chain on numba threads."""
    N = W.shape[1]
    size = (N + nch - 1) // nch
    part = np.zeros(nch)
    for ch in numba.prange(nch):
        lo = ch * size
        hi = min((ch + 1) * size, N)
        if lo < hi:
            part[ch] = _guess_range(out, W, hist, m, head, nh, coefs, lo, hi)
    return part.sum()


@numba.njit(cache=True)
def _guess_ser(out, W, hist, m, head, nh, coefs):  # type: ignore[no-untyped-def]
    """``out = W + sum_q a_q D_q`` (or ``W`` when ``nh = 0``); returns ``|W|^2``."""
    return _guess_range(out, W, hist, m, head, nh, coefs, 0, W.shape[1])


@numba.njit(cache=True, inline="always", fastmath=_FM)
def _final_one(Y, X, W, Wn, D, i, im, ip, c, h):  # type: ignore[no-untyped-def]
    y0, y1, y2 = Y[0, i], Y[1, i], Y[2, i]
    b0 = c * (Y[0, im] + Y[0, ip])
    b1 = c * (Y[1, im] + Y[1, ip])
    b2 = c * (Y[2, im] + Y[2, ip])
    w0, w1, w2 = W[0, i], W[1, i], W[2, i]
    v0 = w0 + h * (b1 * y2 - b2 * y1)
    v1 = w1 + h * (b2 * y0 - b0 * y2)
    v2 = w2 + h * (b0 * y1 - b1 * y0)
    Wn[0, i] = v0
    Wn[1, i] = v1
    Wn[2, i] = v2
    D[0, i] = X[0, i] - w0
    D[1, i] = X[1, i] - w1
    D[2, i] = X[2, i] - w2
    return abs(v0) + abs(v1) + abs(v2)


@numba.njit(cache=True, fastmath=_FM)
def _final_range(Y, X, W, Wn, D, c, h, lo, hi):  # type: ignore[no-untyped-def]
    """Interior particles ``[lo, hi)``; returns a sum that is finite iff every entry is."""
    acc = 0.0
    for i in range(lo, hi):
        acc += _final_one(Y, X, W, Wn, D, i, i - 1, i + 1, c, h)
    return acc


@numba.njit(cache=True)
def _final_ser(Y, X, W, Wn, D, c, h):  # type: ignore[no-untyped-def]
    """``Wn = W + h B(Y) x Y`` (``Y = x`` for IsoMP, ``m`` for SMM) and ``D = X - W``."""
    N = X.shape[1]
    acc = _final_one(Y, X, W, Wn, D, 0, N - 1, 1 % N, c, h)
    if N > 1:
        acc += _final_one(Y, X, W, Wn, D, N - 1, N - 2, 0, c, h)
        acc += _final_range(Y, X, W, Wn, D, c, h, 1, N - 1)
    return math.isfinite(acc)


@numba.njit(cache=True, parallel=True)
def _final_par(Y, X, W, Wn, D, c, h, nch):  # type: ignore[no-untyped-def]
    N = X.shape[1]
    size = (N + nch - 1) // nch
    part = np.zeros(nch)
    for ch in numba.prange(nch):
        lo = max(ch * size, 1)
        hi = min((ch + 1) * size, N - 1)
        if lo < hi:
            part[ch] = _final_range(Y, X, W, Wn, D, c, h, lo, hi)
    acc = part.sum()
    acc += _final_one(Y, X, W, Wn, D, 0, N - 1, 1, c, h)
    acc += _final_one(Y, X, W, Wn, D, N - 1, N - 2, 0, c, h)
    return math.isfinite(acc)


@numba.njit(cache=True)
def _drive(  # type: ignore[no-untyped-def]
    kind, par, W, Wn, X, G, m, hist, head, nh, kmax, coefs, c, h, nsteps,
    rtol, atol, stall_rtol, divf, max_iter, its, res, stat, totals, nch,
):  # fmt: skip
    """Step-synchronous loop over ``nsteps`` steps of every member of ``W`` (``(M, 3, N)``).

    ``W`` and ``Wn`` are swapped after every accepted step (no copy); the returned flag says
    whether the current state ended up in ``Wn``. ``hist`` gets a scratch slot ``K - 1`` beyond
    the ``kmax`` offsets in use.
    """
    M = W.shape[0]
    K = hist.shape[0] - 1
    half = 0.5 * h
    quarter = 0.25 * h * h
    it_tot = 0
    it_max = 0
    res_max = 0.0
    swapped = False
    scratch = K
    for step in range(nsteps):
        ok = True
        new = (head + 1) % K if kmax > 0 else scratch
        for mm in range(M):
            Wm = W[mm]
            if par:
                sc = _guess_par(X[mm], Wm, hist, mm, head, nh, coefs, nch)
            else:
                sc = _guess_ser(X[mm], Wm, hist, mm, head, nh, coefs)
            scale = math.sqrt(sc)
            tol = atol + rtol * scale
            floor = stall_rtol * scale
            prev = math.inf
            first = math.inf
            status = _MAX_ITER
            r = math.inf
            it = 0
            cur = X[mm]
            nxt = G
            in_x = True
            for it in range(1, max_iter + 1):
                if par:
                    rr = _sweep_par(kind, cur, Wm, nxt, m, c, half, quarter, nch)
                else:
                    rr = _sweep_ser(kind, cur, Wm, nxt, m, c, half, quarter)
                r = math.sqrt(rr)
                code, prev, first = stopping_step(r, prev, first, it, tol, floor, divf)
                if code != STATUS_RUNNING:
                    status = code
                    break
                cur, nxt = nxt, cur
                in_x = not in_x
            if not in_x:
                X[mm, :, :] = cur  # the accepted iterate lives in G: bring it home
            Y = X[mm] if kind == _ISOMP else m
            if par:
                fin = _final_par(Y, X[mm], Wm, Wn[mm], hist[new, mm], c, h, nch)
            else:
                fin = _final_ser(Y, X[mm], Wm, Wn[mm], hist[new, mm], c, h)
            its[mm] = it
            res[mm] = r
            stat[mm] = status
            it_tot += it
            it_max = max(it_max, it)
            if status != _CONVERGED or not fin:
                ok = False
        if not ok:
            totals[0] = it_tot
            totals[1] = it_max
            totals[2] = res_max
            return step, head, nh, swapped
        for mm in range(M):
            res_max = max(res_max, res[mm])
        W, Wn = Wn, W
        swapped = not swapped
        if kmax > 0:
            head = new
            nh = min(nh + 1, kmax)
    totals[0] = it_tot
    totals[1] = it_max
    totals[2] = res_max
    return nsteps, head, nh, swapped


@numba.njit(cache=True)
def _aos_to_soa(src, dst):  # type: ignore[no-untyped-def]
    """``dst[m, a, i] = src[m, i, a]``: ``(M, N, 3)`` (any strides) into ``(M, 3, N)``.

    NumPy's strided copy of this transpose runs at a fraction of the memory bandwidth (0.4 s
    for ``N = 1e7``); this loop reads ``src`` in order and writes three unit-stride streams.
    """
    for m in range(src.shape[0]):
        for i in range(src.shape[1]):
            dst[m, 0, i] = src[m, i, 0]
            dst[m, 1, i] = src[m, i, 1]
            dst[m, 2, i] = src[m, i, 2]


@numba.njit(cache=True)
def _soa_to_aos(src, dst):  # type: ignore[no-untyped-def]
    """``dst[m, i, a] = src[m, a, i]``: ``(M, 3, N)`` into ``(M, N, 3)`` (three unit-stride
    reads, one sequential write)."""
    for m in range(src.shape[0]):
        for i in range(src.shape[2]):
            dst[m, i, 0] = src[m, 0, i]
            dst[m, i, 1] = src[m, 1, i]
            dst[m, i, 2] = src[m, 2, i]


def to_soa(y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """A new (or ``out``) ``(M, 3, N)`` float64 array of the particles of ``y`` ``(M, N, 3)``."""
    if out is None:
        out = np.empty((y.shape[0], 3, y.shape[1]))
    _aos_to_soa(np.asarray(y, dtype=np.float64), out)
    return out


def to_aos(A: np.ndarray) -> np.ndarray:
    """A new C-contiguous ``(M, N, 3)`` array from the ``(M, 3, N)`` layout."""
    out = np.empty((A.shape[0], A.shape[2], 3))
    _soa_to_aos(A, out)
    return out


def advance_spin(
    kind: str,
    W: np.ndarray,
    hist: np.ndarray,
    nh: int,
    extrapolate: bool,
    coefs: np.ndarray,
    coupling: float,
    h: float,
    nsteps: int,
    rtol: float,
    atol: float,
    stall_rtol: float,
    divergence_factor: float,
    max_iter: int,
    parallel: bool,
) -> dict[str, Any]:
    """Advance ``W`` (``(M, 3, N)``, C-contiguous, overwritten) by ``nsteps`` steps.

    The new state is returned as ``"y"`` (``W`` or a second buffer).

    ``kind`` is ``"isomp"`` or ``"smm"``; ``hist`` (``(K + 1, M, 3, N)``, the last slot is
    scratch) holds the last ``nh`` stage offsets, oldest first, and is returned reordered the
    same way (see :func:`isoflow._fast.dense.advance_elementwise` for the other outputs).
    """
    M, _, N = W.shape
    K = hist.shape[0] - 1
    X = np.empty_like(W)
    Wn = np.empty_like(W)
    G = np.empty((3, N))
    m = np.empty((3, N)) if kind == "smm" else np.empty((3, 1))
    its = np.zeros(M, dtype=np.int64)
    res = np.zeros(M)
    stat = np.zeros(M, dtype=np.int64)
    totals = np.zeros(3)
    head = (nh - 1) % K
    done, head, nh_out, swapped = _drive(
        _ISOMP if kind == "isomp" else _SMM, bool(parallel and N >= 8), W, Wn, X, G, m, hist,
        head, nh, K if extrapolate else 0, coefs, float(coupling), float(h), int(nsteps),
        float(rtol), float(atol), float(stall_rtol), float(divergence_factor), int(max_iter),
        its, res, stat, totals, 8 * numba.get_num_threads() if parallel else 1,
    )  # fmt: skip
    y = Wn if swapped else W
    y_failed = W if swapped else Wn
    order = [(head - q) % K for q in range(nh_out)][::-1]
    return {
        "y": y,
        "n_done": int(done),
        "hist": [hist[q] for q in order],
        "iterations": its,
        "residual": res,
        "status": stat,
        "stage": X,
        "y_failed": y_failed,
        "iterations_total": int(totals[0]),
        "iterations_max": int(totals[1]),
        "residual_max": float(totals[2]),
    }
