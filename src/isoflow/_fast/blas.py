r"""IsoMP on one large dense matrix: two BLAS products per iteration, no hidden copies.

For ``so(n)``, ``u(n)``, ``Sym(n)``, ``Herm(n)`` (:math:`\sigma(Y) = s\,\bar Y^T`) one
fixed-point iteration is

.. math::

    B = B(X), \quad P = B X, \quad T = P B \quad (\text{two products, into fixed buffers}),
    \qquad G = W + \tfrac h2 (P + \sigma(P)) + \tfrac{h^2}{4} T,

where the commutator :math:`[B, X] = P + \sigma(P)` of the two structured matrices comes from
the single product ``P`` (:math:`XB = -\sigma(BX)`), and everything after the products is one
cache-blocked compiled pass (bracket, iterate, residual) that reads one transpose, tile by
tile. ``[B, X]`` and ``W`` lie in ``V`` bit for bit, so ``W_{k+1} = W + h [B, X]`` is exactly in
``V``; ``T`` is in ``V`` up to rounding and is not re-projected (the NumPy path projects it;
the difference is rounding, and it cannot accumulate because ``W`` is exact). ``B`` is the
problem's kernel (``C * X`` into a buffer) or, for any other ``B``, ``problem.B`` itself (a
Python call that allocates its result, which is all it costs).
The stopping rules and the stage extrapolation are those of the NumPy path.
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
    stopping_status,
)
from ..problems import IsospectralProblem
from .kernels import ElementwiseLinear

__all__ = ["combine", "isomp_advance_large"]

Array = NDArray[Any]

_TILE = 32
#: Reassociation only (vectorized residual sums); results differ from NumPy by rounding.
_FM = {"reassoc", "nsz"}


@numba.njit(cache=True, fastmath=_FM, inline="always")
def _load_t(A, bi, ie, bj, je, buf):  # type: ignore[no-untyped-def]
    """``buf[ii, jj] = A[bj + jj, bi + ii]``: the transposed tile, read row by row from ``A``."""
    for j in range(bj, je):
        for i in range(bi, ie):
            buf[i - bi, j - bj] = A[j, i]


@numba.njit(cache=True, fastmath=_FM)
def _combine(W, X, P, T, Cm, G, s, half, quarter):  # type: ignore[no-untyped-def]
    """``Cm = P + sigma(P)``, ``G = W + half Cm + quarter T``; returns ``|G - X|^2``.

    Tile by tile; the transposed tile of ``P`` is first copied row by row into a small buffer
    (a strided column walk through power-of-two rows thrashes the cache). ``Cm`` is in ``V``
    bit for bit (``sigma`` is a signed permutation), ``W`` too, so the projection of the NumPy
    path only acts on ``T = B X B``, which is in ``V`` up to rounding: it is skipped (one
    transposed read instead of three). ``W_{k+1} = W + h Cm`` is then exactly in ``V``.
    """
    n = W.shape[0]
    PT = np.empty((_TILE, _TILE), dtype=P.dtype)
    rr = 0.0
    for bi in range(0, n, _TILE):
        ie = min(bi + _TILE, n)
        for bj in range(0, n, _TILE):
            je = min(bj + _TILE, n)
            _load_t(P, bi, ie, bj, je, PT)
            for i in range(bi, ie):
                ii = i - bi
                for j in range(bj, je):
                    c = P[i, j] + s * PT[ii, j - bj].conjugate()
                    Cm[i, j] = c
                    g = W[i, j] + half * c + quarter * T[i, j]
                    G[i, j] = g
                    d = g - X[i, j]
                    rr += d.real * d.real + d.imag * d.imag
    return rr


@numba.njit(cache=True, fastmath=_FM)
def _finish(W, X, Cm, h, Wn, D):  # type: ignore[no-untyped-def]
    """``Wn = W + h Cm`` (in ``V`` exactly) and ``D = X - W``; returns finiteness."""
    n = W.shape[0]
    bad = 0
    for i in range(n):
        for j in range(n):
            v = W[i, j] + h * Cm[i, j]
            Wn[i, j] = v
            D[i, j] = X[i, j] - W[i, j]
            if not (math.isfinite(v.real) and math.isfinite(v.imag)):
                bad += 1
    return bad == 0


@numba.njit(cache=True, fastmath=_FM)
def _guess(W, H, order, weights, X):  # type: ignore[no-untyped-def]
    """``X = W + sum_q weights[q] H[order[q]]``; returns ``|W|^2``."""
    n = W.shape[0]
    m = order.shape[0]
    acc = 0.0
    for i in range(n):
        for j in range(n):
            w = W[i, j]
            acc += w.real * w.real + w.imag * w.imag
            if m == 0:
                X[i, j] = w
            else:
                e = weights[0] * H[order[0], i, j]
                for q in range(1, m):
                    e = e + weights[q] * H[order[q], i, j]
                X[i, j] = w + e
    return acc


def combine(
    W: Array, X: Array, P: Array, T: Array, Cm: Array, G: Array, s: float, h: float
) -> float:
    """One fused pass after the two products (see the module docstring); returns ``|G - X|``."""
    return math.sqrt(_combine(W, X, P, T, Cm, G, float(s), 0.5 * h, 0.25 * h * h))


def isomp_advance_large(
    method: Any, problem: IsospectralProblem, y: Array, h: float, n: int, state: Any
) -> AdvanceResult:
    """``n`` IsoMP steps of one large matrix with preallocated buffers (see module docstring)."""
    from .dispatch import sigma_sign

    alg = problem.algebra
    s = sigma_sign(alg)
    assert s is not None
    solver = method.solver
    kernel = problem.kernel
    coeff = kernel.coeff if isinstance(kernel, ElementwiseLinear) else None
    dt = alg.dtype
    W = np.array(y, dtype=dt, order="C", copy=True)
    Wn, X, G, P, T, Cm = (np.empty_like(W) for _ in range(6))
    Bbuf = np.empty_like(W) if coeff is not None else None
    extrap = method.initial_guess == "extrapolate"
    K = method.extrapolation_order + 1
    H = np.empty((K + 1, *W.shape), dtype=dt)  # ring of offsets, newest first in `order`
    offsets = method.history(h, state)
    order = list(range(len(offsets)))
    for q, D in enumerate(offsets):
        H[q] = D
    tot = largest = 0
    res_max = 0.0
    half, quarter = 0.5 * h, 0.25 * h * h
    for step in range(n):
        weights = np.asarray(method_weights(len(order)) if order else (), dtype=np.float64)
        scale = math.sqrt(_guess(W, H, np.asarray(order, dtype=np.int64), weights, X))
        tol = solver.atol + solver.rtol * scale
        floor = solver.stall_rtol * scale
        prev = first = math.inf
        status = STATUS_MAX_ITER
        r = math.inf
        it = 0
        for it in range(1, solver.max_iter + 1):
            if coeff is not None:
                assert Bbuf is not None
                B = np.multiply(coeff, X, out=Bbuf)
            else:
                B = np.asarray(problem.evaluate_B(X), dtype=dt)
            np.matmul(B, X, out=P)
            np.matmul(P, B, out=T)
            r = math.sqrt(_combine(W, X, P, T, Cm, G, s, half, quarter))
            code = stopping_status(r, prev, first, it, tol, floor, solver.divergence_factor)
            if code != STATUS_RUNNING:
                status = code
                break
            if it == 1:
                first = r
            prev = r
            X, G = G, X
        free = next(q for q in range(K + 1) if q not in order[:K])
        finite = _finish(W, X, Cm, float(h), Wn, H[free])
        tot += it
        largest = max(largest, it)
        if status != STATUS_CONVERGED or not finite:
            fail = StepResult(
                y=Wn.copy(),
                stage=X.copy(),
                iterations=np.asarray(it, dtype=np.int64),
                residual=np.asarray(r),
                status=np.asarray(status, dtype=np.int64),
                state=None,
            )
            st = state if step == 0 else (h, *(H[q].copy() for q in order))
            return AdvanceResult(W, st, step, tot, largest, res_max, failure=fail)
        res_max = max(res_max, r)
        if extrap:
            order = [free, *order[: K - 1]]
        W, Wn = Wn, W
    new_state = (h, *(H[q].copy() for q in order)) if extrap else None
    return AdvanceResult(W, new_state, n, tot, largest, res_max)


def method_weights(m: int) -> tuple[float, ...]:
    """Extrapolation weights (see :func:`isoflow.methods.isomp.extrapolation_weights`)."""
    from ..methods.isomp import extrapolation_weights

    return extrapolation_weights(m)
