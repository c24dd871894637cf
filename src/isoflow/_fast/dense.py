r"""Compiled IsoMP loop for ``B(W) = C \circ W`` on the structured matrix spaces.

The spaces are ``V = {X : sigma(X) = X}`` with :math:`\sigma(Y) = s\,\bar Y^T`, ``s = -1`` for
:math:`\mathfrak{so}(n)`, :math:`\mathfrak{u}(n)` and ``s = +1`` for ``Sym(n)``, ``Herm(n)``
(``B`` in the normalizer). One fixed-point iteration is, with ``P = B X`` and ``B = C \circ X``,

.. math::

    [B, X] = P + \sigma(P), \qquad B X B = P B, \qquad
    G(X) = \Pi\big(W_k + \tfrac h2 [B, X] + \tfrac{h^2}{4} P B\big), \qquad
    \Pi(Y) = \tfrac12 (Y + \sigma(Y)),

one evaluation of ``B`` and two matrix products, exactly as the NumPy path
(:meth:`isoflow.IsoMP.stage_problem`), with the same stopping rules
(:mod:`isoflow.nonlinear`) and the same polynomial extrapolation of the stage offset
``X - W`` (:class:`isoflow.IsoMP`). The whole time loop (many steps) runs in machine code; an
ensemble is advanced step-synchronously with the members distributed over numba threads
(``prange``), so a failing member stops the ensemble at that step, as in the NumPy path.

These loops are for small ``n`` (written-out products, no BLAS); large ``n`` goes through
:mod:`isoflow._fast.blas`.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

__all__ = ["advance_elementwise"]

from ._rules import STATUS_CONVERGED as _CONVERGED
from ._rules import STATUS_MAX_ITER as _MAX_ITER
from ._rules import STATUS_RUNNING, stopping_step

#: Reassociation and fused multiply-add: vectorized products and residual sums. Results differ
#: from the NumPy path (BLAS) only by rounding, as two BLAS builds would.
_FM = {"reassoc", "nsz", "contract"}


@numba.njit(cache=True, inline="always")
def _abs2(z):  # type: ignore[no-untyped-def]
    return z.real * z.real + z.imag * z.imag


@numba.njit(cache=True, fastmath=_FM)
def _member_step(  # type: ignore[no-untyped-def]
    W, X, G, Bm, P, T, Cm, Wn, hist, m, head, nh, coefs, coeff, s, h, traceless,
    rtol, atol, stall_rtol, divf, max_iter,
):  # fmt: skip
    """One IsoMP step of member ``m``; returns ``(iterations, residual, status, finite)``."""
    n = W.shape[0]
    K = hist.shape[0]
    half = 0.5 * h
    quarter = 0.25 * h * h
    # initial guess X0 = W + sum_j a_j D_j (D_1 the newest offset)
    if nh == 0:
        for i in range(n):
            for j in range(n):
                X[i, j] = W[i, j]
    else:
        s1 = head
        for i in range(n):
            for j in range(n):
                e = coefs[nh - 1, 0] * hist[s1, m, i, j]
                for q in range(1, nh):
                    e = e + coefs[nh - 1, q] * hist[(head - q) % K, m, i, j]
                X[i, j] = W[i, j] + e
    sc = 0.0
    for i in range(n):
        for j in range(n):
            sc += _abs2(W[i, j])
    scale = math.sqrt(sc)
    tol = atol + rtol * scale
    floor = stall_rtol * scale
    prev = math.inf
    first = math.inf
    status = _MAX_ITER
    r = math.inf
    it = 0
    for it in range(1, max_iter + 1):
        for i in range(n):
            for j in range(n):
                Bm[i, j] = coeff[i, j] * X[i, j]
        # P = B X
        for i in range(n):
            for j in range(n):
                P[i, j] = 0.0
            for k in range(n):
                b = Bm[i, k]
                for j in range(n):
                    P[i, j] += b * X[k, j]
        # T = P B
        for i in range(n):
            for j in range(n):
                T[i, j] = 0.0
            for k in range(n):
                p = P[i, k]
                for j in range(n):
                    T[i, j] += p * Bm[k, j]
        for i in range(n):
            for j in range(n):
                Cm[i, j] = P[i, j] + s * P[j, i].conjugate()
        for i in range(n):
            for j in range(n):
                G[i, j] = W[i, j] + half * Cm[i, j] + quarter * T[i, j]
        rr = 0.0
        for i in range(n):
            for j in range(i, n):
                a = 0.5 * (G[i, j] + s * G[j, i].conjugate())
                b2 = 0.5 * (G[j, i] + s * G[i, j].conjugate())
                rr += _abs2(a - X[i, j])
                if j != i:
                    rr += _abs2(b2 - X[j, i])
                P[i, j] = a  # P is free now: store the projected G
                P[j, i] = b2
        r = math.sqrt(rr)
        code, prev, first = stopping_step(r, prev, first, it, tol, floor, divf)
        if code != STATUS_RUNNING:
            status = code
            break
        for i in range(n):
            for j in range(n):
                X[i, j] = P[i, j]
    finite = True
    for i in range(n):
        for j in range(n):
            G[i, j] = W[i, j] + h * Cm[i, j]
    for i in range(n):
        for j in range(n):
            v = 0.5 * (G[i, j] + s * G[j, i].conjugate())
            Wn[i, j] = v
            if not (math.isfinite(v.real) and math.isfinite(v.imag)):
                finite = False
    if traceless:  # su(n): the state space's projection also removes the trace
        tr = Wn[0, 0]
        for i in range(1, n):
            tr += Wn[i, i]
        tr = tr / n
        for i in range(n):
            Wn[i, i] -= tr
    return it, r, status, finite


@numba.njit(cache=True)
def _accept(W, Wn, X, hist, m, slot):  # type: ignore[no-untyped-def]
    n = W.shape[0]
    for i in range(n):
        for j in range(n):
            hist[slot, m, i, j] = X[i, j] - W[i, j]
            W[i, j] = Wn[i, j]


# Serial and parallel drivers are separate functions on purpose: numba's on-disk cache keys an
# entry by signature, machine and bytecode only (not by ``parallel=``), so one body compiled
# twice with ``cache=True`` would share a cache entry and one variant could load the other.
@numba.njit(cache=True)
def _drive_serial(  # type: ignore[no-untyped-def]
    W, Xs, Wns, work, hist, head, nh, coefs, coeff, s, h, traceless, nsteps,
    rtol, atol, stall_rtol, divf, max_iter, its, res, stat, totals, kmax,
):  # fmt: skip
    M = W.shape[0]
    K = hist.shape[0]
    it_tot = 0
    it_max = 0
    res_max = 0.0
    for step in range(nsteps):
        ok = True
        for m in range(M):
            it, r, st, fin = _member_step(
                W[m], Xs[m], work[0, m], work[1, m], work[2, m], work[3, m], work[4, m],
                Wns[m], hist, m, head, nh, coefs, coeff, s, h, traceless,
                rtol, atol, stall_rtol, divf, max_iter,
            )  # fmt: skip
            its[m] = it
            res[m] = r
            stat[m] = st
            if st != _CONVERGED or not fin:
                ok = False
            it_tot += it
            if it > it_max:
                it_max = it
        if not ok:
            totals[0] = it_tot
            totals[1] = it_max
            totals[2] = res_max
            return step, head, nh
        for m in range(M):
            if res[m] > res_max:
                res_max = res[m]
        new = (head + 1) % K
        for m in range(M):
            _accept(W[m], Wns[m], Xs[m], hist, m, new)
        head = new
        nh = min(nh + 1, kmax)
    totals[0] = it_tot
    totals[1] = it_max
    totals[2] = res_max
    return nsteps, head, nh


@numba.njit(cache=True, parallel=True)
def _drive_parallel(  # type: ignore[no-untyped-def]
    W, Xs, Wns, work, hist, head, nh, coefs, coeff, s, h, traceless, nsteps,
    rtol, atol, stall_rtol, divf, max_iter, its, res, stat, totals, kmax,
):  # fmt: skip
    M = W.shape[0]
    K = hist.shape[0]
    it_tot = 0
    it_max = 0
    res_max = 0.0
    bad = np.zeros(M, dtype=np.bool_)
    for step in range(nsteps):
        for m in numba.prange(M):
            it, r, st, fin = _member_step(
                W[m], Xs[m], work[0, m], work[1, m], work[2, m], work[3, m], work[4, m],
                Wns[m], hist, m, head, nh, coefs, coeff, s, h, traceless,
                rtol, atol, stall_rtol, divf, max_iter,
            )  # fmt: skip
            its[m] = it
            res[m] = r
            stat[m] = st
            bad[m] = st != _CONVERGED or not fin
        it_tot += its.sum()
        it_max = max(it_max, its.max())
        if bad.any():
            totals[0] = it_tot
            totals[1] = it_max
            totals[2] = res_max
            return step, head, nh
        res_max = max(res_max, res.max())
        new = (head + 1) % K
        for m in numba.prange(M):
            _accept(W[m], Wns[m], Xs[m], hist, m, new)
        head = new
        nh = min(nh + 1, kmax)
    totals[0] = it_tot
    totals[1] = it_max
    totals[2] = res_max
    return nsteps, head, nh


def advance_elementwise(
    W: np.ndarray,
    hist: np.ndarray,
    nh: int,
    coefs: np.ndarray,
    coeff: np.ndarray,
    s: float,
    h: float,
    nsteps: int,
    rtol: float,
    atol: float,
    stall_rtol: float,
    divergence_factor: float,
    max_iter: int,
    parallel: bool,
    extrapolate: bool = True,
    traceless: bool = False,
) -> dict[str, Any]:
    """Advance the stacked members ``W`` (``(M, n, n)``, modified in place) by ``nsteps`` steps.

    ``hist`` (``(K, M, n, n)``) holds the last ``nh`` stage offsets ``X - W``, newest in slot
    ``nh - 1`` (ordered oldest to newest); ``coefs[m-1, :m]`` are the extrapolation weights
    for ``m`` offsets. On return ``hist`` is reordered the same way. Returns the number of
    accepted steps, the per-member record of the last attempted step, the stage and new state
    of a failed step, and the iteration totals.
    """
    M, n = W.shape[0], W.shape[1]
    K = hist.shape[0]
    Xs = np.empty_like(W)
    Wns = np.empty_like(W)
    work = np.empty((5, M, n, n), dtype=W.dtype)
    its = np.zeros(M, dtype=np.int64)
    res = np.zeros(M, dtype=np.float64)
    stat = np.zeros(M, dtype=np.int64)
    totals = np.zeros(3, dtype=np.float64)
    head = (nh - 1) % K
    drive = _drive_parallel if parallel else _drive_serial
    done, head, nh_out = drive(
        W, Xs, Wns, work, hist, head, nh, coefs, coeff, float(s), float(h), traceless, int(nsteps),
        float(rtol), float(atol), float(stall_rtol), float(divergence_factor), int(max_iter),
        its, res, stat, totals, K if extrapolate else 0,
    )  # fmt: skip
    order = [(head - q) % K for q in range(nh_out)][::-1]  # oldest .. newest
    return {
        "n_done": int(done),
        "hist": [hist[q] for q in order],
        "iterations": its,
        "residual": res,
        "status": stat,
        "stage": Xs,
        "y_failed": Wns,
        "iterations_total": int(totals[0]),
        "iterations_max": int(totals[1]),
        "residual_max": float(totals[2]),
    }


# ---- ensembles: blocks of members with the member index innermost ----------------------------
#: Members per block: the innermost (contiguous, vectorized) axis of the blocked layout.
LANES = 16


@numba.njit(cache=True, fastmath=_FM)
def _block_step(  # type: ignore[no-untyped-def]
    W, X, Wn, hist, blk, head, nh, coefs, coeff, s, h, traceless, valid,
    rtol, atol, stall_rtol, divf, max_iter, its, res, stat, fin,
):  # fmt: skip
    """One IsoMP step of the members of block ``blk`` (arrays ``(n, n, L)``, lanes last).

    Every lane follows the stopping rules on its own; a lane that stops is frozen (its ``X``
    is no longer updated; recomputing its bracket from the frozen ``X`` reproduces it).
    """
    n = W.shape[0]
    L = W.shape[2]
    K = hist.shape[0]
    half = 0.5 * h
    quarter = 0.25 * h * h
    Bm = np.empty_like(W)
    P = np.empty_like(W)
    T = np.empty_like(W)
    Cm = np.empty_like(W)
    G = np.empty_like(W)
    for i in range(n):
        for j in range(n):
            for q in range(L):
                X[i, j, q] = W[i, j, q]
    if nh > 0:
        for i in range(n):
            for j in range(n):
                for q in range(L):
                    e = coefs[nh - 1, 0] * hist[head, blk, i, j, q]
                    for p in range(1, nh):
                        e = e + coefs[nh - 1, p] * hist[(head - p) % K, blk, i, j, q]
                    X[i, j, q] = W[i, j, q] + e
    sc = np.zeros(L)
    for i in range(n):
        for j in range(n):
            for q in range(L):
                w = W[i, j, q]
                sc[q] += w.real * w.real + w.imag * w.imag
    tol = np.empty(L)
    floor = np.empty(L)
    prev = np.full(L, math.inf)
    first = np.full(L, math.inf)
    going = np.zeros(L, dtype=np.bool_)
    rr = np.zeros(L)
    for q in range(L):
        scale = math.sqrt(sc[q])
        tol[q] = atol + rtol * scale
        floor[q] = stall_rtol * scale
        going[q] = valid[q]
        stat[q] = _MAX_ITER if valid[q] else _CONVERGED
        its[q] = 0
        res[q] = 0.0
    for it in range(1, max_iter + 1):
        any_going = False
        for q in range(L):
            if going[q]:
                any_going = True
        if not any_going:
            break
        for i in range(n):
            for j in range(n):
                for q in range(L):
                    Bm[i, j, q] = coeff[i, j] * X[i, j, q]
        for i in range(n):
            for j in range(n):
                for q in range(L):
                    P[i, j, q] = 0.0
                    T[i, j, q] = 0.0
            for k in range(n):
                for j in range(n):
                    for q in range(L):
                        P[i, j, q] += Bm[i, k, q] * X[k, j, q]
            for k in range(n):
                for j in range(n):
                    for q in range(L):
                        T[i, j, q] += P[i, k, q] * Bm[k, j, q]
        for q in range(L):
            rr[q] = 0.0
        for i in range(n):
            for j in range(n):
                for q in range(L):
                    Cm[i, j, q] = P[i, j, q] + s * P[j, i, q].conjugate()
        for i in range(n):
            for j in range(n):
                for q in range(L):
                    P[i, j, q] = W[i, j, q] + half * Cm[i, j, q] + quarter * T[i, j, q]
        for i in range(n):
            for j in range(n):
                for q in range(L):
                    g = 0.5 * (P[i, j, q] + s * P[j, i, q].conjugate())
                    G[i, j, q] = g
                    d = g - X[i, j, q]
                    rr[q] += d.real * d.real + d.imag * d.imag
        for q in range(L):
            if not going[q]:
                continue
            r = math.sqrt(rr[q])
            its[q] = it
            res[q] = r
            code, prev[q], first[q] = stopping_step(
                r, prev[q], first[q], it, tol[q], floor[q], divf
            )
            if code != STATUS_RUNNING:
                stat[q] = code
                going[q] = False
        for i in range(n):
            for j in range(n):
                for q in range(L):
                    if going[q]:
                        X[i, j, q] = G[i, j, q]
    for i in range(n):
        for j in range(n):
            for q in range(L):
                P[i, j, q] = W[i, j, q] + h * Cm[i, j, q]
    for q in range(L):
        fin[q] = True
    for i in range(n):
        for j in range(n):
            for q in range(L):
                v = 0.5 * (P[i, j, q] + s * P[j, i, q].conjugate())
                Wn[i, j, q] = v
                if not (math.isfinite(v.real) and math.isfinite(v.imag)):
                    fin[q] = False
    if traceless:  # su(n): the state space's projection also removes the trace
        for q in range(L):
            tr = Wn[0, 0, q]
            for i in range(1, n):
                tr += Wn[i, i, q]
            tr = tr / n
            for i in range(n):
                Wn[i, i, q] -= tr


@numba.njit(cache=True)
def _accept_block(W, Wn, X, hist, blk, slot, keep):  # type: ignore[no-untyped-def]
    n = W.shape[0]
    L = W.shape[2]
    for i in range(n):
        for j in range(n):
            for q in range(L):
                if keep:
                    hist[slot, blk, i, j, q] = X[i, j, q] - W[i, j, q]
                W[i, j, q] = Wn[i, j, q]


# Serial and parallel drivers are separate functions on purpose: numba's on-disk cache keys an
# entry by signature, machine and bytecode only (not by ``parallel=``), so one body compiled
# twice with ``cache=True`` would share a cache entry and one variant could load the other.
@numba.njit(cache=True, parallel=True)
def _drive_blocks_par(  # type: ignore[no-untyped-def]
    W, Xs, Wns, hist, head, nh, kmax, coefs, coeff, s, h, traceless, nsteps, valid,
    rtol, atol, stall_rtol, divf, max_iter, its, res, stat, fin, totals,
):  # fmt: skip
    nb = W.shape[0]
    K = hist.shape[0]
    it_tot = 0
    it_max = 0
    res_max = 0.0
    for step in range(nsteps):
        for b in numba.prange(nb):
            _block_step(
                W[b], Xs[b], Wns[b], hist, b, head, nh, coefs, coeff, s, h, traceless, valid[b],
                rtol, atol, stall_rtol, divf, max_iter, its[b], res[b], stat[b], fin[b],
            )  # fmt: skip
        ok = True
        for b in range(nb):
            for q in range(W.shape[3]):
                if valid[b, q]:
                    it_tot += its[b, q]
                    it_max = max(it_max, its[b, q])
                    if stat[b, q] != _CONVERGED or not fin[b, q]:
                        ok = False
        if not ok:
            totals[0] = it_tot
            totals[1] = it_max
            totals[2] = res_max
            return step, head, nh
        for b in range(nb):
            for q in range(W.shape[3]):
                if valid[b, q]:
                    res_max = max(res_max, res[b, q])
        new = (head + 1) % K
        for b in numba.prange(nb):
            _accept_block(W[b], Wns[b], Xs[b], hist, b, new, kmax > 0)
        head = new
        nh = min(nh + 1, kmax)
    totals[0] = it_tot
    totals[1] = it_max
    totals[2] = res_max
    return nsteps, head, nh


@numba.njit(cache=True)
def _drive_blocks_ser(  # type: ignore[no-untyped-def]
    W, Xs, Wns, hist, head, nh, kmax, coefs, coeff, s, h, traceless, nsteps, valid,
    rtol, atol, stall_rtol, divf, max_iter, its, res, stat, fin, totals,
):  # fmt: skip
    nb = W.shape[0]
    K = hist.shape[0]
    it_tot = 0
    it_max = 0
    res_max = 0.0
    for step in range(nsteps):
        for b in range(nb):
            _block_step(
                W[b], Xs[b], Wns[b], hist, b, head, nh, coefs, coeff, s, h, traceless, valid[b],
                rtol, atol, stall_rtol, divf, max_iter, its[b], res[b], stat[b], fin[b],
            )  # fmt: skip
        ok = True
        for b in range(nb):
            for q in range(W.shape[3]):
                if valid[b, q]:
                    it_tot += its[b, q]
                    it_max = max(it_max, its[b, q])
                    if stat[b, q] != _CONVERGED or not fin[b, q]:
                        ok = False
        if not ok:
            totals[0] = it_tot
            totals[1] = it_max
            totals[2] = res_max
            return step, head, nh
        for b in range(nb):
            for q in range(W.shape[3]):
                if valid[b, q]:
                    res_max = max(res_max, res[b, q])
        new = (head + 1) % K
        for b in range(nb):
            _accept_block(W[b], Wns[b], Xs[b], hist, b, new, kmax > 0)
        head = new
        nh = min(nh + 1, kmax)
    totals[0] = it_tot
    totals[1] = it_max
    totals[2] = res_max
    return nsteps, head, nh


def _to_blocks(A: np.ndarray, nb: int) -> np.ndarray:
    """``(M, n, n)`` -> ``(nb, n, n, LANES)`` (zero padding), members innermost."""
    M, n = A.shape[0], A.shape[1]
    out = np.zeros((nb * LANES, n, n), dtype=A.dtype)
    out[:M] = A
    return np.ascontiguousarray(out.reshape(nb, LANES, n, n).transpose(0, 2, 3, 1))


def _from_blocks(A: np.ndarray, M: int) -> np.ndarray:
    nb, n = A.shape[0], A.shape[1]
    return np.ascontiguousarray(A.transpose(0, 3, 1, 2).reshape(nb * LANES, n, n)[:M])


def advance_elementwise_blocked(
    W: np.ndarray,
    hist: np.ndarray,
    nh: int,
    coefs: np.ndarray,
    coeff: np.ndarray,
    s: float,
    h: float,
    nsteps: int,
    rtol: float,
    atol: float,
    stall_rtol: float,
    divergence_factor: float,
    max_iter: int,
    parallel: bool,
    extrapolate: bool = True,
    traceless: bool = False,
) -> dict[str, Any]:
    """:func:`advance_elementwise` for ensembles, in the blocked member-innermost layout.

    Same inputs and outputs (``W`` is ``(M, n, n)``; the result state is returned as
    ``"y"``); members are grouped in blocks of :data:`LANES` so that every loop runs over
    contiguous members (SIMD) and a block stays in cache; blocks go to numba threads.
    """
    M = W.shape[0]
    K = hist.shape[0]
    nb = -(-M // LANES)
    Wb = _to_blocks(W, nb)
    hb = np.stack([_to_blocks(hist[k], nb) for k in range(K)])
    valid = np.zeros(nb * LANES, dtype=np.bool_)
    valid[:M] = True
    valid = valid.reshape(nb, LANES)
    Xs = np.empty_like(Wb)
    Wns = np.empty_like(Wb)
    its = np.zeros((nb, LANES), dtype=np.int64)
    res = np.zeros((nb, LANES))
    stat = np.zeros((nb, LANES), dtype=np.int64)
    fin = np.ones((nb, LANES), dtype=np.bool_)
    totals = np.zeros(3)
    head = (nh - 1) % K
    drive = _drive_blocks_par if parallel else _drive_blocks_ser
    done, head, nh_out = drive(
        Wb, Xs, Wns, hb, head, nh, K if extrapolate else 0, coefs, coeff, float(s), float(h),
        traceless, int(nsteps), valid, float(rtol), float(atol), float(stall_rtol),
        float(divergence_factor), int(max_iter), its, res, stat, fin, totals,
    )  # fmt: skip
    order = [(head - q) % K for q in range(nh_out)][::-1]
    return {
        "y": _from_blocks(Wb, M),
        "n_done": int(done),
        "hist": [_from_blocks(hb[q], M) for q in order],
        "iterations": its.reshape(-1)[:M].copy(),
        "residual": res.reshape(-1)[:M].copy(),
        "status": stat.reshape(-1)[:M].copy(),
        "stage": _from_blocks(Xs, M),
        "y_failed": _from_blocks(Wns, M),
        "iterations_total": int(totals[0]),
        "iterations_max": int(totals[1]),
        "residual_max": float(totals[2]),
    }
