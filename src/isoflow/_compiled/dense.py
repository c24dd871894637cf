r"""The dense layouts: so(n), u(n), su(n), Sym(n), Herm(n) as ``n x n`` matrices.

These spaces are ``V = {Y : sigma(Y) = Y}`` with :math:`\sigma(Y) = s\,\bar Y^T` (``s = -1`` for
the skew spaces, ``+1`` for the symmetric ones; ``su(n)`` adds ``Tr = 0``), and ``B`` takes
values in the skew normalizer, so with ``P = B X``

.. math::

    [B, X] = P + \sigma(P), \qquad B X B = P B ,

two matrix products per evaluation. The stage space is ``u(n)`` for ``su(n)`` (a stage has a
trace); ``Pi`` below is the projection :math:`(Y + \sigma(Y))/2` onto it and ``Pi_V`` the one onto
``V`` (for ``su(n)`` it also removes the trace).

Two layout records, one per way of forming the products:

* :class:`DenseSmall` (``n <= SMALL_N``): written-out loops, no library calls;
* :class:`DenseBlas` (larger ``n``): BLAS products (numba's ``np.dot``); IsoMP on it runs a fused
  specialization with a triangular product and tile passes (:mod:`isoflow._compiled.dense_tiles`).

The blocks (:mod:`isoflow._compiled.blocks`) are written on pairs of mirrored entries, so every
iterate and state lies in ``V`` to the last bit (an entry and its mirror go through the same
operations).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from ..algebras import Hermitian, SpecialOrthogonal, Symmetric, Unitary
from ..kernels import ElementwiseLinear
from . import blocks
from .flat import two_sum
from .layout import Layout, member_layout

__all__ = [
    "PLANAR_MIN_N",
    "SMALL_N",
    "THREADED_MIN_N",
    "DenseBlas",
    "DenseSmall",
    "dense_layout",
    "lower_blocks",
    "mirror_sum",
    "packed_row_offsets",
    "product",
    "remove_trace",
    "remove_trace_compensated",
    "sigma_sign",
]

#: Largest ``n`` for which the written-out products beat BLAS calls (measured, benchmark 10).
SMALL_N = 16
#: Tile edge of the mirrored passes of the BLAS layout's IsoMP (:mod:`.dense_tiles`).
_TILE = 32
#: Target row-block height of its triangular product (a multiple of ``_TILE``).
_BLOCK = 128
#: Smallest ``n`` at which complex states run IsoMP in real planes with three real products per
#: complex one (:mod:`.dense_planar`; measured, benchmark 12).
PLANAR_MIN_N = 128
#: Row-block height of the planar stage's triangular products: real products of half the
#: work of complex ones stay efficient at smaller blocks (8 blocks from n = 512, benchmark 12).
_PLANAR_BLOCK = 64
#: Smallest ``n`` at which a single complex system's planar stage runs its products and passes
#: over numba threads (:mod:`.dense_planar`; measured, benchmark 21).
THREADED_MIN_N = 256


class DenseSmall(NamedTuple):
    """A dense ``n x n`` state, products written out. ``s``: the sign of sigma; ``traceless``:
    ``su(n)``."""

    n: int
    s: float
    traceless: bool


class DenseBlas(NamedTuple):
    """A dense ``n x n`` state, products through BLAS. ``rowoff`` and ``blocks`` describe the
    packed triangular product of the fused IsoMP stage (:mod:`.dense_tiles`); ``planar``: a
    complex state from :data:`PLANAR_MIN_N` on, whose IsoMP runs in real planes
    (:mod:`.dense_planar`); ``threaded``: a planar single system from
    :data:`THREADED_MIN_N` on, whose products and passes run over numba threads (in pieces
    that do not depend on the thread count)."""

    n: int
    s: float
    traceless: bool
    rowoff: NDArray[np.int64]
    blocks: NDArray[np.int64]
    planar: bool
    threaded: bool = False


def sigma_sign(alg: Any) -> float | None:
    r"""``s`` with :math:`\sigma(Y) = s\,\bar Y^T` for the dense spaces with a compiled path
    (``su(n)`` is ``u(n)`` plus the trace removal of its projection), else ``None``."""
    if isinstance(alg, (SpecialOrthogonal, Unitary)):
        return -1.0
    if isinstance(alg, (Symmetric, Hermitian)):
        return 1.0
    return None


def lower_blocks(n: int, block: int = _BLOCK) -> list[tuple[int, int]]:
    """Row ranges ``(r0, r1)`` of the lower-block-triangular product, tile aligned.

    At least two blocks once ``n >= 2 * _TILE`` (one block is a full product), at most eight.
    """
    nb = min(8, max(2 if n >= 2 * _TILE else 1, round(n / block)))
    size = -(-n // nb)
    size = -(-size // _TILE) * _TILE
    return [(r0, min(n, r0 + size)) for r0 in range(0, n, size)]


def packed_row_offsets(n: int, block: int = _BLOCK) -> tuple[np.ndarray, np.ndarray]:
    """``(blocks, rowoff)``: the blocks (:func:`lower_blocks`) as an ``(nb, 2)`` array and, for
    each row ``i`` of block ``(r0, r1)``, the offset of its ``r1`` entries in the packed ``T``.

    The packed size ``sum (r1 - r0) r1`` never exceeds ``n^2``.
    """
    blocks = lower_blocks(n, block)
    rowoff = np.empty(n, dtype=np.int64)
    off = 0
    for r0, r1 in blocks:
        for i in range(r0, r1):
            rowoff[i] = off + (i - r0) * r1
        off += (r1 - r0) * r1
    return np.asarray(blocks, dtype=np.int64), rowoff


# ---- blocks -----------------------------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def _evaluate_B(lay, f, fargs, X, B):  # type: ignore[no-untyped-def]
    n = lay.n
    f(X.reshape((n, n)), B.reshape((n, n)), *fargs)


@numba.njit(cache=True, inline="always")
def mirror_sum(lay, C):  # type: ignore[no-untyped-def]
    """``C = P + sigma(P)`` in place (``C`` holds ``P``), pair by pair (``lay``: any record
    with ``n`` and the sign ``s`` of sigma; also the pair layouts' brackets)."""
    n = lay.n
    s = lay.s
    Cm = C.reshape((n, n))
    for i in range(n):
        p = Cm[i, i]
        Cm[i, i] = p + s * p.conjugate()
        for j in range(i + 1, n):
            pij = Cm[i, j]
            pji = Cm[j, i]
            Cm[i, j] = pij + s * pji.conjugate()
            Cm[j, i] = pji + s * pij.conjugate()


@numba.njit(cache=True, inline="always")
def product(n, A, B, out):  # type: ignore[no-untyped-def]
    """``out = A B`` (written out, ``n x n`` views; also the pair layouts' small products)."""
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.0
        for k in range(n):
            a = A[i, k]
            for j in range(n):
                out[i, j] += a * B[k, j]


@numba.njit(cache=True, inline="always")
def _bracket_triple_small(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    n = lay.n
    Bm = B.reshape((n, n))
    Cm = C.reshape((n, n))
    product(n, Bm, X.reshape((n, n)), Cm)
    product(n, Cm, Bm, T.reshape((n, n)))
    mirror_sum(lay, C)


@numba.njit(cache=True, inline="always")
def _bracket_small(lay, B, X, C):  # type: ignore[no-untyped-def]
    n = lay.n
    product(n, B.reshape((n, n)), X.reshape((n, n)), C.reshape((n, n)))
    mirror_sum(lay, C)


@numba.njit(cache=True, inline="always")
def _bracket_triple_blas(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    n = lay.n
    Bm = B.reshape((n, n))
    Cm = C.reshape((n, n))
    np.dot(Bm, X.reshape((n, n)), Cm)
    np.dot(Cm, Bm, T.reshape((n, n)))
    mirror_sum(lay, C)


@numba.njit(cache=True, inline="always")
def _bracket_blas(lay, B, X, C):  # type: ignore[no-untyped-def]
    n = lay.n
    np.dot(B.reshape((n, n)), X.reshape((n, n)), C.reshape((n, n)))
    mirror_sum(lay, C)


@numba.njit(cache=True, inline="always")
def _stage_update(lay, W, a, C, b, T, G, X, rr):  # type: ignore[no-untyped-def]
    """``G = Pi(W + a C + b T)`` pair by pair; ``rr[0] = |G - X|^2``."""
    n = lay.n
    s = lay.s
    Wm = W.reshape((n, n))
    Cm = C.reshape((n, n))
    Tm = T.reshape((n, n))
    Gm = G.reshape((n, n))
    Xm = X.reshape((n, n))
    acc = 0.0
    for i in range(n):
        for j in range(i, n):
            gij = Wm[i, j] + a * Cm[i, j] + b * Tm[i, j]
            gji = Wm[j, i] + a * Cm[j, i] + b * Tm[j, i]
            u = 0.5 * (gij + s * gji.conjugate())
            v = 0.5 * (gji + s * gij.conjugate())
            Gm[i, j] = u
            Gm[j, i] = v
            d = u - Xm[i, j]
            acc += d.real * d.real + d.imag * d.imag
            if j != i:
                d = v - Xm[j, i]
                acc += d.real * d.real + d.imag * d.imag
    rr[0] = acc


@numba.njit(cache=True, inline="always")
def _stage_update1(lay, W, a, C, G, X, rr):  # type: ignore[no-untyped-def]
    """``G = Pi(W + a C)`` pair by pair; ``rr[0] = |G - X|^2``."""
    n = lay.n
    s = lay.s
    Wm = W.reshape((n, n))
    Cm = C.reshape((n, n))
    Gm = G.reshape((n, n))
    Xm = X.reshape((n, n))
    acc = 0.0
    for i in range(n):
        for j in range(i, n):
            gij = Wm[i, j] + a * Cm[i, j]
            gji = Wm[j, i] + a * Cm[j, i]
            u = 0.5 * (gij + s * gji.conjugate())
            v = 0.5 * (gji + s * gij.conjugate())
            Gm[i, j] = u
            Gm[j, i] = v
            d = u - Xm[i, j]
            acc += d.real * d.real + d.imag * d.imag
            if j != i:
                d = v - Xm[j, i]
                acc += d.real * d.real + d.imag * d.imag
    rr[0] = acc


@numba.njit(cache=True, inline="always")
def remove_trace(A, n):  # type: ignore[no-untyped-def]
    """``A -= (Tr A / n) I`` for the flat ``n x n`` matrix ``A``."""
    tr = A[0]
    for i in range(1, n):
        tr += A[i * (n + 1)]
    tr = tr / n
    for i in range(n):
        A[i * (n + 1)] -= tr


@numba.njit(cache=True, inline="always")
def remove_trace_compensated(A, E, n):  # type: ignore[no-untyped-def]
    """:func:`remove_trace` with the rounding of each diagonal entry added to ``E`` (exact:
    the traceless part of ``A + E`` does not change)."""
    tr = A[0]
    for i in range(1, n):
        tr += A[i * (n + 1)]
    tr = tr / n
    for i in range(n):
        k = i * (n + 1)
        v, e = two_sum(A[k], -tr)
        A[k] = v
        E[k] += e


@numba.njit(cache=True, inline="always")
def _advance_state(lay, W, h, C, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = Pi_V(W + h C)``: ``W`` and ``C`` are exact mirrors, hence so is ``W + h C`` (and
    the compensation ``E``, entry by entry the same operations); only the trace of ``su(n)``
    is left to remove."""
    acc = 0.0
    if E.shape[0] == 0:
        for i in range(W.shape[0]):
            v = W[i] + h * C[i]
            Wn[i] = v
            acc += abs(v.real) + abs(v.imag)
        if lay.traceless:
            remove_trace(Wn, lay.n)
    else:
        for i in range(W.shape[0]):
            v, E[i] = two_sum(W[i], h * C[i] + E[i])
            Wn[i] = v
            acc += abs(v.real) + abs(v.imag)
        if lay.traceless:
            remove_trace_compensated(Wn, E, lay.n)
    fin[0] = math.isfinite(acc)


for _cls in (DenseSmall, DenseBlas):
    blocks.provide(blocks.evaluate_B, _cls)(_evaluate_B)
    blocks.provide(blocks.stage_update, _cls)(_stage_update)
    blocks.provide(blocks.stage_update1, _cls)(_stage_update1)
    blocks.provide(blocks.advance_state, _cls)(_advance_state)
blocks.provide(blocks.bracket_triple, DenseSmall)(_bracket_triple_small)
blocks.provide(blocks.bracket, DenseSmall)(_bracket_small)
blocks.provide(blocks.bracket_triple, DenseBlas)(_bracket_triple_blas)
blocks.provide(blocks.bracket, DenseBlas)(_bracket_blas)
blocks.provide_generic_stage_map(DenseSmall, DenseBlas)
blocks.provide_member_defaults(DenseSmall, DenseBlas)


# ---- the layout of a run ----------------------------------------------------------------------


def _load_scipy_blas() -> None:
    """Load the BLAS the BLAS layout calls (numba's ``np.dot`` binds SciPy's cython BLAS, a
    library of its own besides NumPy's) before the run starts, so that the run's thread limits
    reach it from the first step (:mod:`isoflow.threads`)."""
    import scipy.linalg.cython_blas  # noqa: F401


def record(alg: Any, members: int = 1) -> DenseSmall | DenseBlas:
    """The layout record of the dense space ``alg`` for a run of ``members`` members
    (written-out products up to :data:`SMALL_N`; a single large complex system threaded)."""
    s = sigma_sign(alg)
    assert s is not None
    n = alg.shape[0]
    traceless = bool(getattr(alg, "traceless", False))
    if n <= SMALL_N:
        return DenseSmall(n, s, traceless)
    _load_scipy_blas()
    planar = bool(alg.is_complex) and n >= PLANAR_MIN_N
    blocks_, rowoff = packed_row_offsets(n, _PLANAR_BLOCK if planar else _BLOCK)
    threaded = planar and members == 1 and n >= THREADED_MIN_N
    return DenseBlas(n, s, traceless, rowoff, blocks_, planar, threaded)


def dense_layout(problem: Any, members: int) -> Layout | None:
    """The dense layout of the run, or ``None`` for another space.

    An :class:`~isoflow.ElementwiseLinear` kernel with a frame runs in the frame where ``B`` is
    entrywise (IsoMP commutes with the change of frame); the state and the offsets are then
    mapped back at every save point so that a restart continues the run bit for bit.
    """
    alg = problem.algebra
    if sigma_sign(alg) is None:
        return None
    kernel = problem.kernel
    rec = record(alg, members)
    if isinstance(rec, DenseSmall):
        kind = "written-out products"
    else:
        kind = "BLAS, real planes" if rec.planar else "BLAS"
    name = f"dense {alg.name} ({kind})"
    if isinstance(rec, DenseBlas) and rec.threaded:
        name = f"{name[:-1]}, threaded)"
    if isinstance(kernel, ElementwiseLinear) and kernel.frame is not None:
        layout = _frame_layout(name, rec, alg, kernel)
    else:
        layout = member_layout(name, rec, alg.shape, alg.dtype)
    threaded = isinstance(rec, DenseBlas) and rec.threaded
    return dataclasses.replace(layout, threaded=threaded, serial_by_default=threaded)


def _frame_layout(name: str, rec: Any, alg: Any, kernel: ElementwiseLinear) -> Layout:
    n = alg.shape[0]
    assert kernel.frame is not None
    U = kernel.frame.astype(alg.dtype) if alg.is_complex else kernel.frame
    Uh = np.ascontiguousarray(U.conj().T)
    stage = alg.stage_algebra

    def to_units(Y: NDArray[Any]) -> NDArray[Any]:
        return np.ascontiguousarray(Uh @ Y @ U, dtype=alg.dtype).reshape(Y.shape[0], -1)

    def back(space: Any) -> Callable[[NDArray[Any]], NDArray[Any]]:
        def f(A: NDArray[Any]) -> NDArray[Any]:
            M = A.reshape(*A.shape[:-1], n, n)
            return np.asarray(space.project(U @ M @ Uh))

        return f

    return Layout(
        f"{name} in the kernel's frame", rec, to_units=to_units, from_units=back(alg),
        offsets_from_units=back(stage), rows_from_flat=back(alg), identity=False,
        field=ElementwiseLinear(kernel.coeff).field(), restart_at_saves=True,
    )  # fmt: skip
