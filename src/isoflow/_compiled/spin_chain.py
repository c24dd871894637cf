r"""Fused stages for spin chains: :class:`~isoflow.SpinNeighbourSum` in a ``(3, N)`` layout.

``B_i(x) = c\,(x_{i-1} + x_{i+1})`` (periodic; the Heisenberg chain is ``c = -1``), with Gilbert
damping ``B_i = h_i + \lambda\, x_i \times h_i``, ``h_i = c\,(x_{i-1} + x_{i+1})`` (the thermal
and damped chains; the damped sweeps compile apart, :func:`_b`). The generic
particle stage (:mod:`isoflow._compiled.particles`) evaluates ``B`` into a buffer and then the
stage map, which moves about twice the memory of one fused sweep; for long chains the step is
memory bound, so this kernel keeps a specialized evaluation (benchmark 4): the state is held
in the structure-of-arrays layout ``(3, N)`` (unit stride, vectorizable) and each iteration is
one sweep that forms ``B_i`` from the neighbours on the fly:

.. math::

    G_i = w_i + \tfrac h2\, b_i \times x_i - \tfrac{h^2}{4} (b_i\cdot x_i)\, b_i
    \quad\text{(IsoMP)}, \qquad
    G_i = w_i + \tfrac h2\, B_i(m) \times m_i \quad\text{(spherical midpoint)},

72 bytes per spin per IsoMP iteration (read ``x`` and ``w``, write ``G``). The same formulas
and order of operations as :mod:`isoflow._compiled.particles`, so both give the same iterates.
Chains with many spins are cut into chunks over numba threads (the ``*_par`` stages).

The record :class:`SpinChain` (:class:`DampedSpinChain` with damping) holds the number of spins,
the coupling, the number of chunks (and the damping).
The layout also provides the generic blocks (on the ``(3, N)`` layout), so every method with a
compiled stage runs on it; IsoMP, the spherical midpoint and the stochastic midpoint (IsoMP's
sweep with the step's noise added to ``B_i``) run the fused sweeps below, their named
specializations (benchmarks 4, 5 and 18).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba
import numpy as np
from numba.core import types
from numba.extending import overload

from ..algebras import SpinVectors
from ..kernels import SpinNeighbourSum
from . import blocks
from .flat import two_sum
from .layout import Layout
from .particles import (
    flat_advance_state,
    flat_stage_update,
    flat_stage_update1,
    so3_cayley,
    so3_forms,
    so3_stage,
    spherical_factor,
)

__all__ = [
    "CHAIN_RECORDS",
    "PARALLEL_MIN_SPINS",
    "STO_NWORK",
    "DampedSpinChain",
    "SpinChain",
    "chain_layout",
    "finish_iso",
    "finish_iso_cayley",
    "finish_smm",
    "finish_sto",
    "finish_sto_cayley",
    "isomp_cayley_sweeps",
    "isomp_sweeps",
    "iterate_iso_par",
    "iterate_iso_ser",
    "iterate_smm_par",
    "iterate_smm_ser",
    "iterate_sto_par",
    "iterate_sto_ser",
    "spherical_sweeps",
    "stochastic_cayley_sweeps",
    "stochastic_sweeps",
]

#: Smallest spin chain whose sweeps are cut into chunks over numba threads.
PARALLEL_MIN_SPINS = 200_000


class SpinChain(NamedTuple):
    """A periodic chain of ``N`` spins in the ``(3, N)`` layout, ``B_i = c (x_{i-1} +
    x_{i+1})``; ``nch`` chunks of the fused sweeps (``1``: serial)."""

    N: int
    c: float
    nch: int


class DampedSpinChain(NamedTuple):
    """:class:`SpinChain` with Gilbert damping ``lam > 0``: ``B_i = h_i + lam x_i x h_i``,
    ``h_i = c (x_{i-1} + x_{i+1})``. A record class of its own, so numba compiles the damped
    sweeps apart and the undamped ones stay as they were (:func:`_b`)."""

    N: int
    c: float
    nch: int
    lam: float


#: The chain's record classes: its blocks and specializations are registered for both.
CHAIN_RECORDS = (SpinChain, DampedSpinChain)


#: The sweeps that write states: no signed zeros, never reassociation. With ``reassoc`` the
#: new iterates' rounding could depend on what else LLVM saw when it compiled a sweep, so a
#: loop compiled in a run's process and one loaded from numba's cache could disagree in the
#: last bit (as the dense BLAS tiles did: :mod:`.dense_tiles`) and a resume would not continue
#: bit for bit. The inline helpers below take the flags of the function they are inlined into.
_STATE = {"nsz"}
#: The residuals' sums alone reassociate (to vectorize): they decide only when to stop.
_REDUCE = {"reassoc", "nsz"}
#: Spins a sweep handles before it sums their squared changes: they are written to a buffer of
#: this many doubles (16 KiB, in the stage's scratch row; one per chunk of a threaded sweep),
#: still in the L1 cache when it is summed.
_BLOCK = 2048
#: Indices are cast to unsigned: numba wraps negative signed indices around (a select per
#: access), which kept LLVM from vectorizing the sweeps (5x slower per spin).
_U = np.uint64


def _b(X, N, c, i, im, ip):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled only
    """``B_i`` of spin ``i`` from the flat ``(3, N)`` layout (neighbours ``im, ip``): with ``c``
    a number (the coupling), ``c (x_{i-1} + x_{i+1})``; with ``c`` a :class:`DampedSpinChain`,
    the neighbour sum ``h_i`` plus the Gilbert term ``lam x_i x h_i`` (the formulas and their
    order are :func:`isoflow._kernel_fields.neighbour_sum_gilbert`'s). Chosen by the type of
    ``c`` when numba compiles a sweep (:func:`_b_typed`; ``c`` is :func:`_coupling`'s)."""
    raise NotImplementedError("_b runs inside compiled sweeps only")


@overload(_b, inline="always")
def _b_typed(X, N, c, i, im, ip):  # type: ignore[no-untyped-def]
    """:func:`_b`'s two compiled forms, by the type of ``c``."""
    if isinstance(c, types.Number):

        def neighbour_sum(X, N, c, i, im, ip):  # type: ignore[no-untyped-def]
            n, a, b = _U(N), _U(im), _U(ip)
            n2 = n + n
            return (
                c * (X[a] + X[b]), c * (X[n + a] + X[n + b]), c * (X[n2 + a] + X[n2 + b]),
            )  # fmt: skip

        return neighbour_sum

    def damped(X, N, c, i, im, ip):  # type: ignore[no-untyped-def]
        cc, lam = c.c, c.lam
        n, k, a, b = _U(N), _U(i), _U(im), _U(ip)
        n2 = n + n
        h0 = cc * (X[a] + X[b])
        h1 = cc * (X[n + a] + X[n + b])
        h2 = cc * (X[n2 + a] + X[n2 + b])
        x0, x1, x2 = X[k], X[n + k], X[n2 + k]
        return (
            h0 + lam * (x1 * h2 - x2 * h1), h1 + lam * (x2 * h0 - x0 * h2),
            h2 + lam * (x0 * h1 - x1 * h0),
        )  # fmt: skip

    return damped


def _coupling(lay):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled only
    """What :func:`_b` takes as ``c`` on the chain ``lay``: the coupling of a
    :class:`SpinChain` (a number, as the sweeps always took), a :class:`DampedSpinChain`
    itself (its fields are numbers: a tuple would not pass into numba's parallel loops)."""
    raise NotImplementedError("_coupling runs inside compiled sweeps only")


@overload(_coupling, inline="always")
def _coupling_typed(lay):  # type: ignore[no-untyped-def]
    """:func:`_coupling`'s two compiled forms, by the record's class."""
    if getattr(lay, "instance_class", None) is DampedSpinChain:
        return lambda lay: lay
    return lambda lay: lay.c


@numba.njit(cache=True, inline="always")
def _iso_one(X, W, G, N, i, im, ip, c, half):  # type: ignore[no-untyped-def]
    b0, b1, b2 = _b(X, N, c, i, im, ip)
    return _iso_at(X, W, G, N, i, b0, b1, b2, half)


@numba.njit(cache=True, inline="always")
def _iso_at(X, W, G, N, i, b0, b1, b2, half):  # type: ignore[no-untyped-def]
    """IsoMP's stage of spin ``i`` for its ``B_i = (b0, b1, b2)`` in closed form
    (:func:`~isoflow._compiled.particles.so3_stage`); the squared change from ``X_i``."""
    n, k = _U(N), _U(i)  # unsigned: no negative-index wraparound, the loops vectorize
    n2 = n + n
    x0, x1, x2 = X[k], X[n + k], X[n2 + k]  # read before G is written: else no vectorizing
    g0, g1, g2, _, _, _ = so3_stage(b0, b1, b2, W[k], W[n + k], W[n2 + k], half)
    G[k] = g0
    G[n + k] = g1
    G[n2 + k] = g2
    return (g0 - x0) ** 2 + (g1 - x1) ** 2 + (g2 - x2) ** 2


@numba.njit(cache=True, inline="always")
def _smm_one(m, X, W, G, N, i, im, ip, c, half):  # type: ignore[no-untyped-def]
    n, k = _U(N), _U(i)  # unsigned: no negative-index wraparound, the loops vectorize
    n2 = n + n
    x0, x1, x2 = m[k], m[n + k], m[n2 + k]
    b0, b1, b2 = _b(m, N, c, i, im, ip)
    g0 = W[k] + half * (b1 * x2 - b2 * x1)
    g1 = W[n + k] + half * (b2 * x0 - b0 * x2)
    g2 = W[n2 + k] + half * (b0 * x1 - b1 * x0)
    G[k] = g0
    G[n + k] = g1
    G[n2 + k] = g2
    return (g0 - X[k]) ** 2 + (g1 - X[n + k]) ** 2 + (g2 - X[n2 + k]) ** 2


@numba.njit(cache=True, inline="always")
def _point_one(M, W, m, N, i):  # type: ignore[no-untyped-def]
    n, k = _U(N), _U(i)  # unsigned: no negative-index wraparound, the loops vectorize
    n2 = n + n
    w0, w1, w2 = W[k], W[n + k], W[n2 + k]
    a0, a1, a2 = M[k], M[n + k], M[n2 + k]
    f = spherical_factor(w0, w1, w2, a0, a1, a2)
    m[k] = f * a0
    m[n + k] = f * a1
    m[n2 + k] = f * a2


@numba.njit(cache=True, fastmath=_REDUCE)
def _sum(r, n):  # type: ignore[no-untyped-def]
    """``r[0] + ... + r[n - 1]`` (a residual: reassociated, vectorized)."""
    acc = 0.0
    for j in range(n):
        acc += r[j]
    return acc


@numba.njit(cache=True, inline="always")
def _buffer(row, ch, nch):  # type: ignore[no-untyped-def]
    """Chunk ``ch``'s residual buffer of ``nch`` in a scratch row: :data:`_BLOCK` entries, or
    an equal share of the row if it is shorter (a threaded sweep runs on chains of at least
    :data:`PARALLEL_MIN_SPINS` spins, three entries each, so a share is never empty)."""
    size = min(_BLOCK, row.shape[0] // nch)
    return row[ch * size : (ch + 1) * size]


@numba.njit(cache=True, inline="always")
def _blocked(block, lo, hi, r, args):  # type: ignore[no-untyped-def]
    """A sweep over the interior spins ``lo <= i < hi`` (``1 <= lo``, ``hi <= N - 1``) block
    by block: ``block(b, e, r, *args)`` writes the squared changes of spins ``b <= i < e`` to
    the buffer ``r`` (:data:`_BLOCK` or fewer entries), summed before the next block; returns
    the sum over the range. Inlined: a sweep that passed its block function to a compiled
    (not inlined) helper would embed the function's address, and numba would not cache it."""
    size = min(_BLOCK, r.shape[0])
    acc = 0.0
    for b in range(lo, hi, size):
        e = min(b + size, hi)
        block(b, e, r, *args)
        acc += _sum(r, e - b)
    return acc


@numba.njit(cache=True, fastmath=_STATE)
def _iso_block(lo, hi, r, X, W, G, N, c, half):  # type: ignore[no-untyped-def]
    """IsoMP's sweep over the spins ``lo <= i < hi``, squared changes into ``r``."""
    for i in range(lo, hi):
        r[i - lo] = _iso_one(X, W, G, N, i, i - 1, i + 1, c, half)


@numba.njit(cache=True, fastmath=_STATE)
def _point_range(X, W, m, N, lo, hi):  # type: ignore[no-untyped-def]
    for i in range(lo, hi):
        _point_one(X, W, m, N, i)


@numba.njit(cache=True, fastmath=_STATE)
def _smm_block(lo, hi, r, m, X, W, G, N, c, half):  # type: ignore[no-untyped-def]
    """The spherical midpoint's sweep over the spins ``lo <= i < hi``, squared changes into
    ``r``."""
    for i in range(lo, hi):
        r[i - lo] = _smm_one(m, X, W, G, N, i, i - 1, i + 1, c, half)


# Serial and parallel stages are twins on purpose: a short chain runs the serial one (no
# thread start-up per iteration), and numba's cache does not key on ``parallel=``.
# The stages index the flat (3, N) layout directly (component ``a`` of spin ``i`` at
# ``a * N + i``): no reshaped views, which numba's parallel lowering does not write through.
@numba.njit(cache=True)
def iterate_iso_ser(f, fargs, lay, mp, sd, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """One IsoMP sweep over the chain (``f`` is not called: ``B`` is formed on the fly;
    ``work[0]`` takes the spins' squared changes)."""
    N = lay.N
    c = _coupling(lay)
    half = 0.5 * hp
    acc = _iso_one(X, W, G, N, 0, N - 1, 1 % N, c, half)
    if N > 1:
        acc += _blocked(_iso_block, 1, N - 1, work[0], (X, W, G, N, c, half))
        acc += _iso_one(X, W, G, N, N - 1, N - 2, 0, c, half)
    rr[0] = acc


@numba.njit(cache=True, parallel=True)
def iterate_iso_par(f, fargs, lay, mp, sd, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """:func:`iterate_iso_ser` with the chain cut into ``lay.nch`` chunks over numba threads."""
    N = lay.N
    c = _coupling(lay)
    nch = lay.nch
    half = 0.5 * hp
    size = (N + nch - 1) // nch
    part = np.zeros(nch)
    for ch in numba.prange(nch):
        lo = max(ch * size, 1)
        hi = min((ch + 1) * size, N - 1)
        if lo < hi:
            r = _buffer(work[0], ch, nch)
            part[ch] = _blocked(_iso_block, lo, hi, r, (X, W, G, N, c, half))
    acc = part.sum()
    acc += _iso_one(X, W, G, N, 0, N - 1, 1, c, half)
    acc += _iso_one(X, W, G, N, N - 1, N - 2, 0, c, half)
    rr[0] = acc


@numba.njit(cache=True)
def iterate_smm_ser(f, fargs, lay, mp, sd, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """One spherical-midpoint iteration: the points ``m`` (into ``work[0]``), then the sweep
    (the squared changes into ``work[1]``)."""
    N = lay.N
    c = _coupling(lay)
    half = 0.5 * hp
    m = work[0]
    _point_range(X, W, m, N, 0, N)
    acc = _smm_one(m, X, W, G, N, 0, N - 1, 1 % N, c, half)
    if N > 1:
        acc += _blocked(_smm_block, 1, N - 1, work[1], (m, X, W, G, N, c, half))
        acc += _smm_one(m, X, W, G, N, N - 1, N - 2, 0, c, half)
    rr[0] = acc


@numba.njit(cache=True, parallel=True)
def iterate_smm_par(f, fargs, lay, mp, sd, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """:func:`iterate_smm_ser` over ``lay.nch`` chunks on numba threads."""
    N = lay.N
    c = _coupling(lay)
    nch = lay.nch
    half = 0.5 * hp
    m = work[0]
    size = (N + nch - 1) // nch
    part = np.zeros(nch)
    for ch in numba.prange(nch):
        lo = ch * size
        hi = min((ch + 1) * size, N)
        if lo < hi:
            _point_range(X, W, m, N, lo, hi)
    for ch in numba.prange(nch):
        lo = max(ch * size, 1)
        hi = min((ch + 1) * size, N - 1)
        if lo < hi:
            r = _buffer(work[1], ch, nch)
            part[ch] = _blocked(_smm_block, lo, hi, r, (m, X, W, G, N, c, half))
    acc = part.sum()
    acc += _smm_one(m, X, W, G, N, 0, N - 1, 1, c, half)
    acc += _smm_one(m, X, W, G, N, N - 1, N - 2, 0, c, half)
    rr[0] = acc


@numba.njit(cache=True, inline="always")
def _bracket_increment(Y, W, N, i, b0, b1, b2, h):  # type: ignore[no-untyped-def]
    """``h B_i x Y_i`` with ``B_i = (b0, b1, b2)``: the spherical midpoint's increment at its
    points ``Y``."""
    n, k = _U(N), _U(i)
    n2 = n + n
    y0, y1, y2 = Y[k], Y[n + k], Y[n2 + k]
    return h * (b1 * y2 - b2 * y1), h * (b2 * y0 - b0 * y2), h * (b0 * y1 - b1 * y0)


@numba.njit(cache=True, inline="always")
def _stage_increment(Y, W, N, i, b0, b1, b2, h):  # type: ignore[no-untyped-def]
    """``h b_i x g_i`` with ``b_i = (b0, b1, b2)`` the field of the accepted stage and ``g_i``
    the stage of that field (:func:`~isoflow._compiled.particles.so3_stage`, as the last sweep
    formed it): the rotation of ``W_i`` that the generic particle stage's finish applies
    (``Y`` is not read)."""
    n, k = _U(N), _U(i)
    n2 = n + n
    _, _, _, c0, c1, c2 = so3_stage(b0, b1, b2, W[k], W[n + k], W[n2 + k], 0.5 * h)
    return h * c0, h * c1, h * c2


@numba.njit(cache=True, inline="always")
def _add_compensated(W, Wn, E, N, i, d0, d1, d2):  # type: ignore[no-untyped-def]
    """``Wn_i = W_i + d_i`` compensated by ``E`` (TwoSum; no reassociation, which would
    simplify its exact error away)."""
    n, k = _U(N), _U(i)
    n2 = n + n
    Wn[k], E[k] = two_sum(W[k], d0 + E[k])
    Wn[n + k], E[n + k] = two_sum(W[n + k], d1 + E[n + k])
    Wn[n2 + k], E[n2 + k] = two_sum(W[n2 + k], d2 + E[n2 + k])


@numba.njit(cache=True, inline="always")
def _add_plain(W, Wn, N, i, d0, d1, d2):  # type: ignore[no-untyped-def]
    """``Wn_i = W_i + d_i``."""
    n, k = _U(N), _U(i)
    n2 = n + n
    Wn[k] = W[k] + d0
    Wn[n + k] = W[n + k] + d1
    Wn[n2 + k] = W[n2 + k] + d2


@numba.njit(cache=True, inline="always")
def _finish_spin(incr, Y, W, Wn, E, N, i, im, ip, c, h):  # type: ignore[no-untyped-def]
    """Spin ``i`` of a finish: its field ``B_i(Y)``, the increment ``incr`` forms, added with
    the compensation ``E`` (when not empty)."""
    b0, b1, b2 = _b(Y, N, c, i, im, ip)
    d0, d1, d2 = incr(Y, W, N, i, b0, b1, b2, h)
    if E.shape[0] != 0:
        _add_compensated(W, Wn, E, N, i, d0, d1, d2)
    else:
        _add_plain(W, Wn, N, i, d0, d1, d2)


@numba.njit(cache=True, inline="always")
def _final_loops(incr, Y, W, Wn, E, N, c, h):  # type: ignore[no-untyped-def]
    """Every spin's finish with the increment ``incr``, compensated by ``E`` unless it is
    empty: the interior in loops of their own with no reduction, no wrapped neighbours and
    no branch, which vectorize without reassociation. The finiteness check is a pass of its
    own (:func:`_size`): at N = 1e6 this loop takes 6.4 ns a spin and the check 1.1, against
    8.5 for one loop with the sum (compiled with reassociation)."""
    _finish_spin(incr, Y, W, Wn, E, N, 0, N - 1, 1 % N, c, h)
    if E.shape[0] != 0:
        for i in range(1, N - 1):
            b0, b1, b2 = _b(Y, N, c, i, i - 1, i + 1)
            d0, d1, d2 = incr(Y, W, N, i, b0, b1, b2, h)
            _add_compensated(W, Wn, E, N, i, d0, d1, d2)
    else:
        for i in range(1, N - 1):
            b0, b1, b2 = _b(Y, N, c, i, i - 1, i + 1)
            d0, d1, d2 = incr(Y, W, N, i, b0, b1, b2, h)
            _add_plain(W, Wn, N, i, d0, d1, d2)
    if N > 1:
        _finish_spin(incr, Y, W, Wn, E, N, N - 1, N - 2, 0, c, h)


@numba.njit(cache=True, fastmath=_STATE)
def _bracket_final(Y, W, Wn, E, N, c, h):  # type: ignore[no-untyped-def]
    """``Wn = W + h B(Y) x Y`` (flat ``(3, N)``), compensated by ``E`` unless it is empty."""
    _final_loops(_bracket_increment, Y, W, Wn, E, N, c, h)


@numba.njit(cache=True, fastmath=_STATE)
def _stage_final(Y, W, Wn, E, N, c, h):  # type: ignore[no-untyped-def]
    """``Wn = W + h B(Y) x G`` with the closed-form stage ``G`` of the field ``B(Y)``,
    compensated by ``E`` unless it is empty."""
    _final_loops(_stage_increment, Y, W, Wn, E, N, c, h)


@numba.njit(cache=True, fastmath=_REDUCE)
def _size(V):  # type: ignore[no-untyped-def]
    """``sum |V_j|``: finite iff every entry is (a reduction that vectorizes; its order does
    not change whether it is finite)."""
    acc = 0.0
    for j in range(V.shape[0]):
        acc += abs(V[j])
    return acc


@numba.njit(cache=True)
def finish_iso(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = W + h B(X) x G(X)`` from the accepted ``X`` (``B`` and the stage ``G`` of its
    last sweep, formed again)."""
    _stage_final(X, W, Wn, E, lay.N, _coupling(lay), hp)
    fin[0] = math.isfinite(_size(Wn))


@numba.njit(cache=True)
def finish_smm(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = W + h B(m) x m`` with the points ``m`` of the last iteration (``work[0]``)."""
    _bracket_final(work[0], W, Wn, E, lay.N, _coupling(lay), hp)
    fin[0] = math.isfinite(_size(Wn))


def isomp_sweeps(layout: Layout) -> tuple[Any, Any]:
    """IsoMP's fused specialization on the chain: serial or threaded sweeps."""
    par = layout.record.nch > 1
    return (iterate_iso_par if par else iterate_iso_ser), finish_iso


def spherical_sweeps(layout: Layout) -> tuple[Any, Any]:
    """The spherical midpoint's fused specialization on the chain."""
    par = layout.record.nch > 1
    return (iterate_smm_par if par else iterate_smm_ser), finish_smm


# ---- the stochastic midpoint's fused sweeps ------------------------------------------------------
# The noise of a step enters ``B_i`` as ``(1/h) (sum_j sd_j F_j + sigma_i dbeta_i)``. The stage's
# own ``begin`` (:func:`isoflow._compiled.stages.stochastic_isomp.begin`) forms that term once a
# step, in the chain's ``(3, N)`` layout, into the last scratch row, as it does on every layout,
# and every sweep reads it there: 24 more bytes a spin than IsoMP's sweep, in unit stride
# (reading the increments, interleaved by spin, and the amplitudes in each sweep took twice
# IsoMP's time). The sweeps' iterates are those of the generic particle stage to the last bit.


@numba.njit(cache=True, inline="always")
def _noise_of(T, N, i):  # type: ignore[no-untyped-def]
    """Spin ``i``'s noise term, as the stage's ``begin`` left it in ``T``."""
    n, k = _U(N), _U(i)
    return T[k], T[n + k], T[n + n + k]


@numba.njit(cache=True, inline="always")
def _sto_one(X, W, G, N, i, im, ip, c, half, T):  # type: ignore[no-untyped-def]
    b0, b1, b2 = _b(X, N, c, i, im, ip)
    n0, n1, n2 = _noise_of(T, N, i)
    return _iso_at(X, W, G, N, i, b0 + n0, b1 + n1, b2 + n2, half)


@numba.njit(cache=True, fastmath=_STATE)
def _sto_block(lo, hi, r, X, W, G, N, c, half, T):  # type: ignore[no-untyped-def]
    """The stochastic sweep over the interior spins ``lo <= i < hi``, squared changes into
    ``r``."""
    for i in range(lo, hi):
        r[i - lo] = _sto_one(X, W, G, N, i, i - 1, i + 1, c, half, T)


@numba.njit(cache=True)
def iterate_sto_ser(f, fargs, lay, mp, sd, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """One stochastic-midpoint sweep over the chain (IsoMP's with the step's noise term,
    the stage's ``begin`` formed it)."""
    N = lay.N
    c = _coupling(lay)
    half = 0.5 * hp
    T = work[work.shape[0] - 1]
    acc = _sto_one(X, W, G, N, 0, N - 1, 1 % N, c, half, T)
    if N > 1:
        args = (X, W, G, N, c, half, T)
        acc += _blocked(_sto_block, 1, N - 1, work[0], args)
        acc += _sto_one(X, W, G, N, N - 1, N - 2, 0, c, half, T)
    rr[0] = acc


@numba.njit(cache=True, parallel=True)
def iterate_sto_par(f, fargs, lay, mp, sd, W, X, G, aux, work, hp, rr):  # type: ignore[no-untyped-def]
    """:func:`iterate_sto_ser` with the chain cut into ``lay.nch`` chunks over numba threads."""
    N = lay.N
    c = _coupling(lay)
    nch = lay.nch
    half = 0.5 * hp
    T = work[work.shape[0] - 1]
    size = (N + nch - 1) // nch
    part = np.zeros(nch)
    for ch in numba.prange(nch):
        lo = max(ch * size, 1)
        hi = min((ch + 1) * size, N - 1)
        if lo < hi:
            r = _buffer(work[0], ch, nch)
            args = (X, W, G, N, c, half, T)
            part[ch] = _blocked(_sto_block, lo, hi, r, args)
    acc = part.sum()
    acc += _sto_one(X, W, G, N, 0, N - 1, 1, c, half, T)
    acc += _sto_one(X, W, G, N, N - 1, N - 2, 0, c, half, T)
    rr[0] = acc


@numba.njit(cache=True, inline="always")
def _final_sto_one(X, W, Wn, N, i, im, ip, c, hp, T):  # type: ignore[no-untyped-def]
    b0, b1, b2 = _b(X, N, c, i, im, ip)
    n0, n1, n2 = _noise_of(T, N, i)
    d0, d1, d2 = _stage_increment(X, W, N, i, b0 + n0, b1 + n1, b2 + n2, hp)
    _add_plain(W, Wn, N, i, d0, d1, d2)


@numba.njit(cache=True, fastmath=_STATE)
def _final_sto(X, W, Wn, N, c, hp, T):  # type: ignore[no-untyped-def]
    """``Wn = W + h B~(X) x G(X)``, the step's noise term ``T`` in ``B~`` (the interior in a
    loop of its own, as :func:`_final_loops`)."""
    _final_sto_one(X, W, Wn, N, 0, N - 1, 1 % N, c, hp, T)
    for i in range(1, N - 1):
        _final_sto_one(X, W, Wn, N, i, i - 1, i + 1, c, hp, T)
    if N > 1:
        _final_sto_one(X, W, Wn, N, N - 1, N - 2, 0, c, hp, T)


@numba.njit(cache=True)
def finish_sto(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = W + h B~(X) x G(X)`` from the accepted ``X``, the step's noise in ``B~`` (not
    compensated: ``E`` is empty)."""
    _final_sto(X, W, Wn, lay.N, _coupling(lay), hp, work[work.shape[0] - 1])
    fin[0] = math.isfinite(_size(Wn))


#: Scratch rows of the stochastic sweeps: the residuals' buffers and the step's noise term.
STO_NWORK = 2


def stochastic_sweeps(layout: Layout) -> tuple[Any, Any]:
    """The stochastic midpoint's fused specialization on the chain."""
    par = layout.record.nch > 1
    return (iterate_sto_par if par else iterate_sto_ser), finish_sto


# ---- the Cayley update after the fused sweeps (``update="cayley"``) ------------------------------
# The sweeps keep no ``B``: the finish forms ``B_i(X)`` of the accepted stage spin by spin (with
# the step's noise for the stochastic midpoint), rotates ``W_i`` by its Cayley factor and adds
# the increment as the midpoint finish adds its own, in one pass.


@numba.njit(cache=True, inline="always")
def _cayley_rotation_increment(Y, W, N, i, b0, b1, b2, h):  # type: ignore[no-untyped-def]
    """The rotation's increment ``d_i`` of ``u = h/2 b`` with ``b = (b0, b1, b2)``
    (:func:`~isoflow._compiled.particles.so3_cayley`; ``Y`` is not read)."""
    n, k = _U(N), _U(i)
    n2 = n + n
    return so3_cayley(b0, b1, b2, W[k], W[n + k], W[n2 + k], 0.5 * h)


@numba.njit(cache=True, fastmath=_STATE)
def _cayley_final(X, W, Wn, E, N, c, hp):  # type: ignore[no-untyped-def]
    """The Cayley finish without noise (:func:`_final_loops`)."""
    _final_loops(_cayley_rotation_increment, X, W, Wn, E, N, c, hp)


@numba.njit(cache=True, inline="always")
def _cayley_sto_spin(X, W, Wn, E, N, i, im, ip, c, hp, T):  # type: ignore[no-untyped-def]
    b0, b1, b2 = _b(X, N, c, i, im, ip)
    n0, n1, n2 = _noise_of(T, N, i)
    d0, d1, d2 = _cayley_rotation_increment(X, W, N, i, b0 + n0, b1 + n1, b2 + n2, hp)
    if E.shape[0] != 0:
        _add_compensated(W, Wn, E, N, i, d0, d1, d2)
    else:
        _add_plain(W, Wn, N, i, d0, d1, d2)


@numba.njit(cache=True, fastmath=_STATE)
def _cayley_final_sto(X, W, Wn, E, N, c, hp, T):  # type: ignore[no-untyped-def]
    """The Cayley finish with the step's noise term ``T`` in ``B~`` (as :func:`_final_sto`),
    the interior in loops of their own, the branch on ``E`` outside them (inside, it kept the
    loop scalar: 3.6 against 0.45 ms over 10^5 spins)."""
    _cayley_sto_spin(X, W, Wn, E, N, 0, N - 1, 1 % N, c, hp, T)
    if E.shape[0] != 0:
        for i in range(1, N - 1):
            b0, b1, b2 = _b(X, N, c, i, i - 1, i + 1)
            n0, n1, n2 = _noise_of(T, N, i)
            d0, d1, d2 = _cayley_rotation_increment(X, W, N, i, b0 + n0, b1 + n1, b2 + n2, hp)
            _add_compensated(W, Wn, E, N, i, d0, d1, d2)
    else:
        for i in range(1, N - 1):
            b0, b1, b2 = _b(X, N, c, i, i - 1, i + 1)
            n0, n1, n2 = _noise_of(T, N, i)
            d0, d1, d2 = _cayley_rotation_increment(X, W, N, i, b0 + n0, b1 + n1, b2 + n2, hp)
            _add_plain(W, Wn, N, i, d0, d1, d2)
    if N > 1:
        _cayley_sto_spin(X, W, Wn, E, N, N - 1, N - 2, 0, c, hp, T)


@numba.njit(cache=True)
def finish_iso_cayley(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn_i = C_i W_i`` per spin, ``C_i`` the Cayley rotation of ``h/2 B_i(X)`` of the
    accepted ``X``."""
    _cayley_final(X, W, Wn, E, lay.N, _coupling(lay), hp)
    fin[0] = math.isfinite(_size(Wn))


@numba.njit(cache=True)
def finish_sto_cayley(f, fargs, lay, mp, sd, W, X, aux, work, hp, E, Wn, fin):  # type: ignore[no-untyped-def]
    """:func:`finish_iso_cayley` with the step's noise in ``B~`` (as :func:`finish_sto`)."""
    _cayley_final_sto(X, W, Wn, E, lay.N, _coupling(lay), hp, work[work.shape[0] - 1])
    fin[0] = math.isfinite(_size(Wn))


def isomp_cayley_sweeps(layout: Layout) -> tuple[Any, Any]:
    """IsoMP's fused sweeps with the Cayley finish."""
    return isomp_sweeps(layout)[0], finish_iso_cayley


def stochastic_cayley_sweeps(layout: Layout) -> tuple[Any, Any]:
    """The stochastic midpoint's fused sweeps with the Cayley finish."""
    return stochastic_sweeps(layout)[0], finish_sto_cayley


# ---- the generic blocks on the (3, N) layout (component a of spin i at a * N + i) ---------------


@numba.njit(cache=True, inline="always")
def _cayley_increment(lay, B, W, h, D):  # type: ignore[no-untyped-def]
    N = lay.N
    half = 0.5 * h
    for i in range(N):
        d0, d1, d2 = so3_cayley(B[i], B[N + i], B[2 * N + i], W[i], W[N + i], W[2 * N + i],
                                half)  # fmt: skip
        D[i] = d0
        D[N + i] = d1
        D[2 * N + i] = d2


@numba.njit(cache=True, inline="always")
def _evaluate_B(lay, f, fargs, X, B):  # type: ignore[no-untyped-def]
    N = lay.N
    for i in range(N):
        im = i - 1 if i > 0 else N - 1
        ip = i + 1 if i < N - 1 else 0
        b0, b1, b2 = _b(X, N, _coupling(lay), i, im, ip)
        B[i] = b0
        B[N + i] = b1
        B[2 * N + i] = b2


@numba.njit(cache=True, inline="always")
def _bracket_triple(lay, B, X, C, T):  # type: ignore[no-untyped-def]
    N = lay.N
    for i in range(N):
        c0, c1, c2, t0, t1, t2 = so3_forms(B[i], B[N + i], B[2 * N + i], X[i], X[N + i],
                                           X[2 * N + i])  # fmt: skip
        C[i] = c0
        C[N + i] = c1
        C[2 * N + i] = c2
        T[i] = t0
        T[N + i] = t1
        T[2 * N + i] = t2


@numba.njit(cache=True, inline="always")
def _bracket(lay, B, X, C):  # type: ignore[no-untyped-def]
    N = lay.N
    for i in range(N):
        c0, c1, c2, _, _, _ = so3_forms(B[i], B[N + i], B[2 * N + i], X[i], X[N + i],
                                        X[2 * N + i])  # fmt: skip
        C[i] = c0
        C[N + i] = c1
        C[2 * N + i] = c2


@numba.njit(cache=True, inline="always")
def _stage_map(lay, W, h, B, X, G, C, T, rr):  # type: ignore[no-untyped-def]
    """The closed-form stage of every spin (:func:`~isoflow._compiled.particles.so3_stage`)
    on the ``(3, N)`` layout; ``T`` is not used."""
    N = lay.N
    half = 0.5 * h
    acc = 0.0
    for i in range(N):
        g0, g1, g2, c0, c1, c2 = so3_stage(B[i], B[N + i], B[2 * N + i], W[i], W[N + i],
                                           W[2 * N + i], half)  # fmt: skip
        acc += (g0 - X[i]) ** 2 + (g1 - X[N + i]) ** 2 + (g2 - X[2 * N + i]) ** 2  # X before G
        G[i] = g0
        G[N + i] = g1
        G[2 * N + i] = g2
        C[i] = c0
        C[N + i] = c1
        C[2 * N + i] = c2
    rr[0] = acc


@numba.njit(cache=True, inline="always")
def _spherical_point(lay, W, M, mid):  # type: ignore[no-untyped-def]
    _point_range(M, W, mid, lay.N, 0, lay.N)


blocks.provide(blocks.evaluate_B, *CHAIN_RECORDS)(_evaluate_B)
blocks.provide(blocks.cayley_increment, *CHAIN_RECORDS)(_cayley_increment)
blocks.provide(blocks.bracket_triple, *CHAIN_RECORDS)(_bracket_triple)
blocks.provide(blocks.bracket, *CHAIN_RECORDS)(_bracket)
blocks.provide(blocks.stage_map, *CHAIN_RECORDS)(_stage_map)
blocks.provide(blocks.spherical_point, *CHAIN_RECORDS)(_spherical_point)
blocks.provide(blocks.stage_update, *CHAIN_RECORDS)(flat_stage_update)
blocks.provide(blocks.stage_update1, *CHAIN_RECORDS)(flat_stage_update1)
blocks.provide(blocks.advance_state, *CHAIN_RECORDS)(flat_advance_state)
blocks.provide_member_defaults(*CHAIN_RECORDS)


def chain_layout(problem: Any, members: int, threads: int) -> Layout | None:
    r"""The chain layout of a :class:`~isoflow.SpinNeighbourSum` run on
    :math:`(\mathbb{R}^3,\times)^N` with ``N >= 2``, or ``None``."""
    alg = problem.algebra
    kernel = problem.kernel
    if type(alg) is not SpinVectors or not isinstance(kernel, SpinNeighbourSum):
        return None
    N = alg.shape[0]
    if N < 2:
        return None
    par = N >= PARALLEL_MIN_SPINS and threads > 1
    nch = 8 * threads if par else 1
    c, lam = float(kernel.coupling), float(kernel.damping)
    record = SpinChain(N, c, nch) if lam == 0.0 else DampedSpinChain(N, c, nch, lam)

    def to_units(Y: Any) -> Any:
        return np.ascontiguousarray(np.swapaxes(Y, -1, -2), dtype=np.float64).reshape(
            Y.shape[0], -1
        )

    def from_units(A: Any) -> Any:
        return np.swapaxes(A.reshape(*A.shape[:-1], 3, N), -1, -2)

    return Layout(
        f"spin chain ((3, N) layout{', threaded sweeps' if par else ''})",
        record, to_units=to_units, from_units=from_units,
        offsets_from_units=from_units, rows_from_flat=from_units, identity=False,
        threaded=par,
    )  # fmt: skip
