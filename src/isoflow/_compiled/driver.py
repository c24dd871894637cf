r"""The one compiled time loop: every layout, every kernel, every member.

:func:`run_member` advances one ensemble member by ``nsteps`` steps. A step is one or more
substeps (a composition :math:`\Phi_h = \phi_{g_1 h} \circ \dots \circ \phi_{g_P h}`; one
substep with :math:`g_1 = 1` for the plain method), each a fixed-point solve for the stage
``X`` of a midpoint-type method:

.. math::

    X = G(X), \qquad W_{k+1} = \Pi\big(W_k + h\, C(X)\big),

where the *stage* functions of a layout (:mod:`isoflow._compiled.dense`,
:mod:`isoflow._compiled.particles`, :mod:`isoflow._compiled.spin_chain`) evaluate ``G`` with
its auxiliary output ``C`` (``iterate``) and the new state (``finish``); they call the kernel's
``f(X, B, *args)`` for ``B``. Everything else exists here once:

* the extrapolated initial guess and the ring of stage offsets (:mod:`isoflow._compiled.flat`),
  one ring per substep position (substeps of different lengths keep separate histories);
* the stopping rules of :mod:`isoflow.nonlinear` (a numba compilation of the same function)
  and Anderson mixing;
* failure bookkeeping: a member whose solve fails (or whose state turns non-finite) is frozen
  at its last good state, and its record says at which step, why, after how many iterations
  and with which residual; the other members go on;
* saving: the state after every ``save_every``-th step (and after step ``k_final``) is
  written into the member's rows of the output buffer.

Members are independent, so each runs all its steps on its own (member-outer loops); the
drivers run the members in sequence (:func:`drive_serial`) or over numba threads
(:func:`drive_parallel`). The per-step arithmetic of a member does not depend on how many
steps a call takes, so a run split into calls anywhere gives the same states bit for bit.

Record layout (``rec``, one row of ``REC_SIZE`` floats per member): see the ``REC_*`` indices.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .flat import anderson, copy, guess, push
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
    "run_member",
]

#: Step (global index) at which the member failed, ``-1`` while it is alive.
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


@numba.njit(cache=True)
def run_member(  # type: ignore[no-untyped-def]
    iterate, finish, f, fargs, sp, nwork,
    W, ring, head, nh, coefs, kmax, gammas,
    h, nsteps, k0, save_every, k_final, out,
    rtol, atol, stall_rtol, divf, max_iter, mem, reg, rec,
):  # fmt: skip
    """Advance one member (flat state ``W``, its ``ring`` ``(P, K, S)`` and ``head``/``nh``
    ``(P,)``) by ``nsteps`` steps starting after global step ``k0``; see the module docstring.

    Returns the number of steps taken (``nsteps``, or fewer if the member failed; a member
    that is already frozen only fills its rows).
    """
    S = W.shape[0]
    P = gammas.shape[0]
    K = ring.shape[1]
    dt = W.dtype
    row = 0
    if rec[REC_FAIL_STEP] >= 0:  # frozen earlier: its saved rows repeat its last good state
        for step in range(nsteps):
            k = k0 + step + 1
            if k % save_every == 0 or k == k_final:
                copy(out[row], W)
                row += 1
        rec[REC_CALL_DONE] = 1.0
        return 0
    X = np.empty(S, dtype=dt)
    G = np.empty(S, dtype=dt)
    aux = np.empty(S, dtype=dt)
    Wn = np.empty(S, dtype=dt)
    work = np.empty((max(nwork, 1), S), dtype=dt)
    Wstart = np.empty(S if P > 1 else 1, dtype=dt)
    mm = max(mem, 1)
    dF = np.empty((mm, S if mem > 0 else 1), dtype=dt)
    dG = np.empty((mm, S if mem > 0 else 1), dtype=dt)
    fprev = np.empty(S if mem > 0 else 1, dtype=dt)
    gprev = np.empty(S if mem > 0 else 1, dtype=dt)
    fcur = np.empty(S if mem > 0 else 1, dtype=dt)
    gram = np.zeros((mm, mm))
    gamma = np.zeros(mm)
    it_tot = 0
    it_max = 0
    res_max = 0.0
    taken = nsteps
    to_save = save_every - k0 % save_every  # steps until the next k with k % save_every == 0
    for step in range(nsteps):
        k = k0 + step + 1
        if P > 1:
            copy(Wstart, W)
        its = 0
        failed = False
        code = STATUS_CONVERGED
        r = 0.0
        for p in range(P):
            hp = gammas[p] * h
            half = 0.5 * hp
            quarter = 0.25 * hp * hp
            scale = math.sqrt(guess(W, ring[p], head[p], nh[p], coefs, X))
            tol = atol + rtol * scale
            floor = stall_rtol * scale
            prev = math.inf
            first = math.inf
            code = STATUS_MAX_ITER
            r = math.inf
            it = 0
            for it in range(1, max_iter + 1):
                rr = iterate(f, fargs, sp, W, X, G, aux, work, half, quarter)
                r = math.sqrt(rr)
                c, prev, first = stopping_step(r, prev, first, it, tol, floor, divf)
                if c != CONTINUE:
                    code = c
                    break
                if mem > 0:
                    anderson(it, X, G, dF, dG, gram, fprev, gprev, fcur, gamma, reg)
                else:
                    X, G = G, X
            its += it
            fin = finish(f, fargs, sp, W, X, aux, work, hp, Wn)
            if code != STATUS_CONVERGED or not fin:
                if code == STATUS_CONVERGED:
                    code = STATUS_NON_FINITE
                failed = True
                break
            if r > res_max:
                res_max = r
            if kmax > 0:
                slot = head[p] + 1
                if slot == K:
                    slot = 0
                push(ring[p], slot, X, W)
                head[p] = slot
                nh[p] = min(nh[p] + 1, kmax)
            copy(W, Wn)
        it_tot += its
        if its > it_max:
            it_max = its
        if failed:
            if P > 1:
                copy(W, Wstart)
            rec[REC_FAIL_STEP] = k
            rec[REC_FAIL_STATUS] = code
            rec[REC_FAIL_ITERATIONS] = its
            rec[REC_FAIL_RESIDUAL] = r
            taken = step
            for rest in range(step, nsteps):  # frozen: the remaining rows repeat W
                kk = k0 + rest + 1
                if kk % save_every == 0 or kk == k_final:
                    copy(out[row], W)
                    row += 1
            break
        to_save -= 1
        if to_save == 0 or k == k_final:  # k % save_every == 0, without a division per step
            copy(out[row], W)
            row += 1
        if to_save == 0:
            to_save = save_every
    rec[REC_ITERATIONS] += it_tot
    rec[REC_ITERATIONS_MAX] = max(rec[REC_ITERATIONS_MAX], it_max)
    rec[REC_RESIDUAL_MAX] = max(rec[REC_RESIDUAL_MAX], res_max)
    rec[REC_CALL_DONE] = 1.0
    return taken


# The drivers are compiled per run signature by :func:`isoflow._compiled.signatures.
# compiled_driver` (explicit function types, no dispatcher arguments). Serial and parallel are
# separate functions on purpose: numba's on-disk cache keys an entry by signature, machine and
# bytecode only (not by ``parallel=``), so one body compiled twice with ``cache=True`` would
# share a cache entry and one variant could load the other.
def drive_serial(  # type: ignore[no-untyped-def]
    iterate, finish, f, fargs, sp, nwork,
    W, ring, head, nh, coefs, kmax, gammas,
    h, nsteps, k0, save_every, k_final, out,
    rtol, atol, stall_rtol, divf, max_iter, mem, reg, rec,
):  # fmt: skip
    """:func:`run_member` for every member ``m`` of ``W`` (``(M, S)``), one after another."""
    for m in range(W.shape[0]):
        run_member(
            iterate, finish, f, fargs, sp, nwork,
            W[m], ring[m], head[m], nh[m], coefs, kmax, gammas,
            h, nsteps, k0, save_every, k_final, out[:, m],
            rtol, atol, stall_rtol, divf, max_iter, mem, reg, rec[m],
        )  # fmt: skip


def drive_parallel(  # type: ignore[no-untyped-def]
    iterate, finish, f, fargs, sp, nwork,
    W, ring, head, nh, coefs, kmax, gammas,
    h, nsteps, k0, save_every, k_final, out,
    rtol, atol, stall_rtol, divf, max_iter, mem, reg, rec,
):  # fmt: skip
    """:func:`run_member` for every member of ``W``, members spread over numba threads."""
    for m in numba.prange(W.shape[0]):
        run_member(
            iterate, finish, f, fargs, sp, nwork,
            W[m], ring[m], head[m], nh[m], coefs, kmax, gammas,
            h, nsteps, k0, save_every, k_final, out[:, m],
            rtol, atol, stall_rtol, divf, max_iter, mem, reg, rec[m],
        )  # fmt: skip
