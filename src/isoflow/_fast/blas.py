r"""IsoMP on one large dense matrix: BLAS products into fixed buffers, half of the second one.

For ``so(n)``, ``u(n)``, ``su(n)``, ``Sym(n)``, ``Herm(n)`` (``V = {Y : sigma(Y) = Y}`` with
:math:`\sigma(Y) = s\,\bar Y^T`) and ``B`` in the normalizer, one fixed-point iteration is

.. math::

    B = B(X), \qquad P = B X, \qquad T = P B = B X B, \qquad
    G = W + \tfrac h2 \big(P + \sigma(P)\big) + \tfrac{h^2}{4}\, T .

Three facts of the structure are used:

* the commutator :math:`[B, X] = BX - XB = P + \sigma(P)` comes from the single product ``P``
  (:math:`XB = -\sigma(BX)`);
* :math:`T = BXB` lies in ``V`` (:math:`(BXB)^\dagger = B^\dagger X^\dagger B^\dagger` with
  :math:`B^\dagger = -B`), so only its lower block triangle is computed: block row ``i`` of
  ``T`` is ``P[rows_i, :] @ B[:, :end_i]``, about :math:`\tfrac12 + \tfrac1{2 n_b}` of a
  full product for ``n_b`` blocks (benchmark 3, ``isoflow bench --only 3``, reports the
  measured fraction as ``half_product_fraction``);
* ``W``, every iterate ``X`` and ``W_{k+1}`` are kept in ``V`` bit for bit (each strictly
  upper entry is written as ``s * conj`` of its mirror; for ``su(n)`` the trace of
  ``W_{k+1}`` is then removed, as by its projection), so ``|G - X|^2`` is summed over the
  lower triangle only; inside the time loop the states ``W`` and the stored offsets are only
  read, and so only written, on their lower triangles (mirrored when a call returns).

Everything after the products is one cache-blocked compiled pass over pairs of mirrored tiles
(bracket, iterate, residual), reading each of ``P`` and ``T`` once. ``B`` is the problem's
kernel (``C * X`` into a buffer) or, for any other ``B``, the problem's own ``problem.B`` (a
Python call that allocates its result, which is all it costs). The stopping rules and the
stage extrapolation are those of the NumPy path; results agree with it to rounding (the
NumPy path projects ``G`` onto ``V`` instead of mirroring it).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from ..methods._base import AdvanceResult, StepResult
from ..nonlinear import (
    STATUS_CONVERGED,
    STATUS_MAX_ITER,
    STATUS_RUNNING,
    stopping_step,
)
from ..problems import IsospectralProblem

__all__ = ["isomp_advance_large", "lower_blocks"]

Array = NDArray[Any]

_TILE = 32
#: Row-block height of the triangular product (a multiple of ``_TILE``; measured best).
_BLOCK = 128
#: Reassociation only (vectorized residual sums); results differ from NumPy by rounding.
_FM = {"reassoc", "nsz"}


def lower_blocks(n: int, block: int = _BLOCK) -> list[tuple[int, int]]:
    """Row ranges ``(r0, r1)`` of the lower-block-triangular product, tile aligned.

    At least two blocks once ``n >= 2 * _TILE`` (one block is a full product), at most eight.
    """
    nb = min(8, max(1, round(n / block)))
    size = -(-n // nb)
    size = -(-size // _TILE) * _TILE
    return [(r0, min(n, r0 + size)) for r0 in range(0, n, size)]


def lower_product(P: Array, B: Array, T: Array, blocks: list[tuple[int, int]]) -> None:
    """``T[r0:r1, :r1] = P[r0:r1] @ B[:, :r1]`` for every block: the lower block triangle of
    ``P @ B`` (strided views of C-ordered arrays go to BLAS without copies)."""
    for r0, r1 in blocks:
        np.matmul(P[r0:r1], B[:, :r1], out=T[r0:r1, :r1])


@numba.njit(cache=True, fastmath=_FM, inline="always")
def _load_t(A, bi, ie, bj, je, buf):  # type: ignore[no-untyped-def]
    """``buf[ii, jj] = A[bj + jj, bi + ii]``: the transposed tile, read row by row from ``A``."""
    for j in range(bj, je):
        for i in range(bi, ie):
            buf[i - bi, j - bj] = A[j, i]


@numba.njit(cache=True, fastmath=_FM)
def _combine(W, X, P, T, G, s, half, quarter):  # type: ignore[no-untyped-def]
    """``G = W + half (P + sigma(P)) + quarter T`` from the lower triangles, mirrored into
    ``V``; returns ``|G - X|^2``.

    Works on pairs of mirrored tiles ``(bi, bj)``, ``bj < bi``: the upper tile of ``P`` is read
    row by row into a small transposed buffer, the mirrored tile of ``G`` is written back row
    by row from a buffer; the inner loops run over contiguous row pieces (they vectorize).
    Diagonal tiles are their own mirrors; on the diagonal ``T`` is projected onto ``V``.
    """
    n = W.shape[0]
    PT = np.empty((_TILE, _TILE), dtype=P.dtype)
    GT = np.empty((_TILE, _TILE), dtype=G.dtype)
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
                t_row = T[i, bj:je]
                x_row = X[i, bj:je]
                g_row = G[i, bj:je]
                pt_row = PT[ii]
                gt_row = GT[ii]
                for jj in range(_TILE):
                    c = p_row[jj] + s * pt_row[jj].conjugate()
                    g = w_row[jj] + half * c + quarter * t_row[jj]
                    g_row[jj] = g
                    gt_row[jj] = s * g.conjugate()
                    d = g - x_row[jj]
                    rr += 2.0 * (d.real * d.real + d.imag * d.imag)
            for jj in range(_TILE):
                dst = G[bj + jj, bi:ie]
                for ii in range(ie - bi):
                    dst[ii] = GT[ii, jj]
        for i in range(bi, ie):  # the diagonal tile
            for j in range(bi, i):
                c = P[i, j] + s * P[j, i].conjugate()
                g = W[i, j] + half * c + quarter * T[i, j]
                G[i, j] = g
                G[j, i] = s * g.conjugate()
                d = g - X[i, j]
                rr += 2.0 * (d.real * d.real + d.imag * d.imag)
            p = P[i, i]
            t = T[i, i]
            g = W[i, i] + half * (p + s * p.conjugate()) + quarter * (0.5 * (t + s * t.conjugate()))
            G[i, i] = g
            d = g - X[i, i]
            rr += d.real * d.real + d.imag * d.imag
    return rr


@numba.njit(cache=True, fastmath=_FM)
def _finish(W, X, P, h, s, Wn, D):  # type: ignore[no-untyped-def]
    """``Wn = W + h (P + sigma(P))`` and ``D = X - W`` on the lower triangles; returns
    finiteness of ``Wn``.

    The strict upper triangles are not written: inside the time loop ``W`` and the offsets are
    only read on their lower triangles (by :func:`_guess`, :func:`_combine` and this
    function); :func:`_mirror_lower` completes what a call returns.
    """
    n = W.shape[0]
    PT = np.empty((_TILE, _TILE), dtype=P.dtype)
    acc = 0.0  # finite iff every entry is (a sum of absolute values: no branch in the loop)
    for bi in range(0, n, _TILE):
        ie = min(bi + _TILE, n)
        for bj in range(0, bi, _TILE):  # full tiles below the diagonal
            _load_t(P, bi, ie, bj, bj + _TILE, PT)
            for ii in range(ie - bi):
                i = bi + ii
                p_row = P[i, bj : bj + _TILE]
                w_row = W[i, bj : bj + _TILE]
                x_row = X[i, bj : bj + _TILE]
                wn_row = Wn[i, bj : bj + _TILE]
                d_row = D[i, bj : bj + _TILE]
                pt_row = PT[ii]
                for jj in range(_TILE):
                    v = w_row[jj] + h * (p_row[jj] + s * pt_row[jj].conjugate())
                    wn_row[jj] = v
                    d_row[jj] = x_row[jj] - w_row[jj]
                    acc += abs(v.real) + abs(v.imag)
        for i in range(bi, ie):  # the diagonal tile
            for j in range(bi, i + 1):
                v = W[i, j] + h * (P[i, j] + s * P[j, i].conjugate())
                Wn[i, j] = v
                D[i, j] = X[i, j] - W[i, j]
                acc += abs(v.real) + abs(v.imag)
    return math.isfinite(acc)


@numba.njit(cache=True, fastmath=_FM)
def _mirror_lower(A, s):  # type: ignore[no-untyped-def]
    """``A[j, i] = s * conj(A[i, j])`` for ``j < i``: the strict upper triangle from the lower
    one, tile by tile (rows of the lower tile read, rows of the upper tile written)."""
    n = A.shape[0]
    buf = np.empty((_TILE, _TILE), dtype=A.dtype)
    for bi in range(0, n, _TILE):
        ie = min(bi + _TILE, n)
        for bj in range(0, bi, _TILE):  # full tiles
            for ii in range(ie - bi):
                src = A[bi + ii, bj : bj + _TILE]
                dst = buf[ii]
                for jj in range(_TILE):
                    dst[jj] = s * src[jj].conjugate()
            for jj in range(_TILE):
                row = A[bj + jj, bi:ie]
                for ii in range(ie - bi):
                    row[ii] = buf[ii, jj]
        for i in range(bi, ie):
            for j in range(bi, i):
                A[j, i] = s * A[i, j].conjugate()


@numba.njit(cache=True, fastmath=_FM)
def _project_into(Y, s, W):  # type: ignore[no-untyped-def]
    """``W = (Y + sigma(Y)) / 2``, the lower triangle computed and mirrored (exactly in ``V``)."""
    n = Y.shape[0]
    YT = np.empty((_TILE, _TILE), dtype=Y.dtype)
    for bi in range(0, n, _TILE):
        ie = min(bi + _TILE, n)
        for bj in range(0, bi + 1, _TILE):
            je = min(bj + _TILE, n)
            _load_t(Y, bi, ie, bj, je, YT)
            for i in range(bi, ie):
                for j in range(bj, min(je, i + 1)):
                    W[i, j] = 0.5 * (Y[i, j] + s * YT[i - bi, j - bj].conjugate())
    _mirror_lower(W, s)


@numba.njit(cache=True, fastmath=_FM)
def _guess(W, H, order, weights, s, X):  # type: ignore[no-untyped-def]
    """``X = W + sum_q weights[q] H[order[q]]`` on the lower triangle, mirrored into ``V``;
    returns ``|W|^2``. Row pieces with the first four offsets written out (they vectorize)."""
    n = W.shape[0]
    m = order.shape[0]
    acc = 0.0
    a0 = weights[0] if m > 0 else 0.0
    a1 = weights[1] if m > 1 else 0.0
    a2 = weights[2] if m > 2 else 0.0
    a3 = weights[3] if m > 3 else 0.0
    for i in range(n):
        w = W[i, : i + 1]
        x = X[i, : i + 1]
        row = 0.0
        for j in range(i + 1):
            row += w[j].real * w[j].real + w[j].imag * w[j].imag
        d = W[i, i]
        acc += 2.0 * row - (d.real * d.real + d.imag * d.imag)
        if m == 0:
            for j in range(i + 1):
                x[j] = w[j]
            continue
        h0 = H[order[0], i, : i + 1]
        if m == 1:
            for j in range(i + 1):
                x[j] = w[j] + a0 * h0[j]
        elif m == 2:
            h1 = H[order[1], i, : i + 1]
            for j in range(i + 1):
                x[j] = w[j] + (a0 * h0[j] + a1 * h1[j])
        elif m == 3:
            h1 = H[order[1], i, : i + 1]
            h2 = H[order[2], i, : i + 1]
            for j in range(i + 1):
                x[j] = w[j] + (a0 * h0[j] + a1 * h1[j] + a2 * h2[j])
        else:
            h1 = H[order[1], i, : i + 1]
            h2 = H[order[2], i, : i + 1]
            h3 = H[order[3], i, : i + 1]
            for j in range(i + 1):
                x[j] = a0 * h0[j] + a1 * h1[j] + a2 * h2[j] + a3 * h3[j]
            for q in range(4, m):
                hq = H[order[q], i, : i + 1]
                aq = weights[q]
                for j in range(i + 1):
                    x[j] += aq * hq[j]
            for j in range(i + 1):
                x[j] += w[j]
        v = X[i, i]
        X[i, i] = 0.5 * (v + s * v.conjugate())
    _mirror_lower(X, s)
    return acc


def _remove_trace(A: Array) -> None:
    """``A -= (Tr A / n) I`` in place (the projection of ``su(n)`` on top of ``u(n)``)."""
    A.flat[:: A.shape[0] + 1] -= np.trace(A) / A.shape[0]


def isomp_advance_large(
    method: Any, problem: IsospectralProblem, coeff: Array | None, y: Array, h: float, n: int,
    state: Any,
) -> AdvanceResult:  # fmt: skip
    """``n`` IsoMP steps of one large matrix with preallocated buffers (see module docstring).

    ``B(X) = coeff * X`` (an :class:`~isoflow._fast.kernels.ElementwiseLinear` kernel's
    coefficients), or ``problem.B`` when ``coeff`` is ``None``.
    """
    from ..methods.isomp import extrapolation_weights
    from .dispatch import sigma_sign

    alg = problem.algebra
    s = sigma_sign(alg)
    assert s is not None
    solver = method.solver
    dt = alg.dtype
    W = np.empty(y.shape, dtype=dt)
    _project_into(np.ascontiguousarray(y, dtype=dt), s, W)
    traceless = bool(getattr(alg, "traceless", False))
    if traceless:
        _remove_trace(W)
    Wn, X, G, P, T, Bm = (np.empty_like(W) for _ in range(6))
    C = coeff
    blocks = lower_blocks(W.shape[0])
    extrap = method.initial_guess == "extrapolate"
    K = method.extrapolation_order + 1
    offsets = method.history(h, state)
    # ring of offsets, newest first in `order`; never more slots than can be used
    H = np.empty((min(K + 1, len(offsets) + n), *W.shape), dtype=dt)
    order = list(range(len(offsets)))
    for q, D in enumerate(offsets):
        H[q] = D
    tot = largest = 0
    res_max = 0.0
    half, quarter = 0.5 * h, 0.25 * h * h
    for step in range(n):
        weights = np.asarray(extrapolation_weights(len(order)) if order else (), dtype=np.float64)
        scale = math.sqrt(_guess(W, H, np.asarray(order, dtype=np.int64), weights, s, X))
        tol = solver.atol + solver.rtol * scale
        floor = solver.stall_rtol * scale
        prev = first = math.inf
        status = STATUS_MAX_ITER
        r = math.inf
        it = 0
        for it in range(1, solver.max_iter + 1):
            if C is not None:
                B = np.multiply(C, X, out=Bm)
            else:
                B = np.asarray(problem.evaluate_B(X), dtype=dt)
            np.matmul(B, X, out=P)
            lower_product(P, B, T, blocks)
            r = math.sqrt(_combine(W, X, P, T, G, s, half, quarter))
            code, prev, first = stopping_step(
                r, prev, first, it, tol, floor, solver.divergence_factor
            )
            if code != STATUS_RUNNING:
                status = code
                break
            X, G = G, X
        free = next(q for q in range(H.shape[0]) if q not in order[:K])
        finite = _finish(W, X, P, float(h), s, Wn, H[free])
        if traceless:
            _remove_trace(Wn)
        tot += it
        largest = max(largest, it)
        if status != STATUS_CONVERGED or not finite:
            for A in (W, Wn, *(H[q] for q in order)):
                _mirror_lower(A, s)
            fail = StepResult(
                y=Wn.copy(),
                stage=X.copy(),
                iterations=np.asarray(it, dtype=np.int64),
                residual=np.asarray(r),
                status=np.asarray(status, dtype=np.int64),
                state=None,
            )
            st = state if step == 0 else (h, *(H[q] for q in order))
            return AdvanceResult(W, st, step, tot, largest, res_max, failure=fail)
        res_max = max(res_max, r)
        if extrap:
            order = [free, *order[: K - 1]]
        W, Wn = Wn, W
    for A in (W, *(H[q] for q in order)):
        _mirror_lower(A, s)
    # views of this call's ring (never written again): no copies
    new_state = (h, *(H[q] for q in order)) if extrap else None
    return AdvanceResult(W, new_state, n, tot, largest, res_max)
