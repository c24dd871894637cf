r"""Ensembles of an :class:`~isoflow.ElementwiseLinear` kernel: members innermost, SIMD lanes.

For many small systems with ``B(W) = C \circ W`` the member-by-member driver
(:mod:`isoflow._compiled.driver`) leaves the vector units idle (``n`` is small). This
specialized evaluation (benchmark 2) groups the members in blocks of :data:`LANES` and lays a
block out as ``(n, n, LANES)``, so that every loop of an iteration runs over contiguous members.
It is the same iteration as :func:`isoflow._compiled.dense.iterate_small` lane by lane, with
the shared pieces of the one driver: the initial guess and the ring of offsets act on a block
as one flat vector (:mod:`isoflow._compiled.flat`; they are entrywise), the stopping rules are
:mod:`isoflow.nonlinear`'s, per lane. A lane whose solve fails (or whose state turns
non-finite) is frozen at its last good state and recorded, as in the member driver.

Blocks are independent: each runs all its steps (block-outer loops), blocks over numba threads.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .driver import (
    REC_FAIL_ITERATIONS,
    REC_FAIL_RESIDUAL,
    REC_FAIL_STATUS,
    REC_FAIL_STEP,
    REC_ITERATIONS,
    REC_ITERATIONS_MAX,
    REC_RESIDUAL_MAX,
)
from .flat import guess, push
from .rules import CONTINUE, STATUS_CONVERGED, STATUS_MAX_ITER, STATUS_NON_FINITE, stopping_step

__all__ = ["LANES", "drive_blocks_parallel", "drive_blocks_serial", "from_blocks", "to_blocks"]

#: Members per block: the innermost (contiguous, vectorized) axis.
LANES = 16
_FM = {"reassoc", "nsz", "contract"}


@numba.njit(cache=True, fastmath=_FM)
def _iterate(W, X, G, C, Bm, P, T, coeff, s, half, quarter, rr):  # type: ignore[no-untyped-def]
    """One iteration of every lane of a block (``(n, n, L)`` arrays); ``rr`` per lane."""
    n = W.shape[0]
    L = W.shape[2]
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
                C[i, j, q] = P[i, j, q] + s * P[j, i, q].conjugate()
    for i in range(n):
        for j in range(n):
            for q in range(L):
                P[i, j, q] = W[i, j, q] + half * C[i, j, q] + quarter * T[i, j, q]
    for i in range(n):
        for j in range(n):
            for q in range(L):
                g = 0.5 * (P[i, j, q] + s * P[j, i, q].conjugate())
                G[i, j, q] = g
                d = g - X[i, j, q]
                rr[q] += d.real * d.real + d.imag * d.imag


@numba.njit(cache=True)
def _finish(W, C, h, Wn, traceless, fin):  # type: ignore[no-untyped-def]
    """``Wn = Pi_V(W + h C)`` lane by lane; ``fin[q]`` whether lane ``q`` is finite."""
    n = W.shape[0]
    L = W.shape[2]
    for q in range(L):
        fin[q] = True
    for i in range(n):
        for j in range(n):
            for q in range(L):
                v = W[i, j, q] + h * C[i, j, q]
                Wn[i, j, q] = v
                if not (math.isfinite(v.real) and math.isfinite(v.imag)):
                    fin[q] = False
    if traceless:
        for q in range(L):
            tr = Wn[0, 0, q]
            for i in range(1, n):
                tr += Wn[i, i, q]
            tr = tr / n
            for i in range(n):
                Wn[i, i, q] -= tr


@numba.njit(cache=True)
def run_block(  # type: ignore[no-untyped-def]
    Wb, ring, hn, coefs, kmax, coeff, s, traceless, valid,
    h, nsteps, k0, save_every, k_final, out, m0,
    rtol, atol, stall_rtol, divf, max_iter, rec,
):  # fmt: skip
    """Advance one block (``Wb`` ``(n, n, L)``, its ``ring`` ``(K, n*n*L)``, ``hn = [head,
    nh]``) by ``nsteps`` steps; lanes ``q`` with ``valid[q]`` are members ``m0 + q``, whose
    records are ``rec[m0 + q]`` and whose rows go to ``out[:, m0 + q]``."""
    n = Wb.shape[0]
    L = Wb.shape[2]
    S = n * n * L
    K = ring.shape[0]
    dt = Wb.dtype
    X = np.empty((n, n, L), dtype=dt)
    G = np.empty((n, n, L), dtype=dt)
    C = np.empty((n, n, L), dtype=dt)
    Bm = np.empty((n, n, L), dtype=dt)
    P = np.empty((n, n, L), dtype=dt)
    T = np.empty((n, n, L), dtype=dt)
    Wn = np.empty((n, n, L), dtype=dt)
    Wf = Wb.reshape(S)
    Xf = X.reshape(S)
    alive = np.zeros(L, dtype=np.bool_)
    going = np.zeros(L, dtype=np.bool_)
    code = np.zeros(L, dtype=np.int64)
    its = np.zeros(L, dtype=np.int64)
    res = np.zeros(L)
    prev = np.zeros(L)
    first = np.zeros(L)
    tol = np.zeros(L)
    floor = np.zeros(L)
    rr = np.zeros(L)
    fin = np.ones(L, dtype=np.bool_)
    sc = np.zeros(L)
    for q in range(L):
        alive[q] = valid[q] and rec[m0 + q, REC_FAIL_STEP] < 0
    half = 0.5 * h
    quarter = 0.25 * h * h
    row = 0
    for step in range(nsteps):
        k = k0 + step + 1
        any_alive = False
        for q in range(L):
            if alive[q]:
                any_alive = True
        if any_alive:
            guess(Wf, ring, hn[0], hn[1], coefs, Xf)
            for q in range(L):
                sc[q] = 0.0
            for i in range(n):
                for j in range(n):
                    for q in range(L):
                        w = Wb[i, j, q]
                        sc[q] += w.real * w.real + w.imag * w.imag
            for q in range(L):
                scale = math.sqrt(sc[q])
                tol[q] = atol + rtol * scale
                floor[q] = stall_rtol * scale
                prev[q] = math.inf
                first[q] = math.inf
                going[q] = alive[q]
                code[q] = STATUS_MAX_ITER
                its[q] = 0
                res[q] = math.inf
            for it in range(1, max_iter + 1):
                _iterate(Wb, X, G, C, Bm, P, T, coeff, s, half, quarter, rr)
                more = False
                for q in range(L):
                    if not going[q]:
                        continue
                    r = math.sqrt(rr[q])
                    its[q] = it
                    res[q] = r
                    c, prev[q], first[q] = stopping_step(
                        r, prev[q], first[q], it, tol[q], floor[q], divf
                    )
                    if c != CONTINUE:
                        code[q] = c
                        going[q] = False
                    else:
                        more = True
                if not more:
                    break
                for i in range(n):
                    for j in range(n):
                        for q in range(L):
                            if going[q]:
                                X[i, j, q] = G[i, j, q]
            _finish(Wb, C, h, Wn, traceless, fin)
            if kmax > 0:
                slot = (hn[0] + 1) % K
                push(ring, slot, Xf, Wf)
                hn[0] = slot
                hn[1] = min(hn[1] + 1, kmax)
            for q in range(L):
                if not alive[q]:
                    continue
                m = m0 + q
                rec[m, REC_ITERATIONS] += its[q]
                rec[m, REC_ITERATIONS_MAX] = max(rec[m, REC_ITERATIONS_MAX], its[q])
                if code[q] != STATUS_CONVERGED or not fin[q]:
                    rec[m, REC_FAIL_STEP] = k
                    rec[m, REC_FAIL_STATUS] = (
                        code[q] if code[q] != STATUS_CONVERGED else STATUS_NON_FINITE
                    )
                    rec[m, REC_FAIL_ITERATIONS] = its[q]
                    rec[m, REC_FAIL_RESIDUAL] = res[q]
                    alive[q] = False
                    continue
                rec[m, REC_RESIDUAL_MAX] = max(rec[m, REC_RESIDUAL_MAX], res[q])
                for i in range(n):
                    for j in range(n):
                        Wb[i, j, q] = Wn[i, j, q]
        if k % save_every == 0 or k == k_final:
            for q in range(L):
                if valid[q]:
                    o = out[row, m0 + q]
                    for i in range(n):
                        for j in range(n):
                            o[i * n + j] = Wb[i, j, q]
            row += 1


# Serial and parallel drivers are twins on purpose (numba's cache does not key on
# ``parallel=``; see :mod:`.driver`): one body compiled both ways would share a cache entry.
def drive_blocks_serial(  # type: ignore[no-untyped-def]
    Wb, ring, hn, coefs, kmax, coeff, s, traceless, valid,
    h, nsteps, k0, save_every, k_final, out,
    rtol, atol, stall_rtol, divf, max_iter, rec,
):  # fmt: skip
    """:func:`run_block` for every block of ``Wb`` (``(nb, n, n, L)``), one after another."""
    L = Wb.shape[3]
    for b in range(Wb.shape[0]):
        run_block(
            Wb[b], ring[b], hn[b], coefs, kmax, coeff, s, traceless, valid[b],
            h, nsteps, k0, save_every, k_final, out, b * L,
            rtol, atol, stall_rtol, divf, max_iter, rec,
        )  # fmt: skip


def drive_blocks_parallel(  # type: ignore[no-untyped-def]
    Wb, ring, hn, coefs, kmax, coeff, s, traceless, valid,
    h, nsteps, k0, save_every, k_final, out,
    rtol, atol, stall_rtol, divf, max_iter, rec,
):  # fmt: skip
    """:func:`run_block` for every block, blocks over numba threads."""
    L = Wb.shape[3]
    for b in numba.prange(Wb.shape[0]):
        run_block(
            Wb[b], ring[b], hn[b], coefs, kmax, coeff, s, traceless, valid[b],
            h, nsteps, k0, save_every, k_final, out, b * L,
            rtol, atol, stall_rtol, divf, max_iter, rec,
        )  # fmt: skip


# Separate functions on purpose (numba's cache key ignores ``parallel=``; see driver.py).
drive_blocks_serial = numba.njit(cache=True, nogil=True)(drive_blocks_serial)
drive_blocks_parallel = numba.njit(cache=True, parallel=True, nogil=True)(drive_blocks_parallel)


def to_blocks(A: np.ndarray, nb: int) -> np.ndarray:
    """``(M, n, n)`` -> ``(nb, n, n, LANES)`` (zero padding), members innermost."""
    M, n = A.shape[0], A.shape[1]
    out = np.zeros((nb * LANES, n, n), dtype=A.dtype)
    out[:M] = A
    return np.ascontiguousarray(out.reshape(nb, LANES, n, n).transpose(0, 2, 3, 1))


def from_blocks(A: np.ndarray, M: int) -> np.ndarray:
    """``(nb, n, n, LANES)`` -> ``(M, n, n)``."""
    nb, n = A.shape[0], A.shape[1]
    return np.ascontiguousarray(A.transpose(0, 3, 1, 2).reshape(nb * LANES, n, n)[:M])
