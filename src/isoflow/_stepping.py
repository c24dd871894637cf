r"""Advancing a run by chunks of steps: the seam between the time loop and the step code.

The time loop (:mod:`isoflow._solve`) drives a :class:`Runner`: it asks it to take ``n``
steps, saving every ``save_every``-th state into rows it hands over, and reads back the
current state, the method state (for checkpoints) and a per-member record of failures. Two
runners exist:

* :class:`PythonRunner` (here) calls the method's own :meth:`~isoflow.methods.Method.step`
  on the NumPy arrays: every method, solver and problem;
* the compiled runner of :mod:`isoflow._compiled`, which the time loop asks for first; it
  exists for the combinations that have a compiled driver (a problem with a kernel, the
  fixed-point solver) and runs whole chunks in machine code.

Ensemble members are independent. A member whose step fails (the nonlinear solve does not
converge, the new state is not finite, ``B`` raises) is *frozen* at its last good state and
recorded in :class:`MemberFailures`; the others go on. Saved rows of a frozen member repeat
its last good state.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._errors import NotInSpaceError
from ._failures import B_RAISED, LEFT_SPACE, MemberFailures
from ._save_grid import SaveGrid
from .methods import Method
from .methods._base import StepDataRequest
from .nonlinear import STATUS_CONVERGED, STATUS_NON_FINITE
from .problems import IsospectralProblem

__all__ = [
    "LEFT_SPACE_ATOL",
    "LEFT_SPACE_RTOL",
    "MemberFailures",
    "PythonRunner",
    "Runner",
    "merge_members",
    "stop_members_leaving_the_space",
    "take_members",
]

Array = NDArray[Any]

#: Relative distance of ``B`` from the normalizer at a saved state beyond which its member fails
#: (far above rounding, the tolerance of the check of ``B`` when a run starts).
LEFT_SPACE_RTOL = 1e-8
#: Absolute part of that tolerance.
LEFT_SPACE_ATOL = 1e-12


class Runner:
    """Advances ``M`` ensemble members (flattened) by chunks of steps; see the module docstring.

    Attributes
    ----------
    k : int
        Steps completed since ``t0``. Failed members are frozen while the others go on; once
        every member has failed, the run ends where the last one failed.
    exceptions : dict of int to BaseException
        Per failed member (flattened index), the exception that failed it where there is one:
        what its ``B`` raised (the failure code ``B raised``), or the
        :class:`~isoflow.NotInSpaceError` of a ``B`` that left the normalizer (``left the
        space``; :mod:`isoflow._failures`).
    failures : MemberFailures
    iterations_total, iterations_max : int
        Nonlinear iterations summed over steps and members; the largest for one step.
    residual_max : float
        Largest final residual of an accepted solve.
    b_evaluations : int
        Evaluations of ``B`` summed over members (Newton's Jacobians, RK stages included).
    label : str
        What runs the steps, for messages (``"NumPy"``, ``"compiled (dense BLAS)"``, ...).
    parallel : bool
        Whether its steps run over threads of its own (the time loop then keeps the writer's
        work in the loop's thread).
    checkpoints_at_saves : bool
        Whether a checkpoint of it must fall on a save point (the time loop then ends its
        chunks there).
    threads_beside : int
        Threads the run keeps busy beside the runner's (the time loop's background writer):
        a runner that draws its noise on helper threads leaves their cores to them.
    """

    k: int
    failures: MemberFailures
    label: str = "runner"
    parallel: bool = False
    checkpoints_at_saves: bool = False
    threads_beside: int = 0

    def __init__(self) -> None:
        self.exceptions: dict[int, BaseException] = {}
        self.iterations_total = 0
        self.iterations_max = 0
        self.residual_max = 0.0
        self.b_evaluations = 0

    @property
    def numba_threaded(self) -> bool:
        """Whether its steps run on numba threads: members in parallel (:attr:`parallel`) or
        one system's work cut into pieces (a long spin chain, a large complex matrix). The
        run's thread plan then gives the cores to numba, not to BLAS."""
        return self.parallel

    @property
    def serial_by_default(self) -> bool:
        """Whether its numba threads are one unless the run asks for more (see
        :attr:`isoflow._compiled.layout.Layout.serial_by_default`)."""
        return False

    def advance(self, nsteps: int, grid: SaveGrid, out: Array) -> None:
        """Take ``nsteps`` steps; the state after every save point ``k`` of ``grid``
        (:meth:`SaveGrid.is_save <isoflow._save_grid.SaveGrid.is_save>`) goes into the next
        row of ``out`` (``(R, M, *core)``)."""
        raise NotImplementedError  # pragma: no cover

    def state(self) -> tuple[Array, Any]:
        """The current state ``(*batch, *core)`` and the method state (members flattened:
        per-member arrays ``(M, ...)``, or the member's own shape for one system)."""
        raise NotImplementedError  # pragma: no cover

    def freeze(self, m: int, step: int, y: Array, status: int, message: str) -> None:
        """Fail member ``m`` from outside the steps (a check of its saved states): it is
        frozen at ``y`` (``core`` shape), its state after ``step`` steps."""
        raise NotImplementedError  # pragma: no cover

    def B_at(self, rows: Array) -> Array:
        """``B`` as the steps evaluate it (the Python ``B``, or the compiled kernel), at the
        states ``rows`` ``(R, m, *core)`` of ``m`` members (uncounted)."""
        raise NotImplementedError  # pragma: no cover


def take_members(state: Any, idx: NDArray[np.intp], members: int) -> Any:
    """The method state of the members ``idx`` (arrays whose first axis has ``members``
    entries are indexed; floats and other entries are shared)."""
    if state is None:
        return None
    return tuple(
        x[idx] if isinstance(x, np.ndarray) and x.ndim and x.shape[0] == members else x
        for x in state
    )


def merge_members(full: Any, idx: NDArray[np.intp], sub: Any, members: int) -> Any:
    """``full`` with the entries of the members ``idx`` replaced by ``sub`` (see
    :func:`take_members`); arrays missing from ``full`` start at zero for the others."""
    if sub is None:
        return None
    out = []
    for q, x in enumerate(sub):
        if isinstance(x, np.ndarray) and x.ndim and x.shape[0] == len(idx):
            old = full[q] if full is not None and q < len(full) else None
            if not (isinstance(old, np.ndarray) and old.shape[1:] == x.shape[1:]):
                old = np.zeros((members, *x.shape[1:]), dtype=x.dtype)
            else:
                old = old.copy()
            old[idx] = x
            out.append(old)
        else:
            out.append(x)
    return tuple(out)


class _CountingB:
    """``B`` that counts the members it is evaluated on."""

    def __init__(self, B: Any, core_ndim: int) -> None:
        self.B = B
        self.core_ndim = core_ndim
        self.count = 0

    def __call__(self, W: Array) -> Array:
        self.count += int(np.prod(np.shape(W)[: np.ndim(W) - self.core_ndim], dtype=np.int64))
        return self.B(W)


class PythonRunner(Runner):
    """Steps with the method's own :meth:`~isoflow.methods.Method.step` (NumPy).

    Parameters
    ----------
    problem, method, h :
        The run.
    y : ndarray, shape (*batch, *core)
        The state after ``k`` steps (in the space).
    method_state : object
        The method state after ``k`` steps (``None`` at the start).
    k : int
        Steps already taken.
    failures : MemberFailures or None
        The record to continue (a resumed run), else all members alive.
    t0 : float
        The run's start time (step ``k`` goes from ``t0 + (k - 1) h``): what the step data of
        a method that reads some depends on.
    """

    label = "NumPy"

    def __init__(
        self, problem: IsospectralProblem, method: Method, y: Array, h: float, *,
        method_state: Any = None, k: int = 0, failures: MemberFailures | None = None,
        t0: float = 0.0,
    ) -> None:  # fmt: skip
        super().__init__()
        alg = problem.algebra
        self.t0 = float(t0)
        self.core = alg.shape
        self.batch = alg.batch_shape(y)
        self.single = self.batch == ()
        self.M = int(np.prod(self.batch, dtype=np.int64))
        self.counter = _CountingB(problem.B, alg.core_ndim)
        self.problem = dataclasses.replace(problem, B=self.counter)
        self.uncounted = problem
        self.method = method
        self.h = float(h)
        self.Y = np.array(y, dtype=alg.dtype, copy=True).reshape(self.M, *self.core)
        self.mstate = method_state
        self.k = int(k)
        self.failures = failures if failures is not None else MemberFailures.none(self.M)

    @property
    def b_evaluations(self) -> int:  # type: ignore[override]
        return self.counter.count

    @b_evaluations.setter
    def b_evaluations(self, value: int) -> None:
        pass  # counted by the wrapped B

    def state(self) -> tuple[Array, Any]:
        return self.Y.reshape(*self.batch, *self.core), self.mstate

    def B_at(self, rows: Array) -> Array:
        B = self.uncounted.evaluate_B
        if self.single:  # B as the steps call it: one state, or the members stacked
            return np.stack([B(r[0])[None] for r in rows])
        return np.stack([B(r) for r in rows])

    def freeze(self, m: int, step: int, y: Array, status: int, message: str) -> None:
        self.Y[m] = y
        self.failures.record(m, step, status, 0, float("nan"))
        self.failures.messages[m] = message

    def _data(self, k: int, members: NDArray[np.intp]) -> dict[str, Array]:
        """``{"data": rows}``: the step data of step ``k + 1`` (from ``t0 + k h``) of the
        ``members`` for a method that reads some (:attr:`Method.reads_step_data`), else ``{}``."""
        if not self.method.reads_step_data:
            return {}
        request = StepDataRequest(int(k), 1, np.asarray(members, dtype=np.int64), self.h, self.t0)
        rows = np.asarray(self.method.step_data(self.uncounted, request))[0]
        return {"data": rows[0] if self.single else rows}

    def _step_all(
        self, y: Array, st: Any, k: int, members: NDArray[np.intp]
    ) -> tuple[Any, BaseException | None]:
        try:
            data = self._data(k, members)
            return self.method.step(self.problem, y, self.h, st, **data), None
        except Exception as exc:  # B (or the user's code under it) raised
            return None, exc

    def advance(self, nsteps: int, grid: SaveGrid, out: Array) -> None:
        if self.single:
            self._advance_single(nsteps, grid, out)
            return
        row = 0
        fails = self.failures
        for _ in range(nsteps):
            k = self.k + 1
            self._one_step(k - 1, np.flatnonzero(fails.alive))
            if not fails.alive.any():
                return  # every member frozen: the run ends after k - 1 steps
            self.k = k
            if grid.is_save(k):
                out[row] = self.Y
                row += 1

    def _advance_single(self, nsteps: int, grid: SaveGrid, out: Array) -> None:
        """:meth:`advance` for one system (no member bookkeeping on the way)."""
        if not self.failures.alive[0]:
            return
        method, problem, h = self.method, self.problem, self.h
        y, st = self.Y[0], self.mstate
        row = 0
        for _ in range(nsteps):
            k = self.k
            try:
                res = method.step(problem, y, h, st, **self._data(k, np.zeros(1, np.intp)))
            except Exception as exc:  # B (or the user's code under it) raised
                self.failures.record(0, k, B_RAISED, 0, float("nan"))
                self.failures.messages[0] = f"{type(exc).__name__}: {exc}"
                self.exceptions[0] = exc
                break
            its = 0 if res.iterations is None else int(res.iterations)
            code = STATUS_CONVERGED if res.status is None else int(res.status)
            if code == STATUS_CONVERGED and not np.isfinite(res.y).all():
                code = STATUS_NON_FINITE
            self.iterations_total += its
            self.iterations_max = max(self.iterations_max, its)
            if code != STATUS_CONVERGED:
                resid = float("nan") if res.residual is None else float(res.residual)
                self.failures.record(0, k, code, its, resid)
                break
            if res.residual is not None:
                self.residual_max = max(self.residual_max, float(res.residual))
            y, st = res.y, res.state
            self.k = k + 1
            if grid.is_save(self.k):
                out[row, 0] = y
                row += 1
        self.Y[0] = y
        self.mstate = st

    def _isolate(self, k: int, alive: NDArray[np.intp], exc: BaseException) -> None:
        """Step ``k`` of the members ``alive`` raised ``exc``: find the members whose step
        raises on its own (each stepped alone, the results dropped), fail them with
        :data:`B_RAISED`, and step the others together as if those were not there. If
        no member raises alone, the step of them all raised: every one of them fails."""
        raised: dict[int, BaseException] = {}
        if alive.size > 1:
            for m in alive:
                one = np.array([m])
                _, e = self._step_all(self.Y[one], take_members(self.mstate, one, self.M), k, one)
                if e is not None:
                    raised[int(m)] = e
        if not raised:
            raised = {int(m): exc for m in alive}
        for m, e in raised.items():
            self.failures.record(m, k, B_RAISED, 0, float("nan"))
            self.failures.messages[m] = f"{type(e).__name__}: {e}"
            self.exceptions[m] = e
        rest = np.setdiff1d(alive, np.fromiter(raised, dtype=np.int64))
        if rest.size:
            self._one_step(k, rest)

    def _one_step(self, k: int, alive: NDArray[np.intp]) -> None:
        """Step ``k`` (from ``t0 + k h``) of the ensemble members ``alive`` (one system steps
        in :meth:`_advance_single`)."""
        everyone = alive.size == self.M
        if everyone:
            y, st = self.Y, self.mstate
        else:
            y, st = self.Y[alive], take_members(self.mstate, alive, self.M)
        res, exc = self._step_all(y, st, k, alive)
        if exc is not None:
            self._isolate(k, alive, exc)
            return
        n = alive.size
        if res.status is None:
            status = np.full(n, STATUS_CONVERGED, dtype=np.int64)
            iters = np.zeros(n, dtype=np.int64)
            resid = np.zeros(n)
        else:
            status = np.asarray(res.status, dtype=np.int64).reshape(n).copy()
            iters = np.asarray(res.iterations, dtype=np.int64).reshape(n)
            resid = np.asarray(res.residual, dtype=float).reshape(n)
        ynew = np.asarray(res.y).reshape(n, *self.core)
        finite = np.all(np.isfinite(ynew.reshape(n, -1)), axis=1)
        status[(status == STATUS_CONVERGED) & ~finite] = STATUS_NON_FINITE
        ok = status == STATUS_CONVERGED
        self.iterations_total += int(iters.sum())
        self.iterations_max = max(self.iterations_max, int(iters.max()) if n else 0)
        if ok.any():
            self.residual_max = max(self.residual_max, float(resid[ok].max()))
        for j in np.flatnonzero(~ok):
            self.failures.record(int(alive[j]), k, int(status[j]), int(iters[j]), float(resid[j]))
        if ok.all():
            if everyone:
                self.Y = ynew.copy() if ynew.base is not None else ynew
                self.mstate = res.state
            else:
                self.Y[alive] = ynew
                self.mstate = merge_members(self.mstate, alive, res.state, self.M)
            return
        good = alive[ok]
        self.Y[good] = ynew[ok]
        sub = take_members(res.state, np.flatnonzero(ok), n)
        self.mstate = merge_members(self.mstate, good, sub, self.M)


def _b_off_the_normalizer(
    problem: IsospectralProblem, runner: Runner, rows: Array
) -> tuple[Array, Array, Array]:
    """Per saved row and alive member (``(R, M)``): whether ``B`` at the state (as the steps
    evaluate it) is farther from the normalizer than ``LEFT_SPACE_ATOL + LEFT_SPACE_RTOL *
    norm``, the distance and the tolerance. A ``B`` that raises or is not finite here is
    left to the steps, which fail the member for it."""
    R, M = rows.shape[:2]
    off = np.zeros((R, M), dtype=bool)
    dist, tol = np.zeros((R, M)), np.zeros((R, M))
    alive = np.flatnonzero(runner.failures.alive)
    N = problem.algebra.normalizer
    members = slice(None) if alive.size == M else alive  # no copy while all are alive
    try:
        with np.errstate(all="ignore"):
            B = np.asarray(runner.B_at(rows[:, members]), dtype=N.dtype)
    except Exception:  # the steps report a B that raises (B_RAISED)
        return off, dist, tol
    dist[:, members] = N.distance(B)
    tol[:, members] = LEFT_SPACE_ATOL + LEFT_SPACE_RTOL * N.norm(B)
    off[:, members] = dist[:, members] > tol[:, members]
    return off, dist, tol


def stop_members_leaving_the_space(
    problem: IsospectralProblem, runner: Runner, rows: Array, ks: Array,
    last_good: tuple[int, Array],
) -> tuple[int, Array]:  # fmt: skip
    """Fail the members of a chunk whose ``B`` at a saved state (``rows``, ``(R, M, *core)``,
    at steps ``ks``) is not in the normalizer: the flow from there leaves the space.

    (Every method ends its steps in the space, by a projection: such a ``B`` shows in the
    lost invariants, not in the states, so ``B`` is what is checked.) Such a member is
    frozen with :data:`LEFT_SPACE` at its last saved state where ``B`` passed: the
    previous row, or ``last_good`` (``(step, states)`` from before the chunk); its rows from
    the first bad one on repeat that state. If no member is left, the run ends there.
    Returns the new ``last_good``: the chunk's last row (after the freezes).
    """
    alg = problem.algebra
    off, dist, tol = _b_off_the_normalizer(problem, runner, rows)
    for m in np.flatnonzero(off.any(axis=0)):
        j = int(np.argmax(off[:, m]))
        step, good = (int(ks[j - 1]), rows[j - 1, m]) if j else (last_good[0], last_good[1][m])
        good = np.array(good, copy=True)
        rows[j:, m] = good
        message = (
            f"B(W) after step {int(ks[j])} is at distance {dist[j, m]:.1e} from the "
            f"normalizer {alg.normalizer.name} (beyond {tol[j, m]:.1e}), so the flow "
            f"W' = [B(W), W] leaves {alg.name}"
        )
        runner.freeze(int(m), step, good, LEFT_SPACE, message)
        runner.exceptions[int(m)] = NotInSpaceError(
            message, distance=float(dist[j, m]), tolerance=float(tol[j, m])
        )
    if off.any() and not runner.failures.alive.any():
        runner.k = int(runner.failures.step.max())  # every member failed: the run ends there
    return int(ks[-1]), np.array(rows[-1], copy=True)
