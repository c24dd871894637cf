r"""Ensembles of an :class:`~isoflow.ElementwiseLinear` kernel: members as SIMD lanes.

For many small systems with ``B(W) = C \circ W`` one member per unit leaves the vector units
idle (``n`` is small). This layout (benchmark 2) groups the members in units of :data:`LANES`,
laid out as ``(n, n, LANES)``, so that every loop of an iteration runs over contiguous members;
the field is formed in place (``B = C \circ X``, lane by lane). The blocks are those of the
small dense layout (:mod:`isoflow._compiled.dense`) lane by lane: the same products, the same
pairwise projection, per-lane residuals and finiteness. The one driver runs the lanes of a
unit in lockstep, each with its own stopping rule and failure record.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from ..kernels import ElementwiseLinear
from . import blocks
from .dense import SMALL_N, sigma_sign
from .flat import two_sum
from .layout import Layout

__all__ = ["LANES", "MIN_MEMBERS", "ElementwiseLanes", "lanes_layout"]

#: Members per unit: the innermost (contiguous, vectorized) axis.
LANES = 16
#: Smallest ensemble run in this layout.
MIN_MEMBERS = 8


class ElementwiseLanes(NamedTuple):
    """``L`` members of a small dense space interleaved, ``B = coeff * W``."""

    n: int
    s: float
    traceless: bool
    L: int
    coeff: NDArray[np.float64]


@numba.njit(cache=True, inline="always")
def _lanes(lay):  # type: ignore[no-untyped-def]
    return lay.L


@numba.njit(cache=True, inline="always")
def _evaluate_B(lay, f, fargs, X, B):  # type: ignore[no-untyped-def]
    n, L = lay.n, lay.L
    Xm = X.reshape((n, n, L))
    Bm = B.reshape((n, n, L))
    for i in range(n):
        for j in range(n):
            c = lay.coeff[i, j]
            for q in range(L):
                Bm[i, j, q] = c * Xm[i, j, q]


@numba.njit(cache=True, inline="always")
def _product(n, L, A, B, out):  # type: ignore[no-untyped-def]
    """``out = A B`` lane by lane (``(n, n, L)`` views)."""
    for i in range(n):
        for j in range(n):
            for q in range(L):
                out[i, j, q] = 0.0
        for k in range(n):
            for j in range(n):
                for q in range(L):
                    out[i, j, q] += A[i, k, q] * B[k, j, q]


@numba.njit(cache=True, inline="always")
def _mirror_sum(lay, C):  # type: ignore[no-untyped-def]
    """``C = P + sigma(P)`` in place, pair by pair, lane by lane."""
    n, L, s = lay.n, lay.L, lay.s
    Cm = C.reshape((n, n, L))
    for i in range(n):
        for q in range(L):
            p = Cm[i, i, q]
            Cm[i, i, q] = p + s * p.conjugate()
        for j in range(i + 1, n):
            for q in range(L):
                pij = Cm[i, j, q]
                pji = Cm[j, i, q]
                Cm[i, j, q] = pij + s * pji.conjugate()
                Cm[j, i, q] = pji + s * pij.conjugate()


@numba.njit(cache=True, inline="always")
def _bracket_triple(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    n, L = lay.n, lay.L
    Bm = B.reshape((n, n, L))
    Cm = C.reshape((n, n, L))
    _product(n, L, Bm, X.reshape((n, n, L)), Cm)
    _product(n, L, Cm, Bm, T.reshape((n, n, L)))
    _mirror_sum(lay, C)


@numba.njit(cache=True, inline="always")
def _bracket(lay, B, X, C):  # type: ignore[no-untyped-def]
    n, L = lay.n, lay.L
    _product(n, L, B.reshape((n, n, L)), X.reshape((n, n, L)), C.reshape((n, n, L)))
    _mirror_sum(lay, C)


@numba.njit(cache=True, inline="always")
def _update(lay, W, a, C, b, T, G, X, rr):  # type: ignore[no-untyped-def]
    """``G = Pi(W + a C + b T)`` pair by pair per lane; ``rr[q] = |G_q - X_q|^2``."""
    n, L, s = lay.n, lay.L, lay.s
    Wm = W.reshape((n, n, L))
    Cm = C.reshape((n, n, L))
    Tm = T.reshape((n, n, L))
    Gm = G.reshape((n, n, L))
    Xm = X.reshape((n, n, L))
    for q in range(L):
        rr[q] = 0.0
    for i in range(n):
        for j in range(i, n):
            for q in range(L):
                gij = Wm[i, j, q] + a * Cm[i, j, q] + b * Tm[i, j, q]
                gji = Wm[j, i, q] + a * Cm[j, i, q] + b * Tm[j, i, q]
                u = 0.5 * (gij + s * gji.conjugate())
                v = 0.5 * (gji + s * gij.conjugate())
                Gm[i, j, q] = u
                Gm[j, i, q] = v
                d = u - Xm[i, j, q]
                e = v - Xm[j, i, q]
                acc = d.real * d.real + d.imag * d.imag
                if j != i:
                    acc += e.real * e.real + e.imag * e.imag
                rr[q] += acc


@numba.njit(cache=True, inline="always")
def _stage_update(lay, W, a, C, b, T, G, X, rr):  # type: ignore[no-untyped-def]
    _update(lay, W, a, C, b, T, G, X, rr)


@numba.njit(cache=True, inline="always")
def _stage_update1(lay, W, a, C, G, X, rr):  # type: ignore[no-untyped-def]
    _update(lay, W, a, C, 0.0, C, G, X, rr)


@numba.njit(cache=True, inline="always")
def _advance_state(lay, W, h, C, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = W + h C``, compensated by ``E`` unless it is empty; ``fin[q]`` whether lane
    ``q`` stayed finite, from the sum of ``0 * x`` over its parts (``0`` for finite ``x``, NaN
    otherwise), a branch-free reduction that keeps the loops vectorized."""
    n, L = lay.n, lay.L
    m = n * n
    Wf = W.reshape((m, L))
    Cf = C.reshape((m, L))
    Wof = Wn.reshape((m, L))
    compensated = E.shape[0] != 0
    z = np.zeros(L)
    if compensated:
        Ef = E.reshape((m, L))
        for k in range(m):
            for q in range(L):
                v, e = two_sum(Wf[k, q], h * Cf[k, q] + Ef[k, q])
                Ef[k, q] = e
                Wof[k, q] = v
                z[q] += v.real * 0.0 + v.imag * 0.0
    else:
        for k in range(m):
            for q in range(L):
                v = Wf[k, q] + h * Cf[k, q]
                Wof[k, q] = v
                z[q] += v.real * 0.0 + v.imag * 0.0
    for q in range(L):
        fin[q] = z[q] == 0.0
    if lay.traceless:
        Wo = Wn.reshape((n, n, L))
        Em = E.reshape((n, n, L)) if compensated else E.reshape((0, 0, L))
        for q in range(L):
            tr = Wo[0, 0, q]
            for i in range(1, n):
                tr += Wo[i, i, q]
            tr = tr / n
            for i in range(n):
                if compensated:
                    v, e = two_sum(Wo[i, i, q], -tr)
                    Wo[i, i, q] = v
                    Em[i, i, q] += e
                else:
                    Wo[i, i, q] -= tr


@numba.njit(cache=True, inline="always")
def _lane_sumsq(lay, W, out):  # type: ignore[no-untyped-def]
    L = lay.L
    for q in range(L):
        out[q] = 0.0
    for e in range(W.shape[0] // L):
        for q in range(L):
            v = W[e * L + q]
            out[q] += v.real * v.real + v.imag * v.imag


@numba.njit(cache=True, inline="always")
def _select(lay, X, G, going):  # type: ignore[no-untyped-def]
    L = lay.L
    for e in range(X.shape[0] // L):
        for q in range(L):
            if going[q]:
                X[e * L + q] = G[e * L + q]


@numba.njit(cache=True, inline="always")
def _commit(lay, W, Wn, ok):  # type: ignore[no-untyped-def]
    L = lay.L
    for e in range(W.shape[0] // L):
        for q in range(L):
            if ok[q]:
                W[e * L + q] = Wn[e * L + q]


@numba.njit(cache=True, inline="always")
def _store(lay, out, row, m0, count, W):  # type: ignore[no-untyped-def]
    L = lay.L
    for q in range(count):
        dst = out[row, m0 + q]
        for e in range(dst.shape[0]):
            dst[e] = W[e * L + q]


for _block, _impl in (
    (blocks.lanes, _lanes),
    (blocks.evaluate_B, _evaluate_B),
    (blocks.bracket_triple, _bracket_triple),
    (blocks.bracket, _bracket),
    (blocks.stage_update, _stage_update),
    (blocks.stage_update1, _stage_update1),
    (blocks.advance_state, _advance_state),
    (blocks.lane_sumsq, _lane_sumsq),
    (blocks.select_lanes, _select),
    (blocks.commit_lanes, _commit),
    (blocks.store, _store),
):
    blocks.provide(_block, ElementwiseLanes)(_impl)
blocks.provide_generic_stage_map(ElementwiseLanes)


def to_lanes(A: NDArray[Any], units: int) -> NDArray[Any]:
    """``(M, n, n)`` -> ``(units, n * n * LANES)`` (zero padding), members innermost."""
    M, n = A.shape[0], A.shape[1]
    out = np.zeros((units * LANES, n, n), dtype=A.dtype)
    out[:M] = A
    return np.ascontiguousarray(out.reshape(units, LANES, n, n).transpose(0, 2, 3, 1)).reshape(
        units, -1
    )


def from_lanes(A: NDArray[Any], n: int, members: int) -> NDArray[Any]:
    """``(units, n * n * LANES)`` -> ``(members, n, n)``."""
    units = A.shape[0]
    B = A.reshape(units, n, n, LANES).transpose(0, 3, 1, 2).reshape(units * LANES, n, n)
    return np.ascontiguousarray(B[:members])


def lanes_layout(problem: Any, members: int) -> Layout | None:
    """Members of an :class:`~isoflow.ElementwiseLinear` kernel (no frame) on a small dense
    space as lanes, from :data:`MIN_MEMBERS` members; else ``None``."""
    alg = problem.algebra
    kernel = problem.kernel
    s = sigma_sign(alg)
    if (
        s is None
        or not isinstance(kernel, ElementwiseLinear)
        or kernel.frame is not None
        or alg.shape[0] > SMALL_N
        or members < MIN_MEMBERS
    ):
        return None
    n = alg.shape[0]
    rec = ElementwiseLanes(
        n, s, bool(getattr(alg, "traceless", False)), LANES,
        np.ascontiguousarray(kernel.coeff, dtype=np.float64),
    )  # fmt: skip
    units = -(-members // LANES)

    def to_units(Y: NDArray[Any]) -> NDArray[Any]:
        return to_lanes(np.asarray(Y, dtype=alg.dtype).reshape(-1, n, n), units)

    def from_units(A: NDArray[Any]) -> NDArray[Any]:
        return from_lanes(A, n, members)

    def rows(A: NDArray[Any]) -> NDArray[Any]:
        return A.reshape(*A.shape[:-1], n, n)

    return Layout(
        f"dense {alg.name} (written-out products, {LANES} members as SIMD lanes)", rec,
        to_units=to_units, from_units=from_units, offsets_from_units=from_units,
        rows_from_flat=rows, lanes=LANES, identity=False,
    )  # fmt: skip
