r"""Compiled IsoMP and spherical-midpoint loops for point vortices (:class:`PairwiseVortex`).

The field is the pair sum

.. math::

    B_i(x) = c \sum_{j \ne i} \Gamma_j\, f(x_i \cdot x_j)\, x_j ,

on the sphere (:math:`(\mathbb{R}^3,\times)^N`, Euclidean dot, :math:`f(D) = 1/(1 - D)`,
:math:`c = 1/(4\pi)`) or on the hyperboloid (:math:`(\mathbb{R}^3,\times_L)^N`, Lorentzian dot
:math:`a_1 b_1 + a_2 b_2 - a_3 b_3`, :math:`f(D) = 1/((D - 1)(D + 1))`, :math:`c = -1/\pi`).
Since :math:`D_{ij} = D_{ji}`, one pass over the pairs ``i < j`` computes the factor
:math:`q_{ij} = f(D_{ij})` once and adds :math:`\Gamma_j q_{ij} x_j` to :math:`B_i` and
:math:`\Gamma_i q_{ij} x_i` to :math:`B_j` (``N(N-1)/2`` divisions per evaluation; each
:math:`B_i` still sums its terms in the order ``j = 0, 1, ..., N-1``).

IsoMP (one evaluation of ``B`` per iteration; the products of
:meth:`SpinVectors.bracket_and_triple <isoflow.algebras.SpinVectors.bracket_and_triple>` and
:meth:`SL2Vectors.bracket_and_triple <isoflow.algebras.SL2Vectors.bracket_and_triple>`,
``b = B_i(x)``):

.. math::

    G_i = w_i + \tfrac h2\, C_i + \tfrac{h^2}{4}\, T_i, \qquad
    (C_i, T_i) = \begin{cases}
        \bigl(b \times x_i,\; -(b\cdot x_i)\, b\bigr) & \text{sphere,} \\
        \bigl(-2L(b \times x_i),\; 2 (b\cdot_L x_i)\, b - (b\cdot_L b)\, x_i\bigr)
            & \text{hyperbolic,}
    \end{cases}

and :math:`w_{k+1,i} = w_i + h\, C_i` with the ``C`` of the accepted ``x`` (kept from the last
evaluation, as the NumPy path keeps the auxiliary output of ``G``).

Spherical midpoint (sphere only; unknown ``M = (w_k + w_{k+1})/2``):

.. math::

    m_i = \sqrt{|w_i|\,|2M_i - w_i|}\; M_i/|M_i|, \qquad
    G_i = w_i + \tfrac h2\, B_i(m) \times m_i,

and :math:`w_{k+1} = w_k + h\, B(m)\times m`.

Both use the stopping rules of :mod:`isoflow.nonlinear` (per ensemble member, the residual is
the Euclidean norm over all vortices, the scale :math:`|w_k|`) and the same stage-offset
extrapolation as the NumPy paths. The ``M`` states ``(M, N, 3)`` are copied once per call into
one work buffer, layout ``(slot, M, 3, N)`` (see ``_RING``); the input is never written.
Ensemble members are advanced step-synchronously (a failing member stops the ensemble at that
step), member by member (:func:`_drive_ser`), or spread over numba threads
(:func:`_drive_par`) for large ensembles. No ``fastmath``: the sums are evaluated in the
written order, so the results agree with the NumPy path to rounding and the iteration counts
are the same. ``error_model="numpy"``: a zero denominator (two coinciding vortices) gives
``inf`` and then the ``non_finite`` status, as on the NumPy path, instead of raising
``ZeroDivisionError``.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from ._rules import STATUS_CONVERGED as _CONVERGED
from ._rules import STATUS_MAX_ITER as _MAX_ITER
from ._rules import STATUS_RUNNING, stopping_step

__all__ = ["advance_vortices"]

_ISOMP, _SMM = 0, 1
_SPHERE, _HYPERBOLIC = 0, 1
_GEOMETRY = {"sphere": _SPHERE, "hyperbolic": _HYPERBOLIC}

# Slots of the work buffer ``buf`` (``(_RING + K + 1, M, 3, N)``): two state buffers (current
# and next, swapped by index after every accepted step), the stage X, the other iterate G, the
# bracket C, the field B, the spherical point m, then the ring of stage offsets (``K`` slots
# and a scratch slot). One array instead of ten: numba increfs and decrefs (atomically) every
# array argument of every call, which costs more than a whole iteration of a 3-vortex system.
_X, _G, _C, _B, _MID, _RING = 2, 3, 4, 5, 6, 7


@numba.njit(cache=True, error_model="numpy", inline="always")
def _field(geo, buf, src, mm, circ, c):  # type: ignore[no-untyped-def]
    """``B_i = c sum_{j != i} Gamma_j f(x_i . x_j) x_j`` for ``x = buf[src, mm]`` (``(3, N)``)
    into ``buf[_B, mm]``.

    One pass over the pairs ``i < j``: the contributions to ``B_j`` of the rows ``i < j`` are
    accumulated in ``buf[_B, mm, :, j]`` before row ``j`` adds its own ``j' > j`` and scales
    by ``c``.
    """
    N = buf.shape[3]
    for i in range(N):
        buf[_B, mm, 0, i] = 0.0
        buf[_B, mm, 1, i] = 0.0
        buf[_B, mm, 2, i] = 0.0
    sphere = geo == _SPHERE
    for i in range(N):
        xi0, xi1, xi2 = buf[src, mm, 0, i], buf[src, mm, 1, i], buf[src, mm, 2, i]
        gi = circ[i]
        s0, s1, s2 = buf[_B, mm, 0, i], buf[_B, mm, 1, i], buf[_B, mm, 2, i]
        if sphere:
            for j in range(i + 1, N):
                xj0, xj1, xj2 = buf[src, mm, 0, j], buf[src, mm, 1, j], buf[src, mm, 2, j]
                q = 1.0 / (1.0 - (xi0 * xj0 + xi1 * xj1 + xi2 * xj2))
                a = circ[j] * q
                s0 += a * xj0
                s1 += a * xj1
                s2 += a * xj2
                a = gi * q
                buf[_B, mm, 0, j] += a * xi0
                buf[_B, mm, 1, j] += a * xi1
                buf[_B, mm, 2, j] += a * xi2
        else:
            for j in range(i + 1, N):
                xj0, xj1, xj2 = buf[src, mm, 0, j], buf[src, mm, 1, j], buf[src, mm, 2, j]
                d = xi0 * xj0 + xi1 * xj1 - xi2 * xj2
                q = 1.0 / ((d - 1.0) * (d + 1.0))
                a = circ[j] * q
                s0 += a * xj0
                s1 += a * xj1
                s2 += a * xj2
                a = gi * q
                buf[_B, mm, 0, j] += a * xi0
                buf[_B, mm, 1, j] += a * xi1
                buf[_B, mm, 2, j] += a * xi2
        buf[_B, mm, 0, i] = c * s0
        buf[_B, mm, 1, i] = c * s1
        buf[_B, mm, 2, i] = c * s2


@numba.njit(cache=True, error_model="numpy")
def _iso_sweep(geo, buf, src, dst, iw, mm, circ, c, half, quarter):  # type: ignore[no-untyped-def]
    """One IsoMP iteration at ``x = buf[src, mm]``: ``buf[dst, mm] = G = w + h/2 C + h^2/4 T``
    (``w = buf[iw, mm]``); keeps ``C`` in ``buf[_C, mm]``; returns ``|G - x|^2``."""
    _field(geo, buf, src, mm, circ, c)
    N = buf.shape[3]
    sphere = geo == _SPHERE
    rr = 0.0
    for i in range(N):
        b0, b1, b2 = buf[_B, mm, 0, i], buf[_B, mm, 1, i], buf[_B, mm, 2, i]
        x0, x1, x2 = buf[src, mm, 0, i], buf[src, mm, 1, i], buf[src, mm, 2, i]
        k0 = b1 * x2 - b2 * x1
        k1 = b2 * x0 - b0 * x2
        k2 = b0 * x1 - b1 * x0
        if sphere:  # (b x x, -(b.x) b)
            c0, c1, c2 = k0, k1, k2
            d = -(b0 * x0 + b1 * x1 + b2 * x2)
            t0, t1, t2 = d * b0, d * b1, d * b2
        else:  # (-2 L (b x x), 2 (b._L x) b - (b._L b) x)
            c0, c1, c2 = -2.0 * k0, -2.0 * k1, 2.0 * k2
            bx = 2.0 * (b0 * x0 + b1 * x1 - b2 * x2)
            bb = b0 * b0 + b1 * b1 - b2 * b2
            t0 = bx * b0 - bb * x0
            t1 = bx * b1 - bb * x1
            t2 = bx * b2 - bb * x2
        buf[_C, mm, 0, i] = c0
        buf[_C, mm, 1, i] = c1
        buf[_C, mm, 2, i] = c2
        g0 = buf[iw, mm, 0, i] + half * c0 + quarter * t0
        g1 = buf[iw, mm, 1, i] + half * c1 + quarter * t1
        g2 = buf[iw, mm, 2, i] + half * c2 + quarter * t2
        buf[dst, mm, 0, i] = g0
        buf[dst, mm, 1, i] = g1
        buf[dst, mm, 2, i] = g2
        rr += (g0 - x0) ** 2 + (g1 - x1) ** 2 + (g2 - x2) ** 2
    return rr


@numba.njit(cache=True, error_model="numpy")
def _smm_sweep(buf, src, dst, iw, mm, circ, c, half):  # type: ignore[no-untyped-def]
    """One spherical-midpoint iteration at the average ``M = buf[src, mm]``: ``m`` from ``M``
    into ``buf[_MID, mm]``, then ``buf[dst, mm] = G = w + h/2 B(m) x m``; keeps
    ``C = B(m) x m`` in ``buf[_C, mm]``; returns ``|G - M|^2``."""
    N = buf.shape[3]
    for i in range(N):
        w0, w1, w2 = buf[iw, mm, 0, i], buf[iw, mm, 1, i], buf[iw, mm, 2, i]
        a0, a1, a2 = buf[src, mm, 0, i], buf[src, mm, 1, i], buf[src, mm, 2, i]
        nw = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        v0, v1, v2 = 2.0 * a0 - w0, 2.0 * a1 - w1, 2.0 * a2 - w2
        nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        nm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        f = math.sqrt(nw * nv) / nm if nm > 0 else 0.0
        buf[_MID, mm, 0, i] = f * a0
        buf[_MID, mm, 1, i] = f * a1
        buf[_MID, mm, 2, i] = f * a2
    _field(_SPHERE, buf, _MID, mm, circ, c)
    rr = 0.0
    for i in range(N):
        b0, b1, b2 = buf[_B, mm, 0, i], buf[_B, mm, 1, i], buf[_B, mm, 2, i]
        y0, y1, y2 = buf[_MID, mm, 0, i], buf[_MID, mm, 1, i], buf[_MID, mm, 2, i]
        c0 = b1 * y2 - b2 * y1
        c1 = b2 * y0 - b0 * y2
        c2 = b0 * y1 - b1 * y0
        buf[_C, mm, 0, i] = c0
        buf[_C, mm, 1, i] = c1
        buf[_C, mm, 2, i] = c2
        g0 = buf[iw, mm, 0, i] + half * c0
        g1 = buf[iw, mm, 1, i] + half * c1
        g2 = buf[iw, mm, 2, i] + half * c2
        buf[dst, mm, 0, i] = g0
        buf[dst, mm, 1, i] = g1
        buf[dst, mm, 2, i] = g2
        r0 = g0 - buf[src, mm, 0, i]
        r1 = g1 - buf[src, mm, 1, i]
        r2 = g2 - buf[src, mm, 2, i]
        rr += r0 * r0 + r1 * r1 + r2 * r2
    return rr


@numba.njit(cache=True, error_model="numpy", inline="always")
def _guess(buf, iw, mm, head, nh, K, coefs):  # type: ignore[no-untyped-def]
    """``X = w + E``, ``E = sum_q a_q D_{k-q}`` summed in ``buf[_G, mm]`` (scratch here) in the
    order ``q = 1, 2, ...`` (ring slot ``head`` is the newest offset), or ``X = w`` when
    ``nh = 0``; returns ``|w|^2``. One ring slot (one integer modulo) per offset."""
    N = buf.shape[3]
    if nh > 0:
        aq = coefs[nh - 1, 0]
        slot = _RING + head
        for a in range(3):
            for i in range(N):
                buf[_G, mm, a, i] = aq * buf[slot, mm, a, i]
        for q in range(1, nh):
            aq = coefs[nh - 1, q]
            slot = _RING + (head - q) % K
            for a in range(3):
                for i in range(N):
                    buf[_G, mm, a, i] += aq * buf[slot, mm, a, i]
    acc = 0.0
    for a in range(3):
        for i in range(N):
            w = buf[iw, mm, a, i]
            acc += w * w
            buf[_X, mm, a, i] = w + buf[_G, mm, a, i] if nh > 0 else w
    return acc


@numba.njit(cache=True, error_model="numpy", inline="always")
def _final(buf, iw, iwn, new, mm, h):  # type: ignore[no-untyped-def]
    """``buf[iwn, mm] = w + h C`` and the offset ``X - w`` into ring slot ``new``; whether
    every entry of the new state is finite."""
    N = buf.shape[3]
    acc = 0.0
    for a in range(3):
        for i in range(N):
            w = buf[iw, mm, a, i]
            v = w + h * buf[_C, mm, a, i]
            buf[iwn, mm, a, i] = v
            buf[_RING + new, mm, a, i] = buf[_X, mm, a, i] - w
            acc += 0.0 * v  # 0 for finite v, NaN for +-inf and NaN
    return math.isfinite(acc)


@numba.njit(cache=True, error_model="numpy")
def _member(  # type: ignore[no-untyped-def]
    kind, geo, buf, iw, iwn, mm, head, nh, new, K, coefs, circ, c, h, rtol, atol, stall_rtol,
    divf, max_iter,
):  # fmt: skip
    """One step of member ``mm``: the fixed-point solve, then the new state and offset.

    The iterates alternate between the slots ``_X`` and ``_G`` (no copies, no array views);
    returns ``(iterations, residual, status, finite)``.
    """
    half = 0.5 * h
    quarter = 0.25 * h * h
    scale = math.sqrt(_guess(buf, iw, mm, head, nh, K, coefs))
    tol = atol + rtol * scale
    floor = stall_rtol * scale
    prev = math.inf
    first = math.inf
    status = _MAX_ITER
    r = math.inf
    it = 0
    src, dst = _X, _G
    for it in range(1, max_iter + 1):
        if kind == _ISOMP:
            rr = _iso_sweep(geo, buf, src, dst, iw, mm, circ, c, half, quarter)
        else:
            rr = _smm_sweep(buf, src, dst, iw, mm, circ, c, half)
        r = math.sqrt(rr)
        code, prev, first = stopping_step(r, prev, first, it, tol, floor, divf)
        if code != STATUS_RUNNING:
            status = code
            break
        src, dst = dst, src
    if src != _X:  # the accepted iterate lives in G: bring it home
        for a in range(3):
            for i in range(buf.shape[3]):
                buf[_X, mm, a, i] = buf[_G, mm, a, i]
    fin = _final(buf, iw, iwn, new, mm, h)
    return it, r, status, fin


# Two drivers, the same loop: numba compiles a callee with its caller, so the threaded twin
# (seconds of compilation) is only built when it is used, and a separate function anyway:
# numba's on-disk cache keys an entry by signature, machine and bytecode only (not by
# ``parallel=``). Every member has its own slices of every slot, so the threaded loop computes
# exactly what the serial one does.
@numba.njit(cache=True, error_model="numpy")
def _drive_ser(  # type: ignore[no-untyped-def]
    kind, geo, buf, ring, kmax, coefs, circ, c, h, nsteps, rtol, atol, stall_rtol, divf,
    max_iter, its, res, stat, totals,
):  # fmt: skip
    """Step-synchronous loop over ``nsteps`` steps of every member (``buf.shape[1]``).

    ``ring = [iw, head, nh]``: the slot of the current state (``0`` or ``1``, swapped after
    every accepted step), the ring slot of the newest offset and the number of offsets; updated
    in place. ``totals``: iterations summed and largest (over all steps tried) and the largest
    residual of the accepted steps. Returns the number of accepted steps.
    """
    M = buf.shape[1]
    K = buf.shape[0] - _RING - 1
    iw, head, nh = ring[0], ring[1], ring[2]
    for step in range(nsteps):
        new = (head + 1) % K if kmax > 0 else K
        ok = True
        for mm in range(M):
            it, r, st, fin = _member(
                kind, geo, buf, iw, 1 - iw, mm, head, nh, new, K, coefs, circ, c, h, rtol, atol,
                stall_rtol, divf, max_iter,
            )  # fmt: skip
            its[mm] = it
            res[mm] = r
            stat[mm] = st
            totals[0] += it
            totals[1] = max(totals[1], it)
            if st != _CONVERGED or not fin:
                ok = False
        if not ok:
            ring[0], ring[1], ring[2] = iw, head, nh
            return step
        for mm in range(M):
            totals[2] = max(totals[2], res[mm])
        iw = 1 - iw
        if kmax > 0:
            head = new
            nh = min(nh + 1, kmax)
    ring[0], ring[1], ring[2] = iw, head, nh
    return nsteps


@numba.njit(cache=True, parallel=True, error_model="numpy")
def _members_par(  # type: ignore[no-untyped-def]
    kind, geo, buf, iw, head, nh, new, K, coefs, circ, c, h, rtol, atol, stall_rtol, divf,
    max_iter, its, res, stat, fin,
):  # fmt: skip
    """One step of every member, the members spread over numba threads."""
    for mm in numba.prange(buf.shape[1]):
        it, r, st, f = _member(
            kind, geo, buf, iw, 1 - iw, mm, head, nh, new, K, coefs, circ, c, h, rtol, atol,
            stall_rtol, divf, max_iter,
        )  # fmt: skip
        its[mm] = it
        res[mm] = r
        stat[mm] = st
        fin[mm] = f


@numba.njit(cache=True, error_model="numpy")
def _drive_par(  # type: ignore[no-untyped-def]
    kind, geo, buf, ring, kmax, coefs, circ, c, h, nsteps, rtol, atol, stall_rtol, divf,
    max_iter, its, res, stat, totals,
):  # fmt: skip
    """:func:`_drive_ser` with the members of a step spread over threads (:func:`_members_par`)."""
    M = buf.shape[1]
    K = buf.shape[0] - _RING - 1
    fin = np.zeros(M, dtype=np.bool_)
    iw, head, nh = ring[0], ring[1], ring[2]
    for step in range(nsteps):
        new = (head + 1) % K if kmax > 0 else K
        _members_par(
            kind, geo, buf, iw, head, nh, new, K, coefs, circ, c, h, rtol, atol, stall_rtol,
            divf, max_iter, its, res, stat, fin,
        )  # fmt: skip
        ok = True
        for mm in range(M):
            totals[0] += its[mm]
            totals[1] = max(totals[1], its[mm])
            if stat[mm] != _CONVERGED or not fin[mm]:
                ok = False
        if not ok:
            ring[0], ring[1], ring[2] = iw, head, nh
            return step
        for mm in range(M):
            totals[2] = max(totals[2], res[mm])
        iw = 1 - iw
        if kmax > 0:
            head = new
            nh = min(nh + 1, kmax)
    ring[0], ring[1], ring[2] = iw, head, nh
    return nsteps


def advance_vortices(
    kind: str,
    geometry: str,
    y: np.ndarray,
    offsets: list[np.ndarray],
    K: int,
    extrapolate: bool,
    coefs: np.ndarray,
    circulations: np.ndarray,
    coefficient: float,
    h: float,
    nsteps: int,
    rtol: float,
    atol: float,
    stall_rtol: float,
    divergence_factor: float,
    max_iter: int,
    parallel: bool,
) -> dict[str, Any]:
    """Advance the states ``y`` (``(M, N, 3)``, not modified) by ``nsteps`` steps.

    ``kind`` is ``"isomp"`` or ``"smm"`` (``geometry="sphere"`` only), ``geometry``
    ``"sphere"`` or ``"hyperbolic"``; ``circulations`` (``(N,)``) and ``coefficient`` are the
    ``Gamma`` and ``c`` of the field. ``offsets`` are the stored stage offsets (``(M, N, 3)``
    each), oldest first, at most ``K`` (the ring length; used only with ``extrapolate``);
    ``coefs`` the table of extrapolation weights (row ``m - 1`` for ``m`` offsets). Returns
    ``"y"``, ``"y_failed"``, ``"stage"`` and the ``"hist"`` of offsets (oldest first) as
    ``(M, N, 3)`` arrays, and the records of :func:`isoflow._fast.spin.advance_spin`.
    """
    if kind not in ("isomp", "smm"):
        raise ValueError(f"kind must be 'isomp' or 'smm', got {kind!r}")
    geo = _GEOMETRY[geometry]
    if kind == "smm" and geo != _SPHERE:
        raise ValueError("the spherical midpoint is defined on the sphere only")
    M, N, _ = y.shape
    nh = len(offsets) if extrapolate else 0
    buf = np.empty((_RING + K + 1, M, 3, N))  # every slot is written before it is read
    buf[0] = np.swapaxes(y, -1, -2)
    for q in range(nh):
        buf[_RING + q] = np.swapaxes(offsets[q], -1, -2)
    its = np.zeros(M, dtype=np.int64)
    res = np.zeros(M)
    stat = np.zeros(M, dtype=np.int64)
    totals = np.zeros(3)
    ring = np.array([0, (nh - 1) % K, nh], dtype=np.int64)
    drive = _drive_par if parallel else _drive_ser
    done = drive(
        _ISOMP if kind == "isomp" else _SMM, geo, buf, ring, K if extrapolate else 0,
        np.ascontiguousarray(coefs, dtype=np.float64),
        np.ascontiguousarray(circulations, dtype=np.float64), float(coefficient), float(h),
        int(nsteps), float(rtol), float(atol), float(stall_rtol), float(divergence_factor),
        int(max_iter), its, res, stat, totals,
    )  # fmt: skip
    iw, head, nh_out = (int(v) for v in ring)

    def back(slot: int) -> np.ndarray:
        return np.ascontiguousarray(np.swapaxes(buf[slot], -1, -2))

    return {
        "y": back(iw),
        "n_done": int(done),
        "hist": [back(_RING + (head - q) % K) for q in range(nh_out)][::-1],
        "iterations": its,
        "residual": res,
        "status": stat,
        "stage": back(_X),
        "y_failed": back(1 - iw),
        "iterations_total": int(totals[0]),
        "iterations_max": int(totals[1]),
        "residual_max": float(totals[2]),
    }
