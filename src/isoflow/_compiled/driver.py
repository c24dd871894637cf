r"""The one compiled time loop: every layout, every stage, every kernel, every member.

:func:`run_unit` advances one *unit* of a layout (one ensemble member, or ``L`` members
interleaved as SIMD lanes, :func:`~isoflow._compiled.blocks.lanes`) by ``plan.nsteps`` steps. A
step is one or more substeps (a composition :math:`\Phi_h = \phi_{g_1 h} \circ \dots \circ
\phi_{g_P h}`; one substep with :math:`g_1 = 1` for the plain method), each an optional explicit
part (``begin``, a split step's flow) and a fixed-point solve for the stage ``X`` of a
midpoint-type method,

.. math::

    X = G(X), \qquad W_{k+1} = \text{finish}(W_k, X),

where the stage (:mod:`isoflow._compiled.stages`) evaluates ``G`` per lane with its auxiliary
output (``iterate``) and the new state (``finish``). Everything else exists here once:

* the extrapolated initial guess and the ring of stage offsets (:mod:`isoflow._compiled.flat`),
  one ring per substep position (substeps of different lengths keep separate histories); a
  fitted start that falls back to the interpolating one where that would have predicted the
  newest offset within half the tolerance (``plan.kint``, single-lane units). The start is a
  function passed like the stage's (``start``: :func:`isoflow._compiled.flat.start`, or on
  large dense states :func:`isoflow._compiled.dense_start.lower_start`, which reads the lower
  triangle of the offsets and gives the same start);
* the compensation of the update (``comp``, one per substep position: the rounding error
  the position's last addition left, handed to ``finish``; an empty buffer for a method that
  does not compensate, see :mod:`isoflow.methods.isomp`);
* the stopping rules of :mod:`isoflow.nonlinear` (a numba compilation of the same function),
  per lane, and Anderson mixing (one lane per unit; ``mix``, :func:`~isoflow._compiled.flat.
  anderson`, passed like the stage functions so that a driver neither compiles nor
  re-optimizes it when the run does not mix, see :mod:`isoflow._compiled.signatures`);
* failure bookkeeping: a member whose solve fails (or whose state turns non-finite) is frozen
  at its last good state, and its record says at which step, why, after how many iterations
  and with which residual; the other members go on;
* saving: the state after every save point of the plan (:class:`isoflow._save_grid.SaveGrid`)
  goes into the unit's members' rows of the output buffer.

Units are independent, so each runs all its steps on its own (unit-outer loops); the drivers
run the units in sequence (:func:`drive_serial`) or over numba threads (:func:`drive_parallel`).
The state-sized buffers of a unit's steps (the stage, its guess and new state, the stage's
scratch rows, the state and compensations a failed step returns to) are the caller's: one set
per thread (``sv``, ``sw``, ``se``, indexed by the numba thread's id), kept by the runner from
call to call for large units. Allocated afresh in every call, they cost a page fault per 4 KiB
touched (at ``N = 1024`` about 150 MB a call, 60-100 ms on this machine's VM, while a solve at
that size calls the loop for every step or two); a small unit's (the runner passes buffers of
length 0) are allocated here, which measured faster.
The per-step arithmetic of a member does not depend on how many steps a call takes, so a run
split into calls anywhere gives the same states bit for bit.

Record layout (``rec``, one row of ``REC_SIZE`` floats per member): see the ``REC_*`` indices.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from . import blocks
from .atomics import take
from .flat import copy, push
from .rules import CONTINUE, STATUS_CONVERGED, STATUS_MAX_ITER, STATUS_NON_FINITE, stopping_step

__all__ = [
    "REC_CALL_DONE",
    "REC_FAIL_ITERATIONS",
    "REC_FAIL_RESIDUAL",
    "REC_FAIL_STATUS",
    "REC_FAIL_STEP",
    "REC_ITERATIONS",
    "REC_ITERATIONS_MAX",
    "REC_RESIDUAL_MAX",
    "REC_SIZE",
    "drive_parallel",
    "drive_serial",
    "run_unit",
]

#: Step (global index, from 1) at which the member failed, ``-1`` while it is alive.
REC_FAIL_STEP = 0
#: Status code of the failed solve (``STATUS_NON_FINITE`` for a non-finite new state).
REC_FAIL_STATUS = 1
#: Iterations spent on the failed step (all substeps).
REC_FAIL_ITERATIONS = 2
#: Final residual of the failed solve.
REC_FAIL_RESIDUAL = 3
#: Iterations (= evaluations of ``B``) summed over the accepted and failed steps of the call.
REC_ITERATIONS = 4
#: Largest number of iterations of one step in the call.
REC_ITERATIONS_MAX = 5
#: Largest final residual of an accepted solve in the call.
REC_RESIDUAL_MAX = 6
#: Set to 1 when the member's call returns (the caller clears it before the call): a member
#: whose field raised has 0, also where a parallel driver loses the exception (numba does not
#: propagate an exception raised on a worker thread).
REC_CALL_DONE = 7
REC_SIZE = 8


@numba.njit(cache=True, inline="always")
def _record_failure(rec, k, code, its, r):  # type: ignore[no-untyped-def]
    """Mark a member's record failed at step ``k``."""
    rec[REC_FAIL_STEP] = k
    rec[REC_FAIL_STATUS] = code
    rec[REC_FAIL_ITERATIONS] = its
    rec[REC_FAIL_RESIDUAL] = r


# The heavier per-lane bookkeeping of a step (the stopping rule, failures), on the lanes' small
# arrays only: compiled once for every layout, stage and field (the driver is compiled per run
# signature; keeping these out of its body keeps that compilation shorter).
@numba.njit(cache=True)
def _check_lanes(rr, it, going, res, its_p, prev, first, code, tol, floor, divergence_factor):  # type: ignore[no-untyped-def]
    """The stopping rule for every lane still iterating; whether any goes on."""
    more = False
    for q in range(rr.shape[0]):
        if going[q]:
            r = math.sqrt(rr[q])
            res[q] = r
            its_p[q] = it
            c, prev[q], first[q] = stopping_step(
                r, prev[q], first[q], it, tol[q], floor[q], divergence_factor
            )
            if c != CONTINUE:
                code[q] = c
                going[q] = False
            else:
                more = True
    return more


@numba.njit(cache=True)
def _judge_lanes(ok, its, its_p, code, fin, res, fail_code, fail_res, res_max):  # type: ignore[no-untyped-def]
    """After a substep's finish: lanes whose solve failed or whose state is not finite stop
    being ``ok``; the number of such lanes."""
    n_failed = 0
    for q in range(ok.shape[0]):
        if not ok[q]:
            continue
        its[q] += its_p[q]
        if code[q] != STATUS_CONVERGED or not fin[q]:
            ok[q] = False
            n_failed += 1
            fail_code[q] = code[q] if code[q] != STATUS_CONVERGED else STATUS_NON_FINITE
            fail_res[q] = res[q]
        elif res[q] > res_max[q]:
            res_max[q] = res[q]
    return n_failed


@numba.njit(cache=True)
def _close_step(alive, ok, its, it_tot, it_max, restore, fail_code, fail_res, rec, m0, k):  # type: ignore[no-untyped-def]
    """End of step ``k``: count iterations, freeze the lanes that failed (``restore``) and
    record why; the number frozen now."""
    n_failed = 0
    for q in range(alive.shape[0]):
        failed = alive[q] and not ok[q]
        restore[q] = failed
        if not alive[q]:
            continue
        it_tot[q] += its[q]
        if its[q] > it_max[q]:
            it_max[q] = its[q]
        if failed:  # frozen at the state before this step
            alive[q] = False
            n_failed += 1
            _record_failure(rec[m0 + q], k, fail_code[q], its[q], fail_res[q])
    return n_failed


@numba.njit(cache=True, nogil=True)
def run_unit(  # type: ignore[no-untyped-def]
    begin, iterate, finish, mix, start, f, fargs, lay, mp, nwork,
    W, ring, head, nh, comp, coefs, gammas, plan, data, out, solver, rec, sv, sw, se, m0, tid,
):  # fmt: skip
    """Advance one unit (flat state ``W``, its ``ring`` ``(P, K, S)``, ``head``/``nh``
    ``(P,)`` and compensation ``comp`` ``(P, S)`` or ``(P, 0)``) by ``plan.nsteps`` steps; its
    lanes are the members ``m0, m0 + 1, ...`` (those below ``rec.shape[0]``). Its buffers are
    thread ``tid``'s: ``sv[tid]`` ``(5, S)``, ``sw[tid]`` ``(max(nwork, 1), S)``, ``se[tid]``
    ``(P, S)`` or ``(P, 0)`` (their contents on entry do not matter). See the module
    docstring."""
    S = W.shape[0]
    P = gammas.shape[0]
    K = ring.shape[1]
    L = blocks.lanes(lay)
    M = rec.shape[0]
    nv = min(L, M - m0)  # valid lanes (the last unit may be padded)
    dt = W.dtype
    h = plan.h
    k0 = plan.k0
    every = plan.save_every
    k_final = plan.k_final
    mem = solver.anderson
    alive = np.zeros(L, dtype=np.bool_)
    n_alive = 0
    for q in range(nv):
        if rec[m0 + q, REC_FAIL_STEP] < 0:
            alive[q] = True
            n_alive += 1
    row = 0
    if n_alive == 0:  # frozen earlier: the saved rows repeat the last good states
        for step in range(plan.nsteps):
            k = k0 + step + 1
            if k % every == 0 or k == k_final:
                blocks.store(lay, out, row, m0, nv, W)
                row += 1
        for q in range(nv):
            rec[m0 + q, REC_CALL_DONE] = 1.0
        return
    # A step that changes the state before its solve (earlier substeps, a split step's first
    # half) keeps the state it started from, to freeze a failed lane there (not a begin that
    # fills scratch rows only: the stochastic step's noise term).
    keep_start = P > 1 or plan.begin_moves
    if sv.shape[2] == S:  # the runner's buffers (large units)
        vec = sv[tid]
        X = vec[0]
        G = vec[1]
        aux = vec[2]
        Wn = vec[3]
        Wstart = vec[4]
        work = sw[tid]
    else:  # small units: fresh buffers, as fast as the cache keeps them
        X = np.empty(S, dtype=dt)
        G = np.empty(S, dtype=dt)
        aux = np.empty(S, dtype=dt)
        Wn = np.empty(S, dtype=dt)
        Wstart = np.empty(S if keep_start else 1, dtype=dt)
        work = np.empty((max(nwork, 1), S), dtype=dt)
    # One lane and one substep: the new state is written to the second buffer and the two swap
    # (no copy a step); a failed step leaves the state buffer untouched.
    swap = L == 1 and not keep_start
    Wcur = W
    swapped = False
    compensated = comp.shape[1] != 0
    # The compensations at the start of a step: a failed lane's are restored. Without lanes to
    # restore one by one (``swap``), a failed step resets its compensation to zero instead of
    # copying it every step: a frozen member never steps again, and zero is a valid one.
    if se.shape[2] == comp.shape[1]:
        Estart = se[tid]  # (P, S) when compensated, else (P, 0); read only when not ``swap``
    else:
        Estart = np.empty(comp.shape if compensated and not swap else (P, 0), dtype=comp.dtype)
    D = data.shape[2]
    sd = np.empty((L, D))
    mm = max(mem, 1)
    Sa = S if mem > 0 else 1
    dF = np.empty((mm, Sa), dtype=dt)
    dG = np.empty((mm, Sa), dtype=dt)
    fprev = np.empty(Sa, dtype=dt)
    gprev = np.empty(Sa, dtype=dt)
    fcur = np.empty(Sa, dtype=dt)
    gram = np.zeros((mm, mm))
    gamma = np.zeros(mm)
    rr = np.zeros(L)
    fin = np.ones(L, dtype=np.bool_)
    scale2 = np.zeros(L)
    going = np.zeros(L, dtype=np.bool_)
    ok = np.zeros(L, dtype=np.bool_)
    code = np.zeros(L, dtype=np.int64)
    fail_code = np.zeros(L, dtype=np.int64)
    its_p = np.zeros(L, dtype=np.int64)
    its = np.zeros(L, dtype=np.int64)
    res = np.zeros(L)
    prev = np.zeros(L)
    first = np.zeros(L)
    tol = np.zeros(L)
    floor = np.zeros(L)
    it_tot = np.zeros(L, dtype=np.int64)
    it_max = np.zeros(L, dtype=np.int64)
    res_max = np.zeros(L)
    fail_res = np.zeros(L)
    restore = np.zeros(L, dtype=np.bool_)
    kfit = plan.kint if L == 1 else 0  # a fitted start's fallback: single members only
    to_save = every - k0 % every  # steps until the next k with k % every == 0
    for step in range(plan.nsteps):
        k = k0 + step + 1
        if D > 0:
            for q in range(L):
                for j in range(D):
                    sd[q, j] = data[step, m0 + q, j]
        if keep_start:
            copy(Wstart, Wcur)
        if compensated and not swap:
            for p in range(P):
                copy(Estart[p], comp[p])
        for q in range(L):
            its[q] = 0
            ok[q] = alive[q]
        n_ok = n_alive
        for p in range(P):
            hp = gammas[p] * h
            if plan.begin:
                begin(f, fargs, lay, mp, sd, Wcur, work, hp)
            blocks.lane_sumsq(lay, Wcur, scale2)
            limit = 0.5 * (solver.atol + solver.rtol * math.sqrt(scale2[0])) if kfit else 0.0
            start(lay, Wcur, ring[p], head[p], nh[p], coefs, kfit, limit, X)
            for q in range(L):
                sc = math.sqrt(scale2[q])
                tol[q] = solver.atol + solver.rtol * sc
                floor[q] = solver.stall_rtol * sc
                prev[q] = math.inf
                first[q] = math.inf
                code[q] = STATUS_MAX_ITER
                res[q] = math.inf
                its_p[q] = 0
                going[q] = ok[q]
            for it in range(1, solver.max_iter + 1):
                iterate(f, fargs, lay, mp, sd, Wcur, X, G, aux, work, hp, rr)
                more = _check_lanes(
                    rr, it, going, res, its_p, prev, first, code, tol, floor,
                    solver.divergence_factor,
                )  # fmt: skip
                if not more:
                    break
                if mem > 0:  # one lane per unit (the runner's rule)
                    mix(it, X, G, dF, dG, gram, fprev, gprev, fcur, gamma,
                        solver.regularization)  # fmt: skip
                elif L == 1:
                    X, G = G, X
                else:
                    blocks.select_lanes(lay, X, G, going)
            finish(f, fargs, lay, mp, sd, Wcur, X, aux, work, hp, comp[p], Wn, fin)
            n_ok -= _judge_lanes(ok, its, its_p, code, fin, res, fail_code, fail_res, res_max)
            if n_ok == 0:
                break
            if plan.kmax > 0:
                slot = head[p] + 1
                if slot == K:
                    slot = 0
                push(ring[p], slot, G, Wcur)
                head[p] = slot
                nh[p] = min(nh[p] + 1, plan.kmax)
            if not swap:
                blocks.commit_lanes(lay, Wcur, Wn, ok)
            elif ok[0]:
                Wcur, Wn = Wn, Wcur
                swapped = not swapped
        n_failed = _close_step(
            alive, ok, its, it_tot, it_max, restore, fail_code, fail_res, rec, m0, k
        )
        n_alive -= n_failed
        failed_now = n_failed > 0
        if failed_now and keep_start:  # earlier substeps or a half step changed it: undo them
            blocks.commit_lanes(lay, Wcur, Wstart, restore)
        if failed_now and compensated:  # and the compensations the step changed
            for p in range(P):
                if swap:
                    comp[p][:] = 0.0
                else:
                    blocks.commit_lanes(lay, comp[p], Estart[p], restore)
        to_save -= 1
        if to_save == 0 or k == k_final:  # k % every == 0, without a division per step
            blocks.store(lay, out, row, m0, nv, Wcur)
            row += 1
        if to_save == 0:
            to_save = every
        if n_alive == 0:  # every lane frozen: the remaining rows repeat the states
            for rest in range(step + 1, plan.nsteps):
                kk = k0 + rest + 1
                if kk % every == 0 or kk == k_final:
                    blocks.store(lay, out, row, m0, nv, Wcur)
                    row += 1
            break
    if swapped:  # the state is in the second buffer
        copy(W, Wcur)
    for q in range(nv):
        m = m0 + q
        rec[m, REC_ITERATIONS] += it_tot[q]
        rec[m, REC_ITERATIONS_MAX] = max(rec[m, REC_ITERATIONS_MAX], it_max[q])
        rec[m, REC_RESIDUAL_MAX] = max(rec[m, REC_RESIDUAL_MAX], res_max[q])
        rec[m, REC_CALL_DONE] = 1.0


# The drivers are compiled per run signature by :func:`isoflow._compiled.signatures.
# compiled_driver` (explicit function types, no dispatcher arguments). Serial and parallel are
# separate functions on purpose: numba's on-disk cache keys an entry by signature, machine and
# bytecode only (not by ``parallel=``), so one body compiled twice with ``cache=True`` would
# share a cache entry and one variant could load the other.
def drive_serial(  # type: ignore[no-untyped-def]
    begin, iterate, finish, mix, start, f, fargs, lay, mp, nwork,
    W, ring, head, nh, comp, coefs, gammas, plan, data, out, solver, rec, sv, sw, se,
):  # fmt: skip
    """:func:`run_unit` for every unit ``u`` of ``W`` (``(U, S)``), one after another, on the
    buffers of thread 0."""
    L = blocks.lanes(lay)
    for u in range(W.shape[0]):
        run_unit(
            begin, iterate, finish, mix, start, f, fargs, lay, mp, nwork, W[u], ring[u], head[u],
            nh[u], comp[u], coefs, gammas, plan, data, out, solver, rec, sv, sw, se, u * L, 0,
        )  # fmt: skip


def drive_parallel(  # type: ignore[no-untyped-def]
    begin, iterate, finish, mix, start, f, fargs, lay, mp, nwork,
    W, ring, head, nh, comp, coefs, gammas, plan, data, out, solver, rec, sv, sw, se,
):  # fmt: skip
    """:func:`run_unit` for every unit of ``W`` over numba threads, each on its thread's
    buffers (``numba.get_thread_id()`` is below the threads of the region, which the buffers'
    first axis covers). Each thread takes the next unit from a shared counter as it comes
    free (:func:`~isoflow._compiled.atomics.take`), so a thread that shares its core or draws
    the costlier members does not hold up the others; a unit's states do not depend on the
    thread that runs it."""
    L = blocks.lanes(lay)
    U = W.shape[0]
    taken = np.zeros(1, np.int64)
    for _ in numba.prange(min(sv.shape[0], U)):
        tid = numba.get_thread_id()
        u = take(taken)
        while u < U:
            run_unit(
                begin, iterate, finish, mix, start, f, fargs, lay, mp, nwork, W[u], ring[u],
                head[u], nh[u], comp[u], coefs, gammas, plan, data, out, solver, rec, sv, sw, se,
                u * L, tid,
            )  # fmt: skip
            u = take(taken)
