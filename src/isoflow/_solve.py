r"""The fixed-step time loop: :func:`solve`, :func:`step`, and restarting a run.

One loop serves every run. It validates the input, picks a runner (the compiled one of
:mod:`isoflow._compiled` when the run has a compiled path, else the method's own NumPy steps,
:class:`~isoflow._stepping.PythonRunner`), and advances in chunks: each chunk takes as many
steps as fit in about half a second (or fill the writer's row buffer), writes the saved states
of the chunk and their diagnostics to the writer, and checkpoints the run on time
(``flush_seconds``) as well as when the row buffer is full. So a run is interruptible within
about a second (Ctrl-C acts between chunks: the state, the rows and the checkpoint stay
consistent) and a kill loses at most the work since the last checkpoint.

Without a writer, :func:`solve` streams into an in-memory one; the chunks (and hence the
per-step arithmetic) are the same either way, so a resumed file run reproduces an
uninterrupted run bit for bit.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._errors import (
    ConvergenceError,
    IsoflowError,
    NonFiniteError,
    ParameterError,
    ResultWriteError,
    ShapeError,
    StepSizeError,
    TimeSpanError,
)
from ._stepping import FAIL_B_RAISED, MemberFailures, PythonRunner, Runner
from .diagnostics import Diagnostics, DiagnosticsAccumulator
from .methods import Method, StepResult
from .nonlinear import STATUS_CONVERGED, STATUS_NON_FINITE
from .problems import IsospectralProblem

__all__ = [
    "RUN_FAILED",
    "RUN_FINISHED",
    "RUN_INTERRUPTED",
    "RunState",
    "Solution",
    "SolveStats",
    "StreamWriter",
    "continue_run",
    "solve",
    "step",
    "time_grid",
]

Array = NDArray[Any]

#: Status of a run (:attr:`Solution.status`): all requested steps taken.
RUN_FINISHED = 0
#: A step failed (for a single system; for an ensemble, at least one member).
RUN_FAILED = 1
#: Stopped by an exception from outside the numerics (Ctrl-C, a failed write).
RUN_INTERRUPTED = 2

#: Target wall time of one chunk: Ctrl-C acts and checkpoints happen at least this often.
CHUNK_SECONDS = 0.5
#: Largest row buffer of one chunk, in bytes (larger states save fewer rows per chunk).
CHUNK_BYTES = 64 * 2**20
#: Target wall time of a chunk when the saved rows are processed by the writer thread (a
#: pipeline: the diagnostics of one chunk overlap the stepping of the next). Long against
#: the interpreter's thread switch interval (5 ms), short against :data:`CHUNK_SECONDS`.
PIPELINE_SECONDS = 0.05
#: Fewest saved rows for which the writer thread is worth starting.
PIPELINE_MIN_ROWS = 256


@dataclass(frozen=True)
class SolveStats:
    """Counters of a run.

    Attributes
    ----------
    n_steps : int
        Steps completed (see :attr:`Solution.failed_step` for members that stopped earlier).
    n_iterations : int
        Nonlinear iterations summed over steps and members (0 for explicit methods).
    n_B_evaluations : int
        Evaluations of ``B`` summed over members: one per fixed-point iteration, more for
        Newton's Jacobians, four per step for RK4 (validation calls not counted).
    iterations_mean, iterations_max : float, int
        Nonlinear iterations per step and member; the largest for one step.
    residual_max : float
        Largest final nonlinear residual of an accepted step.
    wall_time : float
        Seconds spent in the loop (compilation included).
    compile_time : float
        Seconds of the first compiled chunk when it compiled (or loaded) the loops, else 0.
    runner : str
        What ran the steps: ``"NumPy"`` or ``"compiled, <layout>"``.
    """

    n_steps: int = 0
    n_iterations: int = 0
    n_B_evaluations: int = 0
    iterations_mean: float = 0.0
    iterations_max: int = 0
    residual_max: float = 0.0
    wall_time: float = 0.0
    compile_time: float = 0.0
    runner: str = ""

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python dictionary (JSON-ready)."""
        return asdict(self)


@dataclass(frozen=True)
class Solution:
    """Result of :func:`solve`.

    Attributes
    ----------
    ts : ndarray, shape (n_save,)
        Saved times ``t0 + k dt``.
    ys : ndarray, shape (n_save, *batch, *shape)
        Saved states, time first. A member that failed keeps its last good state.
    stats : SolveStats
    success : bool
        Whether every member took all requested steps.
    status : int
        :data:`RUN_FINISHED` (0), :data:`RUN_FAILED` (1, only with ``throw=False``) or
        :data:`RUN_INTERRUPTED` (2).
    message : str
        What happened, in words (naming the members that failed).
    diagnostics : Diagnostics or None
        Invariant drifts on the saved states (``None`` when ``diagnostics=False``).
    t0, dt : float
        Start time and step.
    n_steps : int
        Steps requested.
    failed_step : ndarray of int, shape batch
        Per member: the index of the step that failed (``0`` is the step from ``t0``; the
        member's last good state is at ``t0 + failed_step * dt``), ``-1`` for members that
        took every step.
    failure_reasons : dict
        Member index (a tuple, ``()`` for one system) -> why it failed.
    """

    ts: Array
    ys: Array
    stats: SolveStats
    success: bool
    status: int
    message: str
    diagnostics: Diagnostics | None
    t0: float
    dt: float
    n_steps: int
    failed_step: Array = dataclasses.field(default_factory=lambda: np.asarray(-1))
    failure_reasons: dict[tuple[int, ...], str] = dataclasses.field(default_factory=dict)

    @property
    def y_final(self) -> Array:
        """The last saved state (the final state when ``success``)."""
        return self.ys[-1]


@runtime_checkable
class StreamWriter(Protocol):
    """What :func:`solve` needs from a streaming writer (e.g. :class:`isoflow.io.HDF5Writer`).

    The loop calls :meth:`open` once, then for every chunk :meth:`append` with its saved
    states, and :meth:`checkpoint` (on time, every ``flush_seconds``, and when ``chunk_rows``
    rows were appended since the last one) with the step index, the state, the method state and
    the per-member failure record after the last appended row; the writer makes the rows and
    the checkpoint durable together, so what it holds is always a consistent set.
    :meth:`close` ends the run (also after a failure or an interrupt). An ``OSError`` from the
    writer stops the run with :class:`~isoflow.ResultWriteError`.
    """

    chunk_rows: int
    flush_seconds: float

    def open(self, meta: dict[str, Any]) -> None:
        """Start a run described by ``meta`` (times, method, algebra; JSON-ready)."""

    def append(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        """Saved states ``ys`` at ``ts`` (time first) and their diagnostic ``series``."""

    def checkpoint(
        self, step: int, y: Array, method_state: Any, failures: MemberFailures | None
    ) -> None:
        """The state after ``step`` steps, the method state and the failure record."""

    def close(self, info: dict[str, Any]) -> None:
        """End the run; ``info`` holds the status, message and :class:`SolveStats`."""


@dataclass(frozen=True)
class RunState:
    """Where a run stands: what a checkpoint holds and a restart needs.

    Attributes
    ----------
    step : int
        Steps completed since ``t0``.
    y : ndarray
        The state after them, ``(*batch, *shape)``.
    method_state : object
        The method state after them (flattened ensemble members).
    failures : MemberFailures or None
        Members that failed earlier (frozen), ``None`` if none.
    """

    step: int
    y: Array
    method_state: Any = None
    failures: MemberFailures | None = None


# ---- validation -------------------------------------------------------------------------------


def time_grid(
    t0: float, t1: float | None, dt: float | None, n_steps: int | None
) -> tuple[float, int]:
    """Resolve ``(dt, n_steps)`` from the user's choice of two of ``t1``, ``dt``, ``n_steps``.

    The one statement of the rule (the configuration readers call it too).

    Raises
    ------
    TimeSpanError, StepSizeError, ParameterError
        Non-finite or reversed times, a non-positive step, not exactly two of the three, or a
        ``t1`` that is not a whole number of steps (the message says which ``dt`` fits).
    """
    t0 = _real(t0, "t0", TimeSpanError)
    if dt is not None:
        if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
            raise StepSizeError(f"dt must be a real number, got {dt!r}")
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise StepSizeError(f"dt must be positive and finite, got {dt}")
    if n_steps is not None:
        if (
            isinstance(n_steps, bool)
            or not isinstance(n_steps, (int, np.integer, float, np.floating))
            or not math.isfinite(n_steps)
            or int(n_steps) != n_steps
            or n_steps < 0
        ):
            raise StepSizeError(f"n_steps must be a non-negative integer, got {n_steps!r}")
        n_steps = int(n_steps)
    if t1 is not None:
        t1 = _real(t1, "t1", TimeSpanError)
        if t1 < t0:
            raise TimeSpanError(
                f"t1 = {t1} is before t0 = {t0}; steps go forward in time (use a problem with "
                "-B, or step() with a negative h, to integrate backwards)"
            )
    given = sum(x is not None for x in (t1, dt, n_steps))
    if given != 2:
        raise ParameterError(
            f"give exactly two of t1, dt and n_steps (got t1={t1}, dt={dt}, n_steps={n_steps})"
        )
    if t1 is None:
        assert dt is not None and n_steps is not None
        return dt, n_steps
    span = t1 - t0
    if dt is None:
        assert n_steps is not None
        if n_steps == 0:
            if span != 0:
                raise StepSizeError("n_steps = 0 needs t1 == t0")
            return 1.0, 0
        return span / n_steps, n_steps
    n = round(span / dt)
    if abs(n * dt - span) > 1e-9 * max(abs(span), abs(dt)):
        raise StepSizeError(
            f"t1 - t0 = {span!r} is not a whole number of steps dt = {dt!r} "
            f"({span / dt:.6g} steps); choose dt = {span / max(n, 1)!r} or pass n_steps"
        )
    return dt, int(n)


def _real(x: Any, what: str, error: type[Exception]) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise error(f"{what} must be a real number, got {x!r}")
    x = float(x)
    if not math.isfinite(x):
        raise error(f"{what} must be finite, got {x}")
    return x


def _check_objects(problem: Any, method: Any, writer: Any = None) -> None:
    """Clear errors for the wrong kind of object where a problem, method or writer belongs."""
    if not isinstance(problem, IsospectralProblem):
        raise TypeError(
            "problem must be an iso.IsospectralProblem (e.g. from iso.models.rigid_body()), "
            f"got {type(problem).__name__}"
        )
    if isinstance(method, type) and issubclass(method, Method):
        raise TypeError(
            f"method must be a method instance: write iso.{method.__name__}(), not "
            f"iso.{method.__name__}"
        )
    if not isinstance(method, Method):
        raise TypeError(f"method must be an isoflow method (e.g. iso.IsoMP()), got {method!r}")
    if writer is not None and not isinstance(writer, StreamWriter):
        hint = (
            "; to write a file, pass iso.io.HDF5Writer(path)"
            if isinstance(writer, (str, bytes)) or hasattr(writer, "__fspath__")
            else ""
        )
        raise TypeError(
            f"writer must be a stream writer (open/append/checkpoint/close), got "
            f"{type(writer).__name__}{hint}"
        )


def _check_state(problem: IsospectralProblem, y: ArrayLike, what: str) -> Array:
    """``y`` validated and projected onto the space, ``B(y)`` checked; no empty ensembles."""
    W = problem.algebra.validate(y, what)
    if W.size == 0:
        raise ShapeError(f"{what} is an empty ensemble (shape {W.shape}): nothing to integrate")
    problem.check_B(W)
    return W


# ---- one step ---------------------------------------------------------------------------------


def _failure_exception(method: Method, res: StepResult, k: int, t: float) -> Exception:
    """The exception describing a rejected step ``k`` that started at time ``t``."""
    if not res.success:
        assert res.residual is not None and res.iterations is not None
        status = np.asarray(res.status)
        bad = int(np.count_nonzero(status != STATUS_CONVERGED))
        reason = res.failure_reason()
        return ConvergenceError(
            f"{method.name}: the nonlinear solve of step {k} (t = {t:.6g}) did not converge "
            f"({reason}) for {bad} of {status.size} ensemble member(s): residual "
            f"{float(np.max(res.residual)):.3e} after {int(np.max(res.iterations))} "
            "iterations. Reduce dt (h * ||B(W)|| should stay well below 2) or change the "
            "solver.",
            step=k,
            time=t,
            residual=float(np.max(res.residual)),
            iterations=int(np.max(res.iterations)),
            reason=reason,
        )
    return NonFiniteError(f"{method.name}: the state became non-finite at step {k} (t = {t:.6g})")


def step(
    problem: IsospectralProblem,
    method: Method,
    y: ArrayLike,
    h: float,
    *,
    validate: bool = True,
    return_info: bool = False,
) -> Any:
    """Take one step of size ``h`` (any sign, nonzero) from ``y``.

    Parameters
    ----------
    problem : IsospectralProblem
    method : Method
        e.g. ``iso.IsoMP()``.
    y : array_like, shape (*batch, *shape)
        Current state in ``V``.
    h : float
        Step size; negative steps integrate backwards (IsoMP is symmetric).
    validate : bool
        Check ``y`` and ``B(y)`` first (default).
    return_info : bool
        Also return the :class:`~isoflow.methods.StepResult` (stage ``X``, iterations, ...).

    Returns
    -------
    y_next : ndarray, or ``(y_next, StepResult)`` when ``return_info``.

    Raises
    ------
    ConvergenceError
        If the nonlinear solve fails for any member.
    NonFiniteError
        If the new state is not finite.
    """
    _check_objects(problem, method)
    h = _real(h, "h", StepSizeError)
    if h == 0:
        raise StepSizeError("h must be finite and nonzero, got 0.0")
    W = _check_state(problem, y, "state") if validate else np.asarray(y)
    res = method.step(problem, W, h, method.init(problem, W, h))
    if not res.success or not np.all(np.isfinite(res.y)):
        raise _failure_exception(method, res, 0, 0.0)
    return (res.y, res) if return_info else res.y


# ---- solve ------------------------------------------------------------------------------------


def solve(
    problem: IsospectralProblem,
    method: Method,
    y0: ArrayLike,
    *,
    t0: float = 0.0,
    t1: float | None = None,
    dt: float | None = None,
    n_steps: int | None = None,
    save_every: int = 1,
    diagnostics: bool = True,
    progress: bool | None = None,
    throw: bool = True,
    writer: StreamWriter | None = None,
) -> Solution:
    r"""Integrate ``problem`` from ``y0`` with a fixed step (no adaptivity, by design).

    Parameters
    ----------
    problem : IsospectralProblem
    method : Method
        e.g. ``iso.IsoMP()``, ``iso.IsoMP(solver=iso.Newton())``.
    y0 : array_like, shape (*batch, *shape)
        Initial state; leading axes make an ensemble, solved in one call (members are
        independent: a member whose step fails is frozen at its last good state and reported,
        the others go on). It is checked to lie in ``V`` (relative distance ``1e-10``) and then
        projected onto ``V`` exactly.
    t0 : float
        Start time.
    t1, dt, n_steps :
        Exactly two of them. ``t1`` with ``dt`` must be a whole number of steps (else
        :class:`StepSizeError` says which ``dt`` would fit); the times are ``t0 + k dt``.
    save_every : int
        Save every this many steps; the initial and the final state are always saved.
    diagnostics : bool
        Compute :class:`~isoflow.diagnostics.Diagnostics` on the saved states.
    progress : bool or None
        Progress bar (tqdm). ``None``: only when stderr is a terminal, after one second.
    throw : bool
        If a step fails, raise :class:`ConvergenceError` (default; after writing what was
        computed) or return the solution with ``success=False``.
    writer : StreamWriter or None
        Stream the saved states, their diagnostics and checkpoints to ``writer`` (e.g.
        ``iso.io.HDF5Writer("run.h5")``) instead of holding them: memory stays bounded in the
        number of steps. The returned :class:`Solution` then holds only two saved states,
        the initial and the final one, and its ``diagnostics`` has the drifts over *all* saved
        states with the time series of those two states only.

    Returns
    -------
    Solution

    Raises
    ------
    ConvergenceError
        A step failed and ``throw=True``.
    ResultWriteError
        The writer failed (disk full, ...): the file holds the run up to its last checkpoint.
    """
    _check_objects(problem, method, writer)
    _check_save_every(save_every)
    dt_, n = time_grid(t0, t1, dt, n_steps)
    W = _check_state(problem, y0, "y0")
    return _run(
        problem, method, RunState(0, W, method.init(problem, W, dt_)),
        t0=float(t0), dt=dt_, n=n, save_every=int(save_every), diagnostics=diagnostics,
        progress=progress, throw=throw, writer=writer, fresh=True,
    )  # fmt: skip


def _check_save_every(save_every: Any) -> None:
    """``save_every`` is a positive integer (``ParameterError`` otherwise)."""
    ok = isinstance(save_every, (int, np.integer)) and not isinstance(save_every, bool)
    if not ok or save_every < 1:
        raise ParameterError(f"save_every must be a positive integer, got {save_every!r}")


def check_restart(
    problem: IsospectralProblem,
    method: Method,
    state: RunState,
    *,
    t0: float,
    dt: float,
    n_steps: int,
    save_every: int,
    writer: StreamWriter | None = None,
) -> tuple[float, int, RunState]:
    """Validate a restart from ``state`` as :func:`solve` validates a start.

    Returns ``(dt, n_steps, state)`` with the state checked, and kept as stored: a checkpoint
    is the run's own state, and projecting it again is not the identity in floating point for
    every space (the trace removal of ``su(n)`` moves the last bits), which would break the
    bit-for-bit continuation.

    Raises
    ------
    IsoflowError
        The state (outside the space: :class:`NotInSpaceError`; not finite; another shape),
        the failure record or the time grid do not describe a valid run.
    """
    _check_objects(problem, method, writer)
    dt_, n = time_grid(t0, None, dt, n_steps)
    _check_save_every(save_every)
    if not 0 <= state.step <= n:
        raise ParameterError(f"checkpoint step {state.step} outside the run's 0..{n} steps")
    W = _check_state(problem, state.y, "checkpoint state")
    M = int(np.prod(problem.algebra.batch_shape(W), dtype=np.int64))
    if state.failures is not None and state.failures.step.shape != (M,):
        raise ShapeError(
            f"checkpoint failure record for {state.failures.step.shape} members, state has {M}"
        )
    return dt_, n, dataclasses.replace(state, y=np.asarray(state.y, dtype=W.dtype))


def continue_run(
    problem: IsospectralProblem,
    method: Method,
    state: RunState,
    *,
    t0: float,
    dt: float,
    n_steps: int,
    save_every: int,
    writer: StreamWriter,
    accumulator: DiagnosticsAccumulator,
    progress: bool | None = None,
    throw: bool = True,
) -> Solution:
    """Continue a run from ``state`` (a checkpoint), appending to ``writer``.

    The restart goes through the same validation as :func:`solve` (:func:`check_restart`):
    the time grid, the checkpoint's state (in the space, finite, the run's shape) and ``B`` at
    it. ``accumulator`` has absorbed the diagnostics of the rows already written.

    Raises
    ------
    IsoflowError
        The state or the time grid do not describe a valid run.
    """
    dt_, n, st = check_restart(
        problem, method, state, t0=t0, dt=dt, n_steps=n_steps, save_every=save_every,
        writer=writer,
    )  # fmt: skip
    return _run(
        problem, method, st, t0=float(t0), dt=dt_, n=n, save_every=int(save_every),
        diagnostics=True, progress=progress, throw=throw, writer=writer, fresh=False,
        accumulator=accumulator,
    )  # fmt: skip


class _MemoryWriter:
    """The in-memory "stream" of :func:`solve` without a writer: keeps every saved state.

    The rows are preallocated (the loop knows how many states it saves) and the compiled
    runner writes its saved states straight into them (:meth:`rows`), so memory holds the saved
    states once, not also in chunk buffers or a final concatenation.
    """

    chunk_rows = 2**62
    flush_seconds = math.inf

    def __init__(self, total: int, shape: tuple[int, ...], dtype: Any) -> None:
        self._ts = np.empty(total)
        self._ys = np.empty((total, *shape), dtype=dtype)
        self._n = 0

    def rows(self, count: int) -> Array:
        """A view of the next ``count`` rows (``count`` at most the rows left)."""
        return self._ys[self._n : self._n + count]

    def open(self, meta: dict[str, Any]) -> None:
        """Nothing to prepare."""

    def append(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        m = len(ts)
        dst = self._ys[self._n : self._n + m]
        if not np.shares_memory(dst, ys):  # rows written in place need no copy
            dst[...] = ys
        self._ts[self._n : self._n + m] = ts
        self._n += m

    def checkpoint(self, step: int, y: Array, method_state: Any, failures: Any) -> None:
        """In memory there is nothing to make durable."""

    def close(self, info: dict[str, Any]) -> None:
        """Nothing to release."""

    def arrays(self) -> tuple[Array, Array]:
        """All saved times and states, time first."""
        return self._ts[: self._n], self._ys[: self._n]


@contextmanager
def _deferred_sigint() -> Iterator[None]:
    """Hold back Ctrl-C (SIGINT) inside the block and deliver it after (main thread only).

    A chunk's bookkeeping (rows, checkpoint, counters) is then never cut in half; since a
    chunk lasts about :data:`CHUNK_SECONDS`, an interrupt still acts within about a second.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        received.append(signum)

    try:
        old = signal.signal(signal.SIGINT, hold)
    except (ValueError, OSError):  # not the main interpreter thread, or no signals here
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old if old is not None else signal.default_int_handler)
    if received:
        raise KeyboardInterrupt


def _save_steps(k0: int, k1: int, save_every: int, k_final: int) -> int:
    """Number of save points ``k`` in ``(k0, k1]`` (multiples of ``save_every`` and
    ``k_final``)."""
    if k1 <= k0:
        return 0
    c = k1 // save_every - k0 // save_every
    if k0 < k_final <= k1 and k_final % save_every:
        c += 1
    return c


def _end_at_save(k0: int, nsteps: int, save_every: int, k_final: int) -> int:
    """``nsteps`` shortened (or lengthened) so that the chunk ends at a save point."""
    end = k0 + nsteps
    if end == k_final or end % save_every == 0:
        return nsteps
    last = (end // save_every) * save_every
    if last > k0:
        return last - k0
    return min((k0 // save_every + 1) * save_every, k_final) - k0


def _steps_for_rows(k0: int, rows: int, save_every: int, k_final: int) -> int:
    """Steps from ``k0`` until ``rows`` save points have passed (capped at ``k_final``)."""
    nxt = (k0 // save_every + rows) * save_every
    return max(min(nxt, k_final) - k0, 1)


def _runner_for(problem: IsospectralProblem, method: Method, state: RunState, dt: float) -> Runner:
    failures = state.failures
    if problem.kernel is not None:
        from ._compiled import compiled_runner

        r = compiled_runner(
            problem, method, state.y, dt, method_state=state.method_state, k=state.step,
            failures=failures,
        )  # fmt: skip
        if r is not None:
            return r
    return PythonRunner(
        problem, method, state.y, dt, method_state=state.method_state, k=state.step,
        failures=failures,
    )  # fmt: skip


def _failure_message(method: Method, fails: MemberFailures, batch: tuple[int, ...],
                     t0: float, dt: float) -> str:  # fmt: skip
    idx = fails.failed
    if batch == ():
        m = 0
        k = int(fails.step[m])
        t = t0 + k * dt
        code = int(fails.status[m])
        if code == FAIL_B_RAISED:
            return f"{method.name}: at step {k} (t = {t:.6g}) {fails.reason(m)}"
        if code == STATUS_NON_FINITE and fails.iterations[m] <= 1:
            return f"{method.name}: the state became non-finite at step {k} (t = {t:.6g})"
        return (
            f"{method.name}: the nonlinear solve of step {k} (t = {t:.6g}) did not converge "
            f"({fails.reason(m)}): residual {fails.residual[m]:.3e} after "
            f"{int(fails.iterations[m])} iterations. Reduce dt (h * ||B(W)|| should stay well "
            "below 2) or change the solver."
        )
    shown = ", ".join(
        f"{tuple(int(i) for i in np.unravel_index(int(m), batch))} at step "
        f"{int(fails.step[m])} ({fails.reason(int(m))})"
        for m in idx[:5]
    )
    more = f" and {idx.size - 5} more" if idx.size > 5 else ""
    total = int(np.prod(batch))
    return (
        f"{method.name}: {idx.size} of {total} ensemble member(s) failed and were frozen at "
        f"their last good state: {shown}{more}. The other members took every step. Reduce dt "
        "(h * ||B(W)|| should stay well below 2) or change the solver."
    )


class _Sink:
    """The writer's side of the loop: diagnostics of the saved rows, appends, checkpoints and
    the final close, in the order they are given.

    With ``background=True`` they run in one worker thread, overlapping with the next chunk
    (the compiled drivers release the GIL; NumPy's eigenvalue routines and h5py's writes do
    too), so saving every step costs little more than stepping on a machine with a core to
    spare. Work is queued at most two items deep; an error in the worker is raised in the
    loop at its next call (an ``OSError`` as :class:`ResultWriteError`).
    """

    def __init__(
        self, writer: StreamWriter, accumulator: DiagnosticsAccumulator, series: bool,
        background: bool,
    ) -> None:  # fmt: skip
        self.writer = writer
        self.accumulator = accumulator
        self.series = series
        self.pool: Any = None
        self.pending: list[Any] = []
        if background:
            from concurrent.futures import ThreadPoolExecutor

            self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="isoflow-writer")

    def _do(self, fn: Any, *args: Any) -> None:
        if self.pool is None:
            fn(*args)
            return
        self.pending.append(self.pool.submit(fn, *args))
        while len(self.pending) > 2:
            self.pending.pop(0).result()

    def _rows(self, ts: Array, ys: Array) -> None:
        series = self.accumulator.update(ts, ys) if self.series else {}
        try:
            self.writer.append(ts, ys, series)
        except IsoflowError:
            raise  # already says what failed (a lock, a failed write): not wrapped again
        except OSError as exc:
            raise ResultWriteError(f"writing the saved states failed: {exc}") from exc

    def _checkpoint(self, k: int, y: Array, st: Any, fails: MemberFailures | None) -> None:
        try:
            self.writer.checkpoint(k, y, st, fails)
        except IsoflowError:
            raise
        except OSError as exc:
            raise ResultWriteError(f"writing a checkpoint failed: {exc}") from exc

    def rows(self, ts: Array, ys: Array) -> None:
        """Saved states (owned by the sink from now on) and their diagnostics."""
        self._do(self._rows, ts, ys)

    def checkpoint(self, k: int, y: Array, st: Any, fails: MemberFailures | None) -> None:
        """A checkpoint (``y``, ``st`` and ``fails`` must not change afterwards: copies)."""
        self._do(self._checkpoint, k, y, st, fails)

    def wait(self) -> None:
        """Everything handed over is done (raises the first error of the worker)."""
        pending, self.pending = self.pending, []
        for f in pending:
            f.result()

    def shutdown(self) -> None:
        """Wait for the worker without raising (after another error)."""
        for f in self.pending:
            try:
                f.result()
            except BaseException:  # the error that stopped the run matters more
                pass
        self.pending = []
        if self.pool is not None:
            self.pool.shutdown(wait=True)
            self.pool = None


def _run(
    problem: IsospectralProblem,
    method: Method,
    state: RunState,
    *,
    t0: float,
    dt: float,
    n: int,
    save_every: int,
    diagnostics: bool,
    progress: bool | None,
    throw: bool,
    writer: StreamWriter | None,
    fresh: bool,
    accumulator: DiagnosticsAccumulator | None = None,
) -> Solution:
    """The loop (see the module docstring). ``fresh`` runs open the writer and write the
    initial state; a restart continues a writer holding the rows up to ``state.step``."""
    from tqdm.auto import tqdm

    alg = problem.algebra
    W = state.y
    batch = alg.batch_shape(W)
    M = int(np.prod(batch, dtype=np.int64))
    memory = writer is None
    if writer is None:
        total = (1 if fresh else 0) + _save_steps(state.step, n, save_every, n)
        out_writer: StreamWriter = _MemoryWriter(total + 1, W.shape, alg.dtype)
    else:
        out_writer = writer
    if accumulator is None:
        accumulator = DiagnosticsAccumulator(problem, keep_series=memory)
        accumulator.set_first_state(W)
    runner = _runner_for(problem, method, state, dt)
    k0 = runner.k
    start = time.perf_counter()
    compute_series = diagnostics or not memory
    sink = _Sink(
        out_writer, accumulator, compute_series,
        background=(
            compute_series
            and not getattr(runner, "parallel", False)
            and _save_steps(runner.k, n, save_every, n) >= PIPELINE_MIN_ROWS
        ),
    )  # fmt: skip

    def emit(ts: Array, ys: Array) -> None:
        sink.rows(ts, ys)

    def checkpoint() -> None:
        y, st = runner.state()
        fails = copy.deepcopy(runner.failures) if runner.failures.failed.size else None
        sink.checkpoint(runner.k, np.array(y, copy=True).reshape(W.shape), st, fails)

    status, message = RUN_FINISHED, f"{n} steps of dt = {dt:g} completed"
    W_first = np.array(W, copy=True)
    if fresh:
        try:
            out_writer.open(
                {
                    "t0": t0,
                    "dt": dt,
                    "n_steps": n,
                    "save_every": save_every,
                    "method": method.name,
                    "algebra": alg.name,
                    "state_shape": list(W.shape),
                    "core_shape": list(alg.shape),
                    "state_dtype": np.dtype(alg.dtype).str,
                    "casimir_scale": np.asarray(alg.casimir_scale(W), dtype=float).tolist(),
                }
            )
        except IsoflowError:
            raise  # e.g. another process writes the file: its own message
        except OSError as exc:
            raise ResultWriteError(f"creating the result file failed: {exc}") from exc
    bar = tqdm(
        total=n, initial=k0, disable=(None if progress is None else not progress),
        delay=1.0, desc=method.name, unit="step", leave=False,
    )  # fmt: skip
    row_bytes = max(W.nbytes, 1)
    max_rows = int(max(1, min(out_writer.chunk_rows, CHUNK_BYTES // row_bytes)))
    chunk_seconds = CHUNK_SECONDS
    if sink.pool is not None:  # shorter chunks keep the writer thread busy alongside
        chunk_seconds = PIPELINE_SECONDS
    last_checkpoint = time.monotonic()
    rows_since = 0
    per_step: float | None = None
    nsteps_next = 1
    calls = 0
    reported = runner.failures.failed.size
    failure_exc: Exception | None = None
    try:
        if fresh:  # inside the try: a failure here closes the writer (no temporary files left)
            emit(np.array([t0]), W[None].copy())
            if not memory:
                checkpoint()
        while runner.k < n and runner.failures.alive.any():
            with _deferred_sigint():
                k_before = runner.k
                nsteps = min(n - k_before, _steps_for_rows(k_before, max_rows, save_every, n))
                if per_step is not None:
                    nsteps = min(nsteps, max(1, int(chunk_seconds / max(per_step, 1e-12))))
                else:
                    nsteps = min(nsteps, nsteps_next)
                if getattr(runner, "checkpoints_at_saves", False):
                    nsteps = _end_at_save(k_before, nsteps, save_every, n)
                rows = _save_steps(k_before, k_before + nsteps, save_every, n)
                if memory and not sink.pending:  # straight into the result (none queued)
                    assert isinstance(out_writer, _MemoryWriter)
                    out = out_writer.rows(rows).reshape(rows, M, *alg.shape)
                else:
                    out = np.empty((rows, M, *alg.shape), dtype=alg.dtype)
                t_call = time.perf_counter()
                runner.advance(nsteps, save_every, n, out)
                elapsed = time.perf_counter() - t_call
                calls += 1
                if calls > 1 and nsteps > 0:  # the first call may compile: do not time it
                    rate = elapsed / nsteps
                    per_step = rate if per_step is None else 0.5 * (per_step + rate)
                elif calls == 1:
                    nsteps_next = 4
                done = _save_steps(k_before, runner.k, save_every, n)
                if done:
                    ks = _save_points(k_before, runner.k, save_every, n)
                    emit(t0 + ks * dt, out[:done].reshape(done, *W.shape))
                    rows_since += done
                bar.update(runner.k - k_before)
                now = time.monotonic()
                newly = runner.failures.failed.size > reported
                finished = runner.k >= n or not runner.failures.alive.any()
                if not memory and (
                    finished
                    or newly
                    or rows_since >= out_writer.chunk_rows
                    or now - last_checkpoint >= out_writer.flush_seconds
                ):
                    checkpoint()
                    last_checkpoint, rows_since = now, 0
                if newly:
                    reported = runner.failures.failed.size
                    message = _failure_message(method, runner.failures, batch, t0, dt)
                    status = RUN_FAILED
                    if throw:
                        failure_exc = _convergence_error(message, runner, t0, dt)
                        break
        if runner.failures.failed.size and status == RUN_FINISHED:
            status = RUN_FAILED
            message = _failure_message(method, runner.failures, batch, t0, dt)
        if runner.k < n and not runner.failures.alive.any():
            # every member failed: the run ends at its last good state; save it at its time
            with _deferred_sigint():
                if runner.k > k0 and runner.k % save_every:
                    y, _ = runner.state()
                    emit(np.array([t0 + runner.k * dt]), np.array(y).reshape(1, *W.shape))
                    if not memory:
                        checkpoint()
        with _deferred_sigint():
            sink.wait()
    except BaseException as exc:
        status = RUN_INTERRUPTED
        message = f"interrupted: {type(exc).__name__}: {exc}"
        sink.shutdown()
        if not memory and not isinstance(exc, ResultWriteError):
            try:  # the state is consistent between chunks: keep it
                y, st = runner.state()
                fails = runner.failures if runner.failures.failed.size else None
                sink._checkpoint(runner.k, y.reshape(W.shape), st, fails)
            except Exception:  # pragma: no cover - the original error matters more
                pass
        raise
    finally:
        bar.close()
        sink.shutdown()
        wall = time.perf_counter() - start
        stats = _stats(runner, k0, wall)
        try:
            out_writer.close(
                {
                    "status": status,
                    "message": message,
                    "steps_done": runner.k,
                    "stats": stats.as_dict(),
                }
            )
        except IsoflowError:
            if status != RUN_INTERRUPTED:
                raise
        except OSError as exc:
            if status != RUN_INTERRUPTED:
                raise ResultWriteError(f"closing the result file failed: {exc}") from exc
    if failure_exc is not None:
        raise failure_exc
    fails = runner.failures
    failed_step = fails.step.reshape(batch) if batch else np.asarray(fails.step[0])
    reasons = {
        (tuple(int(i) for i in np.unravel_index(int(m), batch)) if batch else ()): fails.reason(
            int(m)
        )
        for m in fails.failed
    }
    common: dict[str, Any] = {
        "stats": stats,
        "success": status == RUN_FINISHED,
        "status": status,
        "message": message,
        "t0": t0,
        "dt": dt,
        "n_steps": n,
        "failed_step": failed_step,
        "failure_reasons": reasons,
    }
    if memory:
        assert isinstance(out_writer, _MemoryWriter)
        ts, ys = out_writer.arrays()
        diag = accumulator.result() if diagnostics else None
        return Solution(ts=ts, ys=ys, diagnostics=diag, **common)
    y_last, _ = runner.state()
    t_first = t0 + state.step * dt
    if runner.k == state.step:
        ts, ys = np.array([t_first]), W_first[None]
    else:
        ts = np.array([t_first, t0 + runner.k * dt])
        ys = np.stack([W_first, y_last.reshape(W.shape)])
    return Solution(ts=ts, ys=ys, diagnostics=accumulator.result(), **common)


def _save_points(k0: int, k1: int, save_every: int, k_final: int) -> Array:
    """The save points in ``(k0, k1]`` in order, as an array."""
    first = (k0 // save_every + 1) * save_every
    ks = list(range(first, k1 + 1, save_every))
    if k0 < k_final <= k1 and k_final % save_every:
        ks.append(k_final)
    return np.asarray(ks, dtype=float)


def _convergence_error(message: str, runner: Runner, t0: float, dt: float) -> Exception:
    fails = runner.failures
    m = int(fails.failed[np.argmin(fails.step[fails.failed])])
    k = int(fails.step[m])
    code = int(fails.status[m])
    if code == FAIL_B_RAISED:
        exc: Exception = IsoflowError(message)
        if runner.last_exception is not None:
            exc.__cause__ = runner.last_exception
        return exc
    if code == STATUS_NON_FINITE and fails.iterations[m] <= 1 and fails.residual[m] == 0:
        return NonFiniteError(message)
    return ConvergenceError(
        message,
        step=k,
        time=t0 + k * dt,
        residual=float(fails.residual[m]),
        iterations=int(fails.iterations[m]),
        reason=fails.reason(m).split(":")[0],
    )


def _stats(runner: Runner, k0: int, wall: float) -> SolveStats:
    fails = runner.failures
    taken = runner.k - k0
    member_steps = 0
    for m in range(fails.step.shape[0]):
        j = int(fails.step[m])  # the failed step's index: j steps done, step j attempted
        member_steps += taken if j < 0 else max(j + 1 - k0, 0)
    its = runner.iterations_total
    return SolveStats(
        n_steps=runner.k,
        n_iterations=its,
        n_B_evaluations=int(runner.b_evaluations),
        iterations_mean=its / max(member_steps, 1),
        iterations_max=int(runner.iterations_max),
        residual_max=float(runner.residual_max),
        wall_time=wall,
        compile_time=float(getattr(runner, "compile_seconds", 0.0)),
        runner=runner.label,
    )
