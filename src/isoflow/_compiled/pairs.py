r"""The pair layouts: states of :math:`\mathfrak g \ltimes \mathfrak g^*` as dual numbers.

A state of :func:`~isoflow.algebras.semidirect` is a pair of ``n x n`` matrices
:math:`X = X_0 + \varepsilon X_1` (``(Theta, W)``, flat: field ``0`` then field ``1``), and
``B = B_0 + \varepsilon B_1`` (``(P, J)``) the same. Products are dual-number products,
:math:`(AB)_0 = A_0 B_0`, :math:`(AB)_1 = A_0 B_1 + A_1 B_0`, so with ``P = B X`` (three
``n x n`` products)

.. math::

    [B, X] = P + \sigma(P) \ \text{(field by field)}, \qquad B X B = P B \ \text{(three more)},

as in the dense layouts (:mod:`isoflow._compiled.dense`, whose :func:`~.dense.product` and
:func:`~.dense.mirror_sum` are used here). The generic IsoMP stage
(:mod:`isoflow._compiled.stages.isomp`) runs unchanged on these blocks: it is the
exponential-free midpoint for :math:`\mathfrak g\ltimes\mathfrak g^*` (the theory page
``docs/theory/semidirect.rst``). The projection and the new state are the dense blocks applied
to each field (the stage space of ``su(n)`` pairs is the pairs of ``u(n)``).

Records:

* :class:`PairsSmall` (``n <= SMALL_N``): written-out products;
* :class:`PairsBlas` (larger ``n``): BLAS products (numba's ``np.dot``), six per iteration
  (benchmark 20 times an iteration against six bare products), with subnormal numbers flushed
  to zero (:func:`_bracket_blas`);
* :class:`TopPair`: the heavy top's :math:`\mathfrak{se}(3)` pairs ``(Gamma, M)`` in vectors
  (:func:`~isoflow.algebras.se3_vectors`), the formulas of
  :class:`~isoflow.algebras.SE3Vectors` through :func:`~.particles.so3_forms`.

The kernel's field ``f(X, B, *args)`` gets one state as a C-contiguous ``(2, n, n)`` (or
``(2, 3)``) array and writes ``B`` into an array of the same shape.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numba
import numpy as np

from ..algebras import SE3Vectors, SemidirectProduct
from . import blocks
from .dense import SMALL_N, DenseSmall, mirror_sum, product, sigma_sign
from .layout import Layout, member_layout
from .particles import flat_advance_state, flat_stage_update, flat_stage_update1, so3_forms
from .subnormals import flush_on, flush_restore

__all__ = ["PairsBlas", "PairsSmall", "TopPair", "pair_layout"]


class PairsSmall(NamedTuple):
    """Pairs of ``n x n`` matrices, products written out; ``s`` and ``traceless`` as in
    :class:`~.dense.DenseSmall` (the record of one field, :func:`_field`)."""

    n: int
    s: float
    traceless: bool


class PairsBlas(NamedTuple):
    """Pairs of ``n x n`` matrices, products through BLAS."""

    n: int
    s: float
    traceless: bool


@numba.njit(cache=True, inline="always")
def _field(lay):  # type: ignore[no-untyped-def]
    """The dense record of one field: its projection and new-state blocks are the dense ones.
    (Formed here: a record nested in the layout record does not pass numba's parallel
    lowering.)"""
    return DenseSmall(lay.n, lay.s, lay.traceless)


class TopPair(NamedTuple):
    """The heavy top's ``(Gamma, M)``: ``2 x 3`` numbers."""

    rows: int


# ---- dense pairs (flat: field 0 at [0, n^2), field 1 at [n^2, 2 n^2)) ---------------------------


@numba.njit(cache=True, inline="always")
def _evaluate_B(lay, f, fargs, X, B):  # type: ignore[no-untyped-def]
    n = lay.n
    f(X.reshape((2, n, n)), B.reshape((2, n, n)), *fargs)


@numba.njit(cache=True, inline="always")
def _fields(n, A):  # type: ignore[no-untyped-def]
    """The two fields of a flat pair as ``n x n`` views."""
    m = n * n
    return A[:m].reshape((n, n)), A[m:].reshape((n, n))


@numba.njit(cache=True, inline="always")
def _add_into(A, B):  # type: ignore[no-untyped-def]
    """``A += B`` entrywise (``n x n`` views)."""
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            A[i, j] += B[i, j]


@numba.njit(cache=True, inline="always")
def _dual_small(n, A0, A1, B0, B1, P0, P1, tmp):  # type: ignore[no-untyped-def]
    """``P = A B`` for dual matrices, written out; ``tmp`` is an ``n x n`` scratch matrix
    distinct from the others."""
    product(n, A1, B0, tmp)
    product(n, A0, B1, P1)
    _add_into(P1, tmp)
    product(n, A0, B0, P0)


@numba.njit(cache=True, inline="always")
def _dual_blas(n, A0, A1, B0, B1, P0, P1, tmp):  # type: ignore[no-untyped-def]
    """``P = A B`` for dual matrices through BLAS."""
    np.dot(A1, B0, tmp)
    np.dot(A0, B1, P1)
    _add_into(P1, tmp)
    np.dot(A0, B0, P0)


@numba.njit(cache=True, inline="always")
def _triple_small(n, P0, P1, B0, B1, T0, T1):  # type: ignore[no-untyped-def]
    """``T = P B`` (written out), ``T0`` as the scratch of ``P1 B0`` before it is written."""
    product(n, P0, B1, T1)
    product(n, P1, B0, T0)
    _add_into(T1, T0)
    product(n, P0, B0, T0)


@numba.njit(cache=True, inline="always")
def _triple_blas(n, P0, P1, B0, B1, T0, T1):  # type: ignore[no-untyped-def]
    """``T = P B`` through BLAS (the same order as :func:`_triple_small`)."""
    np.dot(P0, B1, T1)
    np.dot(P1, B0, T0)
    _add_into(T1, T0)
    np.dot(P0, B0, T0)


@numba.njit(cache=True, inline="always")
def _bracket_triple_small(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    """``C = [B, X]``, ``T = B X B``: ``P = B X`` into ``C`` (``T0`` as scratch), ``T = P B``,
    then ``C = P + sigma(P)`` field by field. Six products."""
    n = lay.n
    m = n * n
    B0, B1 = _fields(n, B)
    C0, C1 = _fields(n, C)
    T0, T1 = _fields(n, T)
    X0, X1 = _fields(n, X)
    _dual_small(n, B0, B1, X0, X1, C0, C1, T0)
    _triple_small(n, C0, C1, B0, B1, T0, T1)
    mirror_sum(lay, C[:m])
    mirror_sum(lay, C[m:])


@numba.njit(cache=True, inline="always")
def _bracket_triple_blas(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    """:func:`_bracket_triple_small` through BLAS, subnormals flushed (:func:`_bracket_blas`)."""
    n = lay.n
    m = n * n
    B0, B1 = _fields(n, B)
    C0, C1 = _fields(n, C)
    T0, T1 = _fields(n, T)
    X0, X1 = _fields(n, X)
    old = flush_on()
    _dual_blas(n, B0, B1, X0, X1, C0, C1, T0)
    _triple_blas(n, C0, C1, B0, B1, T0, T1)
    mirror_sum(lay, C[:m])
    mirror_sum(lay, C[m:])
    flush_restore(old)


@numba.njit(cache=True, inline="always")
def _bracket_small(lay, B, X, C):  # type: ignore[no-untyped-def]
    """``C = [B, X]`` alone (three products and a scratch matrix)."""
    n = lay.n
    m = n * n
    B0, B1 = _fields(n, B)
    C0, C1 = _fields(n, C)
    X0, X1 = _fields(n, X)
    _dual_small(n, B0, B1, X0, X1, C0, C1, np.empty((n, n), dtype=C.dtype))
    mirror_sum(lay, C[:m])
    mirror_sum(lay, C[m:])


@numba.njit(cache=True, inline="always")
def _bracket_blas(lay, B, X, C):  # type: ignore[no-untyped-def]
    """:func:`_bracket_small` through BLAS.

    The products run with subnormal numbers flushed to zero on the calling thread
    (:mod:`isoflow._compiled.subnormals`), as the dense BLAS stages do: MHD on the sphere's
    fields are band-limited, their entries far from the band fall below ``1e-150`` within a
    few steps, and their subnormal products run in microcode. Measured with the whole solve
    flushed (``mhd_sphere(N=512, seed=1)``, ``h |B| = 0.3``, one thread, 4 steps): 634-776 ms
    a step against 1192. Only the products and the mirror sums run with the bits (no user
    code, nothing that raises), and the caller's setting is restored after them."""
    n = lay.n
    m = n * n
    B0, B1 = _fields(n, B)
    C0, C1 = _fields(n, C)
    X0, X1 = _fields(n, X)
    tmp = np.empty((n, n), dtype=C.dtype)
    old = flush_on()
    _dual_blas(n, B0, B1, X0, X1, C0, C1, tmp)
    mirror_sum(lay, C[:m])
    mirror_sum(lay, C[m:])
    flush_restore(old)


@numba.njit(cache=True, inline="always")
def _stage_update(lay, W, a, C, b, T, G, X, rr):  # type: ignore[no-untyped-def]
    """``G = Pi(W + a C + b T)``: the dense block on each field; ``rr[0]`` summed."""
    m = lay.n * lay.n
    blocks.stage_update(_field(lay), W[:m], a, C[:m], b, T[:m], G[:m], X[:m], rr)
    first = rr[0]
    blocks.stage_update(_field(lay), W[m:], a, C[m:], b, T[m:], G[m:], X[m:], rr)
    rr[0] += first


@numba.njit(cache=True, inline="always")
def _stage_update1(lay, W, a, C, G, X, rr):  # type: ignore[no-untyped-def]
    """``G = Pi(W + a C)`` on each field."""
    m = lay.n * lay.n
    blocks.stage_update1(_field(lay), W[:m], a, C[:m], G[:m], X[:m], rr)
    first = rr[0]
    blocks.stage_update1(_field(lay), W[m:], a, C[m:], G[m:], X[m:], rr)
    rr[0] += first


@numba.njit(cache=True, inline="always")
def _advance_state(lay, W, h, C, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = Pi_V(W + h C)`` on each field (each compensated by its half of ``E`` unless
    ``E`` is empty); finite when both are."""
    m = lay.n * lay.n
    E0, E1 = (E, E) if E.shape[0] == 0 else (E[:m], E[m:])
    blocks.advance_state(_field(lay), W[:m], h, C[:m], E0, Wn[:m], fin)
    first = fin[0]
    blocks.advance_state(_field(lay), W[m:], h, C[m:], E1, Wn[m:], fin)
    fin[0] = fin[0] and first


for _cls in (PairsSmall, PairsBlas):
    blocks.provide(blocks.evaluate_B, _cls)(_evaluate_B)
    blocks.provide(blocks.stage_update, _cls)(_stage_update)
    blocks.provide(blocks.stage_update1, _cls)(_stage_update1)
    blocks.provide(blocks.advance_state, _cls)(_advance_state)
blocks.provide(blocks.bracket_triple, PairsSmall)(_bracket_triple_small)
blocks.provide(blocks.bracket, PairsSmall)(_bracket_small)
blocks.provide(blocks.bracket_triple, PairsBlas)(_bracket_triple_blas)
blocks.provide(blocks.bracket, PairsBlas)(_bracket_blas)


# ---- the heavy top: (Gamma, M) flat as six numbers -----------------------------------------------


@numba.njit(cache=True, inline="always")
def _top_B(lay, f, fargs, X, B):  # type: ignore[no-untyped-def]
    f(X.reshape((2, 3)), B.reshape((2, 3)), *fargs)


@numba.njit(cache=True, inline="always")
def _top_forms(B, X, C, T):  # type: ignore[no-untyped-def]
    """``C = [B, X]`` and ``T = B X B`` of :class:`~isoflow.algebras.SE3Vectors`: with
    ``b0, b1 = B``, ``x0, x1 = X``, ``C = (b0 x x0, b0 x x1 + b1 x x0)`` and
    ``T = (-(b0.x0) b0, -(b0.x1) b0 - (b1.x0) b0 - (b0.x0) b1)``."""
    b0, b1, b2, b3, b4, b5 = B[0], B[1], B[2], B[3], B[4], B[5]
    x0, x1, x2, x3, x4, x5 = X[0], X[1], X[2], X[3], X[4], X[5]
    c0, c1, c2, t0, t1, t2 = so3_forms(b0, b1, b2, x0, x1, x2)
    c3, c4, c5, u3, u4, u5 = so3_forms(b0, b1, b2, x3, x4, x5)
    e3, e4, e5, _, _, _ = so3_forms(b3, b4, b5, x0, x1, x2)
    d = -(b3 * x0 + b4 * x1 + b5 * x2)  # -(b1 . x0)
    q = -(b0 * x0 + b1 * x1 + b2 * x2)  # -(b0 . x0)
    C[0], C[1], C[2] = c0, c1, c2
    C[3], C[4], C[5] = c3 + e3, c4 + e4, c5 + e5
    T[0], T[1], T[2] = t0, t1, t2
    T[3] = u3 + d * b0 + q * b3
    T[4] = u4 + d * b1 + q * b4
    T[5] = u5 + d * b2 + q * b5


@numba.njit(cache=True, inline="always")
def _top_bracket_triple(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    _top_forms(B, X, C, T)


@numba.njit(cache=True, inline="always")
def _top_bracket(lay, B, X, C):  # type: ignore[no-untyped-def]
    _top_forms(B, X, C, np.empty(6))


blocks.provide(blocks.evaluate_B, TopPair)(_top_B)
blocks.provide(blocks.bracket_triple, TopPair)(_top_bracket_triple)
blocks.provide(blocks.bracket, TopPair)(_top_bracket)
blocks.provide(blocks.stage_update, TopPair)(flat_stage_update)
blocks.provide(blocks.stage_update1, TopPair)(flat_stage_update1)
blocks.provide(blocks.advance_state, TopPair)(flat_advance_state)
blocks.provide_generic_stage_map(PairsSmall, PairsBlas, TopPair)
blocks.provide_member_defaults(PairsSmall, PairsBlas, TopPair)


# ---- the layout of a run ----------------------------------------------------------------------


def pair_layout(problem: Any, members: int) -> Layout | None:
    """The pair layout of a run on :func:`~isoflow.algebras.semidirect` or
    :func:`~isoflow.algebras.se3_vectors`, or ``None`` for another space."""
    alg = problem.algebra
    if type(alg) is SE3Vectors:
        return member_layout("se(3) pairs (Gamma, M)", TopPair(2), alg.shape, np.float64)
    if not isinstance(alg, SemidirectProduct):
        return None
    base = alg.base
    s = sigma_sign(base)
    assert s is not None
    n = base.n
    traceless = bool(getattr(base, "traceless", False))
    if n <= SMALL_N:
        rec: PairsSmall | PairsBlas = PairsSmall(n, s, traceless)
        kind = "written-out products"
    else:
        rec = PairsBlas(n, s, traceless)
        kind = "BLAS"
    return member_layout(f"dual pairs {alg.name} ({kind})", rec, alg.shape, alg.dtype)
