"""The fixed-step time loop: :func:`solve` and :func:`step`."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import asdict, dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm.auto import tqdm

from ._errors import ConvergenceError, NonFiniteError, StepSizeError, TimeSpanError
from .diagnostics import Diagnostics, DiagnosticsAccumulator, compute_diagnostics
from .methods import Method, StepResult
from .problems import IsospectralProblem

__all__ = ["Solution", "SolveStats", "StreamWriter", "solve", "step"]

Array = NDArray[Any]

STATUS_FINISHED = 0
STATUS_FAILED = -1


@dataclass(frozen=True)
class SolveStats:
    """Counters of a run.

    Attributes
    ----------
    n_steps : int
        Steps completed.
    n_B_evaluations : int
        Nonlinear iterations summed over steps and members (one ``B`` evaluation each).
    iterations_mean, iterations_max : float, int
        Nonlinear iterations per step and member.
    residual_max : float
        Largest final nonlinear residual over all steps and members.
    wall_time : float
        Seconds spent in the loop.
    """

    n_steps: int = 0
    n_B_evaluations: int = 0
    iterations_mean: float = 0.0
    iterations_max: int = 0
    residual_max: float = 0.0
    wall_time: float = 0.0

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
        Saved states, time first.
    stats : SolveStats
    success : bool
        Whether all requested steps were taken.
    status : int
        ``0`` finished, ``-1`` a step failed (only with ``throw=False``).
    message : str
        What happened, in words.
    diagnostics : Diagnostics or None
        Invariant drifts on the saved states (``None`` when ``diagnostics=False``).
    t0, dt : float
        Start time and step.
    n_steps : int
        Steps requested.
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

    @property
    def y_final(self) -> Array:
        """The last saved state (the final state when ``success``)."""
        return self.ys[-1]


@runtime_checkable
class StreamWriter(Protocol):
    """What :func:`solve` needs from a streaming writer (e.g. :class:`isoflow.io.HDF5Writer`).

    The solve loop buffers at most ``chunk_rows`` saved states (or ``flush_seconds`` of work),
    then calls :meth:`append` with them and :meth:`checkpoint` with the step index, state and
    method state of the last of them; the writer makes both durable together, so what it holds
    is always a consistent (saved states, last state, method state, step) set. The initial state
    is appended and checkpointed at once. :meth:`close` ends the run (also after a failure or an
    interrupt, after the last good states were appended).
    """

    chunk_rows: int
    flush_seconds: float

    def open(self, meta: dict[str, Any]) -> None:
        """Start a run described by ``meta`` (times, method, algebra; JSON-ready)."""

    def append(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        """Saved states ``ys`` at ``ts`` (time first) and their diagnostic ``series``."""

    def checkpoint(self, step: int, y: Array, method_state: Any) -> None:
        """The state after ``step`` steps (the last appended one) and the method state."""

    def close(self, info: dict[str, Any]) -> None:
        """End the run; ``info`` holds the status, message and :class:`SolveStats`."""


def _time_grid(
    t0: float, t1: float | None, dt: float | None, n_steps: int | None
) -> tuple[float, int]:
    """Resolve ``(dt, n_steps)`` from the user's choice of two of ``t1``, ``dt``, ``n_steps``."""
    if not math.isfinite(t0):
        raise TimeSpanError(f"t0 must be finite, got {t0}")
    if dt is not None and not (math.isfinite(dt) and dt > 0):
        raise StepSizeError(f"dt must be positive and finite, got {dt}")
    if n_steps is not None:
        if isinstance(n_steps, bool) or int(n_steps) != n_steps or n_steps < 0:
            raise StepSizeError(f"n_steps must be a non-negative integer, got {n_steps!r}")
        n_steps = int(n_steps)
    if t1 is not None:
        if not math.isfinite(t1):
            raise TimeSpanError(f"t1 must be finite, got {t1}")
        if t1 < t0:
            raise TimeSpanError(
                f"t1 = {t1} is before t0 = {t0}; steps go forward in time (use a problem with "
                "-B, or step() with a negative h, to integrate backwards)"
            )
    given = sum(x is not None for x in (t1, dt, n_steps))
    if given != 2:
        raise ValueError(
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
    assert dt is not None
    n = round(span / dt)
    if abs(n * dt - span) > 1e-9 * max(abs(span), abs(dt)):
        raise StepSizeError(
            f"t1 - t0 = {span!r} is not a whole number of steps dt = {dt!r} "
            f"({span / dt:.6g} steps); choose dt = {span / max(n, 1)!r} or pass n_steps"
        )
    return dt, int(n)


def _failure_message(method: Method, res: StepResult, k: int, t: float) -> str:
    assert res.residual is not None and res.iterations is not None
    reason = res.failure_reason()
    bad = int(np.count_nonzero(np.asarray(res.status) != 0))
    total = int(np.asarray(res.status).size)
    return (
        f"{method.name}: the nonlinear solve of step {k} (t = {t:.6g}) did not converge "
        f"({reason}) for {bad} of {total} ensemble member(s): residual "
        f"{float(np.max(res.residual)):.3e} after {int(np.max(res.iterations))} iterations. "
        "Reduce dt (h * ||B(W)|| should stay well below 2) or change the solver."
    )


def _failure_exception(method: Method, res: StepResult, k: int, t: float) -> Exception:
    """The exception describing a rejected step ``k`` that started at time ``t``."""
    if not res.success:
        return ConvergenceError(
            _failure_message(method, res, k, t),
            step=k,
            time=t,
            residual=float(np.max(res.residual)) if res.residual is not None else float("nan"),
            iterations=int(np.max(res.iterations)) if res.iterations is not None else 0,
            reason=res.failure_reason(),
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
    """
    if not (math.isfinite(h) and h != 0):
        raise StepSizeError(f"h must be finite and nonzero, got {h}")
    W = problem.algebra.validate(y, "state") if validate else np.asarray(y)
    if validate:
        problem.check_B(W)
    res = method.step(problem, W, h, method.init(problem, W, h))
    if not res.success or not np.all(np.isfinite(res.y)):
        raise _failure_exception(method, res, 0, 0.0)
    return (res.y, res) if return_info else res.y


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
        Initial state; leading axes make an ensemble, solved in one call. It is checked to lie
        in ``V`` (relative distance ``1e-10``) and then projected onto ``V`` exactly.
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
        If a step fails, raise :class:`ConvergenceError` (default) or return the solution so
        far with ``success=False``; its last saved state is the last good state.
    writer : StreamWriter or None
        Stream the saved states, their diagnostics and checkpoints to ``writer`` (e.g.
        ``iso.io.HDF5Writer("run.h5")``) in chunks instead of holding them: memory stays bounded
        in the number of steps. The returned :class:`Solution` then holds only two saved states,
        the initial and the final one (``sol.ys[-1]`` is the final state), and its
        ``diagnostics`` has the drifts over *all* saved states (computed incrementally) with the
        time series of those two states only; the full series are in the writer's output.

    Returns
    -------
    Solution
    """
    if isinstance(save_every, bool) or int(save_every) != save_every or save_every < 1:
        raise ValueError(f"save_every must be a positive integer, got {save_every!r}")
    save_every = int(save_every)
    dt_, n = _time_grid(float(t0), None if t1 is None else float(t1), dt, n_steps)
    alg = problem.algebra
    W = alg.validate(y0, "y0")
    problem.check_B(W)
    memory: _MemoryWriter | None = None
    if writer is None:
        memory = _MemoryWriter()
        writer = memory
    sol = _solve_streaming(
        problem,
        method,
        W,
        method.init(problem, W, dt_),
        k0=0,
        n=n,
        t0=float(t0),
        dt=dt_,
        save_every=save_every,
        progress=progress,
        throw=throw,
        writer=writer,
        accumulator=DiagnosticsAccumulator(problem) if memory is None else None,
        diagnostics=diagnostics,
        fresh=True,
    )
    if memory is None:
        return sol
    ts, ys = memory.arrays()
    return dataclasses.replace(
        sol, ts=ts, ys=ys, diagnostics=compute_diagnostics(problem, ts, ys) if diagnostics else None
    )


class _MemoryWriter:
    """The in-memory "stream" of :func:`solve` without a writer: keeps every saved state."""

    chunk_rows = 2**62  # never flush early: one chunk at the end
    flush_seconds = math.inf

    def __init__(self) -> None:
        self._ts: list[Array] = []
        self._ys: list[Array] = []

    def open(self, meta: dict[str, Any]) -> None:
        """Nothing to prepare."""

    def append(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        self._ts.append(ts)
        self._ys.append(ys)

    def checkpoint(self, step: int, y: Array, method_state: Any) -> None:
        """In memory there is nothing to make durable."""

    def close(self, info: dict[str, Any]) -> None:
        """Nothing to release."""

    def arrays(self) -> tuple[Array, Array]:
        """All saved times and states, time first."""
        return np.concatenate(self._ts), np.concatenate(self._ys)


def _solve_streaming(
    problem: IsospectralProblem,
    method: Method,
    W: Array,
    state: Any,
    *,
    k0: int,
    n: int,
    t0: float,
    dt: float,
    save_every: int,
    progress: bool | None,
    throw: bool,
    writer: StreamWriter,
    accumulator: DiagnosticsAccumulator | None,
    diagnostics: bool,
    fresh: bool,
) -> Solution:
    """The solve loop writing to ``writer``: steps ``k0 .. n`` from ``W`` (after ``k0`` steps).

    ``fresh`` runs open the writer and write the initial state; a resumed run (``fresh=False``)
    continues a writer that already holds the states up to step ``k0``, whose diagnostics
    ``accumulator`` has absorbed (``None``: the caller computes diagnostics itself, as
    :func:`solve` does on the states it keeps in memory). This is the only time loop: without a
    writer :func:`solve` streams into an in-memory one, so the ``advance`` calls cover the same
    step ranges (between saves) either way and a resumed run reproduces an uninterrupted one bit
    for bit.
    """
    alg = problem.algebra
    buf_t: list[float] = []
    buf_y: list[Array] = []
    last_flush = time.monotonic()
    last_written = (k0, W, state)

    def flush(k: int, y: Array, st: Any) -> None:
        nonlocal last_flush, last_written
        if buf_y:
            ts_c = np.asarray(buf_t, dtype=float)
            ys_c = np.stack(buf_y)
            series = accumulator.update(ts_c, ys_c) if accumulator is not None else {}
            writer.append(ts_c, ys_c, series)
            writer.checkpoint(k, y, st)
            buf_t.clear()
            buf_y.clear()
            last_written = (k, y, st)
        last_flush = time.monotonic()

    W_first = W
    if fresh:
        writer.open(
            {
                "t0": t0,
                "dt": dt,
                "n_steps": n,
                "save_every": save_every,
                "method": method.name,
                "algebra": alg.name,
                "state_shape": list(W.shape),
                "state_dtype": np.dtype(alg.dtype).str,
                "casimir_scale": np.asarray(alg.casimir_scale(W), dtype=float).tolist(),
            }
        )
        buf_t.append(t0)
        buf_y.append(W)
        flush(0, W, state)
    total_iter = max_iter = 0
    max_res = 0.0
    status, message = STATUS_FINISHED, f"{n} steps of dt = {dt:g} completed"
    start = time.perf_counter()
    k = k0
    bar = tqdm(
        total=n,
        initial=k0,
        disable=(None if progress is None else not progress),
        delay=1.0,
        desc=method.name,
        unit="step",
        leave=False,
    )
    try:
        while k < n:
            chunk = min(save_every - k % save_every, n - k)
            adv = method.advance(problem, W, dt, chunk, state)
            total_iter += adv.iterations_total
            max_iter = max(max_iter, adv.iterations_max)
            max_res = max(max_res, adv.residual_max)
            W, state = adv.y, adv.state
            k += adv.n_done
            bar.update(adv.n_done)
            if adv.failure is not None:
                failure = _failure_exception(method, adv.failure, k, t0 + k * dt)
                status, message = STATUS_FAILED, str(failure)
                if adv.n_done:  # keep the last good state
                    buf_t.append(t0 + k * dt)
                    buf_y.append(W)
                if throw:
                    raise failure
                break
            buf_t.append(t0 + k * dt)
            buf_y.append(W)
            if len(buf_y) >= writer.chunk_rows or (
                time.monotonic() - last_flush >= writer.flush_seconds
            ):
                flush(k, W, state)
    except BaseException as exc:
        if status == STATUS_FINISHED:
            status, message = STATUS_FAILED, f"interrupted: {type(exc).__name__}: {exc}"
        raise
    finally:
        bar.close()
        wall = time.perf_counter() - start
        if buf_y:
            # the buffered states are all good; the last of them is the current (k, W, state)
            flush(k, W, state)
        n_done = k - k0
        members = max(int(np.prod(alg.batch_shape(W))), 1)
        stats = SolveStats(
            n_steps=k,
            n_B_evaluations=total_iter,
            iterations_mean=total_iter / max(n_done + (status == STATUS_FAILED), 1) / members,
            iterations_max=max_iter,
            residual_max=max_res,
            wall_time=wall,
        )
        writer.close(
            {
                "status": status,
                "message": message,
                "steps_done": last_written[0],
                "stats": stats.as_dict(),
            }
        )
    t_last = t0 + last_written[0] * dt
    t_first = t0 + k0 * dt
    if k == k0:
        ts, ys = np.array([t_first]), np.stack([W_first])
    else:
        ts, ys = np.array([t_first, t_last]), np.stack([W_first, last_written[1]])
    return Solution(
        ts=ts,
        ys=ys,
        stats=stats,
        success=status == STATUS_FINISHED,
        status=status,
        message=message,
        diagnostics=accumulator.result() if diagnostics and accumulator is not None else None,
        t0=t0,
        dt=dt,
        n_steps=n,
    )
