r"""The entry points of a run: :func:`solve`, :func:`step`, and restarting a run.

Each validates its input (the time grid, the objects, the state and ``B`` at it) and hands the
run to the one time loop (:mod:`isoflow._time_loop`). The run's results are
:class:`~isoflow._solution.Solution` and :class:`~isoflow._solution.SolveStats`; a streaming
writer fulfils :class:`~isoflow._writers.StreamWriter`. Without a writer, :func:`solve`
streams into an in-memory one; the chunks (and hence the per-step arithmetic) are the same
either way, so a resumed file run reproduces an uninterrupted run bit for bit.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._compile_clock import compile_clock
from ._errors import (
    ArgumentTypeError,
    ParameterError,
    ShapeError,
    StepSizeError,
    TimeSpanError,
)
from ._failures import step_exception
from ._flags import check_flag
from ._save_grid import SaveGrid
from ._solution import RUN_FAILED, RUN_FINISHED, RUN_INTERRUPTED, RunState, Solution, SolveStats
from ._time_loop import open_run, run, run_threads
from ._writers import StreamWriter
from .diagnostics import DiagnosticsAccumulator
from .methods import Composition, Method, Strang
from .methods._base import StepDataRequest
from .methods.stochastic_isomp import refuse_noise
from .problems import IsospectralProblem
from .splitting import has_split_part
from .threads import ThreadRequest

__all__ = [
    "RUN_FAILED",
    "RUN_FINISHED",
    "RUN_INTERRUPTED",
    "Restart",
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
        return _resolvable(t0, dt, n_steps)
    span = t1 - t0
    if dt is None:
        assert n_steps is not None
        if n_steps == 0:
            if span != 0:
                raise StepSizeError("n_steps = 0 needs t1 == t0")
            return 1.0, 0
        if span == 0:
            raise TimeSpanError(
                f"the time span is empty (t1 == t0 = {t0}): {n_steps} steps would each be of "
                "dt = 0; give a later t1, or n_steps = 0"
            )
        return _resolvable(t0, span / n_steps, n_steps)
    n = round(span / dt)
    if abs(n * dt - span) > 1e-9 * max(abs(span), abs(dt)):
        raise StepSizeError(
            f"t1 - t0 = {span!r} is not a whole number of steps dt = {dt!r} "
            f"({span / dt:.6g} steps); choose dt = {span / max(n, 1)!r} or pass n_steps"
        )
    return _resolvable(t0, dt, int(n))


def _resolvable(t0: float, dt: float, n_steps: int) -> tuple[float, int]:
    """``(dt, n_steps)`` if the times ``t0 + k dt`` of the run are distinct floats.

    Raises
    ------
    StepSizeError
        ``dt`` below the spacing of the floats near the run's times (the times of the saved
        states would repeat or skip while the states advance), or a last time that overflows.
    """
    if n_steps == 0:
        return dt, n_steps
    end = t0 + n_steps * dt
    if not math.isfinite(end):
        raise StepSizeError(f"t0 + n_steps dt = {t0} + {n_steps} * {dt} is not a finite time")
    spacing = float(np.spacing(max(abs(t0), abs(end))))
    if dt < 4.0 * spacing:
        raise StepSizeError(
            f"dt = {dt!r} is below the resolution of the run's times (floats near "
            f"{max(abs(t0), abs(end)):.6g} are {spacing:.3g} apart): the times of the states "
            "would not be t0 + k dt; shift t0 towards 0 or take fewer, larger steps"
        )
    return dt, n_steps


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
        raise ArgumentTypeError(
            "problem must be an iso.IsospectralProblem (e.g. from iso.models.rigid_body()), "
            f"got {type(problem).__name__}"
        )
    if isinstance(method, type) and issubclass(method, Method):
        raise ArgumentTypeError(
            f"method must be a method instance: write iso.{method.__name__}(), not "
            f"iso.{method.__name__}"
        )
    if not isinstance(method, Method):
        raise ArgumentTypeError(
            f"method must be an isoflow method (e.g. iso.IsoMP()), got {method!r}"
        )
    refuse_noise(problem, method)
    if writer is not None and not isinstance(writer, StreamWriter):
        hint = (
            "; to write a file, pass iso.io.HDF5Writer(path)"
            if isinstance(writer, (str, bytes)) or hasattr(writer, "__fspath__")
            else ""
        )
        raise ArgumentTypeError(
            f"writer must be a stream writer (open/append/checkpoint/close), got "
            f"{type(writer).__name__}{hint}"
        )
    _check_split(problem, method)


def _splits(method: Method) -> bool:
    """Whether ``method`` integrates a problem's linear part and forcing (a split method, or
    a composition of one)."""
    if isinstance(method, Composition):
        return _splits(method.base)
    return isinstance(method, Strang)


def _check_split(problem: IsospectralProblem, method: Method) -> None:
    """A problem with a linear part or a forcing needs a split method.

    Raises
    ------
    ParameterError
        The method would integrate ``[B(W), W]`` alone, dropping the rest of the flow.
    """
    if has_split_part(problem) and not _splits(method):
        what = " and ".join(
            w
            for w, there in (
                ("a linear part", problem.linear_part is not None),
                ("a forcing", bool(problem.forcing)),
            )
            if there
        )
        raise ParameterError(
            f"the problem has {what}, which {method.name} does not integrate: solve it with "
            f"the split method iso.Strang({type(method).__name__}(...)) "
            "(or iso.Strang() for IsoMP)"
        )


def _check_state(
    problem: IsospectralProblem, y: ArrayLike, what: str, *, project: bool = True
) -> Array:
    """``y`` validated (and projected onto the space unless ``project=False``), ``B(y)``
    checked; no empty ensembles."""
    W = problem.algebra.validate(y, what, project=project)
    if W.size == 0:
        raise ShapeError(f"{what} is an empty ensemble (shape {W.shape}): nothing to integrate")
    problem.check_B(W)
    if problem.noise is not None:  # the members' ids (their noise keys) fit the ensemble
        problem.noise.member_ids(int(np.prod(problem.algebra.batch_shape(W), dtype=np.int64)))
        problem.noise.check_fields_at(W, problem.algebra)
    return W


# ---- one step ---------------------------------------------------------------------------------


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
    method = method.for_problem(problem)
    h = _real(h, "h", StepSizeError)
    if h == 0:
        raise StepSizeError("h must be finite and nonzero, got 0.0")
    W = _check_state(problem, y, "state") if validate else np.asarray(y)
    kw: dict[str, Any] = {}
    if method.reads_step_data:  # the step from t = 0 of every member
        batch = problem.algebra.batch_shape(W)
        members = np.arange(int(np.prod(batch, dtype=np.int64)))
        rows = np.asarray(method.step_data(problem, StepDataRequest(0, 1, members, h)))[0]
        kw["data"] = rows.reshape(*batch, rows.shape[-1])
    res = method.step(problem, W, h, method.init(problem, W, h), **kw)
    if not res.success or not np.all(np.isfinite(res.y)):
        raise step_exception(method.name, res, 0, 0.0)
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
    threads: ThreadRequest = None,
    status_every: float | None = None,
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
        A run that compiles (the first with a kernel on a machine) says so on stderr, what it
        compiles and how long it took, unless ``progress=False``.
    throw : bool
        If a step fails, raise :class:`ConvergenceError` (default; after writing what was
        computed) or return the solution with ``success=False``.
    writer : StreamWriter or None
        Stream the saved states, their diagnostics and checkpoints to ``writer`` (e.g.
        ``iso.io.HDF5Writer("run.h5")``) instead of holding them: memory stays bounded in the
        number of steps. The returned :class:`Solution` then holds only two saved states,
        the initial and the final one, and its ``diagnostics`` has the drifts over *all* saved
        states with the time series of those two states only.

    threads : None, int or dict
        Threads of the run (:mod:`isoflow.threads`), applied inside the loop to every BLAS and
        OpenMP library and to numba. ``None`` (default): the enclosing
        ``iso.threads.thread_limits`` block's choice, else one BLAS thread and numba threads
        on every core for compiled loops that run ensemble members in parallel; ``k``: ``k``
        cores (numba threads when the compiled loop runs members in parallel, else BLAS
        threads); ``{"blas": b, "numba": m}``: both. Environment variables such as
        ``OPENBLAS_NUM_THREADS`` are upper bounds; more threads than cores are refused
        (:class:`ParameterError`). The counts used are in ``stats.threads``.
    status_every : float or None
        For runs left alone for hours: every this many seconds of wall time, one line on stderr
        with the step, the simulated time, the steps per second (the mean since the first
        chunk) and the projected end as a clock time (``isoflow run`` writes one a minute).
        ``None`` (default): none.

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
    method = method.for_problem(problem)  # what the run's file records
    _check_save_every(save_every)
    _check_status_every(status_every)
    _check_flags(progress, throw)
    check_flag(diagnostics, "diagnostics")
    dt_, n = time_grid(t0, t1, dt, n_steps)
    with compile_clock(show=progress is not False) as clock, run_threads(threads) as pools:
        W = _check_state(problem, y0, "y0")
        start = RunState(0, W, method.init(problem, W, dt_))
        r = open_run(
            problem, method, start, t0=float(t0), dt=dt_, grid=SaveGrid(int(save_every), n),
            diagnostics=diagnostics, writer=writer, fresh=True, threads=(threads, pools),
        )  # fmt: skip
        return run(
            r, fresh=True, progress=progress, throw=throw, clock=clock, status_every=status_every
        )


def _check_status_every(status_every: Any) -> None:
    """``status_every`` is ``None`` or a positive finite number of seconds."""
    if status_every is None:
        return
    ok = isinstance(status_every, (int, float, np.integer, np.floating))
    if not ok or isinstance(status_every, bool) or not 0 < float(status_every) < np.inf:
        raise ParameterError(
            f"status_every must be a positive number of seconds or None, got {status_every!r}"
        )


def _check_flags(progress: Any, throw: Any) -> None:
    """``progress`` is a bool or ``None``, ``throw`` a bool (a string such as ``"no"`` would
    count as true)."""
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise ParameterError(f"progress must be True, False or None, got {progress!r}")
    check_flag(throw, "throw")


def check_continue_options(progress: Any, throw: Any, status_every: Any) -> None:
    """The options of a continued run, checked before a file is touched."""
    _check_flags(progress, throw)
    _check_status_every(status_every)


def _check_save_every(save_every: Any) -> None:
    """``save_every`` is a positive integer (``ParameterError`` otherwise)."""
    ok = isinstance(save_every, (int, np.integer)) and not isinstance(save_every, bool)
    if not ok or save_every < 1:
        raise ParameterError(f"save_every must be a positive integer, got {save_every!r}")


@dataclass(frozen=True)
class Restart:
    """A run to continue, as :func:`check_restart` validated it (the only way to make one that
    :func:`continue_run` trusts: it does not validate again).

    Attributes
    ----------
    problem, method :
        The run's.
    state : RunState
        Where it continues from; ``state.y`` holds exactly the checkpoint's values (checked,
        not projected: see :func:`check_restart`).
    t0, dt : float
        Start time and step.
    n_steps, save_every : int
        The run's time grid.
    """

    problem: IsospectralProblem
    method: Method
    state: RunState
    t0: float
    dt: float
    n_steps: int
    save_every: int


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
) -> Restart:
    """Validate a restart from ``state`` as :func:`solve` validates a start.

    The state is checked (the run's space to the tolerance of :func:`solve`, finite, its
    dtype and shape, ``B`` at it) but **not** projected: the run continues from exactly the
    state it held, so that it continues bit for bit (a projection is not idempotent in
    floating point for every space; ``su(n)``'s trace removal is not).

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
    W = _check_state(problem, state.y, "checkpoint state", project=False)
    M = int(np.prod(problem.algebra.batch_shape(W), dtype=np.int64))
    if state.failures is not None and state.failures.step.shape != (M,):
        raise ShapeError(
            f"checkpoint failure record for {state.failures.step.shape} members, state has {M}"
        )
    return Restart(
        problem, method, dataclasses.replace(state, y=W), float(t0), dt_, n, int(save_every)
    )


def continue_run(
    restart: Restart,
    *,
    writer: StreamWriter,
    accumulator: DiagnosticsAccumulator,
    progress: bool | None = None,
    throw: bool = True,
    threads: ThreadRequest = None,
    status_every: float | None = None,
) -> Solution:
    """Continue a run validated by :func:`check_restart`, appending to ``writer``.

    ``accumulator`` has absorbed the diagnostics of the rows already written; ``threads`` and
    ``status_every`` are as in :func:`solve`.
    """
    _check_status_every(status_every)
    _check_flags(progress, throw)
    rs = restart
    with compile_clock(show=progress is not False) as clock, run_threads(threads) as pools:
        r = open_run(
            rs.problem, rs.method, rs.state, t0=rs.t0, dt=rs.dt,
            grid=SaveGrid(rs.save_every, rs.n_steps), diagnostics=True, writer=writer,
            fresh=False, accumulator=accumulator, threads=(threads, pools),
        )  # fmt: skip
        return run(
            r, fresh=False, progress=progress, throw=throw, clock=clock, status_every=status_every
        )
