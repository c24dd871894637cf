r"""The fixed-step time loop, in parts: opening a run, its chunks, its checkpoints, its result.

One loop serves every run (:func:`isoflow.solve`, a restart from a checkpoint). It picks a
runner (the compiled one of :mod:`isoflow._compiled` when the run has a compiled path, else the
method's own NumPy steps, :class:`~isoflow._stepping.PythonRunner`) and advances in chunks:

* :func:`open_run` builds the runner, the writer (a file's, or the in-memory one) and the
  :class:`~isoflow._writers.Sink` that feeds it, and opens the writer for a fresh run;
* :class:`ChunkPolicy` says how many steps the next chunk takes: as many as fit in about half
  a second (:data:`CHUNK_SECONDS`, measured from the chunks before) and in the writer's row
  buffer, ending at a save point when the runner needs that;
* :class:`CheckpointPolicy` says when the writer checkpoints: when the run ends, when a member
  failed, every ``chunk_rows`` saved rows and every ``flush_seconds``;
* :func:`run` is the loop itself (saved rows, their check, failures, progress, interrupts);
  :func:`solution` builds what it returns.

So a run is interruptible within about a second (Ctrl-C acts between chunks: the state, the rows
and the checkpoint stay consistent) and a kill loses at most the work since the last
checkpoint. Which steps are saved is :class:`~isoflow._save_grid.SaveGrid`'s rule. Without a
writer the chunks (and hence the per-step arithmetic) are the same, so a resumed file run
reproduces an uninterrupted run bit for bit.
"""

from __future__ import annotations

import copy
import dataclasses
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._compile_clock import CompileClock
from ._errors import IsoflowError, ResultWriteError
from ._failures import MemberFailures, describe, exception_for
from ._fingerprint import model_fingerprint
from ._method_settings import method_settings
from ._save_grid import SaveGrid
from ._solution import RUN_FAILED, RUN_FINISHED, RUN_INTERRUPTED, RunState, Solution, SolveStats
from ._status_lines import StatusLines
from ._stepping import PythonRunner, Runner, stop_members_leaving_the_space
from ._writers import PIPELINE_MIN_ROWS, PIPELINE_SECONDS, MemoryWriter, Sink, StreamWriter
from .diagnostics import DiagnosticsAccumulator
from .methods import Method
from .problems import IsospectralProblem
from .threads import ThreadPools, ThreadRequest, default_request, plan_threads

__all__ = [
    "CHUNK_BYTES",
    "CHUNK_SECONDS",
    "CheckpointPolicy",
    "ChunkPolicy",
    "OpenRun",
    "open_run",
    "run",
    "run_threads",
    "runner_for",
    "solution",
]

Array = NDArray[Any]

#: Target wall time of one chunk: Ctrl-C acts and checkpoints happen at least this often.
CHUNK_SECONDS = 0.5
#: Largest row buffer of one chunk, in bytes (larger states save fewer rows per chunk).
CHUNK_BYTES = 64 * 2**20


@contextmanager
def run_threads(threads: ThreadRequest) -> Iterator[ThreadPools]:
    """The run's thread counts (:mod:`isoflow.threads`) for the block: applied to numba and
    every BLAS/OpenMP library before the runner is built (settled once it is, by
    :func:`open_run`), restored at the end."""
    pools = ThreadPools()
    try:
        pools.apply(plan_threads(threads, parallel=True))
        yield pools
    finally:
        pools.restore()


def _settle_threads(pools: ThreadPools, threads: ThreadRequest, runner: Runner) -> dict[str, int]:
    """Apply the final thread counts for ``runner`` (a number of cores goes to numba when its
    steps run on numba threads, else to BLAS); return those it uses (``stats.threads``)."""
    threaded = runner.numba_threaded
    plan = plan_threads(threads, parallel=threaded)
    if threaded and runner.serial_by_default and default_request(threads):
        plan = dataclasses.replace(plan, numba=1)
    pools.apply(plan)
    return {"cores": plan.cores, "numba": plan.numba if threaded else 1, "blas": plan.blas}


def runner_for(
    problem: IsospectralProblem, method: Method, state: RunState, dt: float, t0: float = 0.0
) -> Runner:
    """The compiled runner of the run when it has a compiled path, else the NumPy one."""
    kw: dict[str, Any] = {
        "method_state": state.method_state, "k": state.step, "failures": state.failures,
        "t0": t0,
    }  # fmt: skip
    if problem.kernel is not None:
        from ._compiled import compiled_runner

        r = compiled_runner(problem, method, state.y, dt, **kw)
        if r is not None:
            return r
    return PythonRunner(problem, method, state.y, dt, **kw)


@dataclass
class ChunkPolicy:
    """How many steps the next chunk takes.

    The first chunk takes one step (it may compile: it is not timed), the second four; from
    then on a chunk takes :attr:`seconds` at the mean time per step of the chunks before. A
    chunk never saves more than :attr:`max_rows` rows, and ends at a save point when the
    runner needs its checkpoints there (:attr:`~isoflow._stepping.Runner.checkpoints_at_saves`).
    """

    grid: SaveGrid
    max_rows: int
    seconds: float
    at_saves: bool
    per_step: float | None = None
    calls: int = 0

    def steps(self, k: int) -> int:
        """Steps of the chunk from step ``k``."""
        n = min(self.grid.k_final - k, self.grid.steps_for_rows(k, self.max_rows))
        if self.per_step is not None:
            n = min(n, max(1, int(self.seconds / max(self.per_step, 1e-12))))
        else:
            n = min(n, 1 if self.calls == 0 else 4)
        return self.grid.end_at_save(k, n) if self.at_saves else n

    def took(self, nsteps: int, seconds: float) -> None:
        """A chunk of ``nsteps`` steps took ``seconds``."""
        self.calls += 1
        if self.calls > 1 and nsteps > 0:  # the first call may compile: not timed
            rate = seconds / nsteps
            self.per_step = rate if self.per_step is None else 0.5 * (self.per_step + rate)


@dataclass
class CheckpointPolicy:
    """When the writer checkpoints: when the run ends, when a member failed, every
    :attr:`rows` saved rows and every :attr:`seconds` (never for the in-memory writer)."""

    enabled: bool
    rows: int
    seconds: float
    last: float = field(default_factory=time.monotonic)
    since: int = 0

    def due(self, rows: int, finished: bool, failed: bool) -> bool:
        """After a chunk that saved ``rows`` rows: whether to checkpoint now."""
        self.since += rows
        now = time.monotonic()
        if self.enabled and (
            finished or failed or self.since >= self.rows or now - self.last >= self.seconds
        ):
            self.last, self.since = now, 0
            return True
        return False


@dataclass
class OpenRun:
    """A run being stepped: what the loop and its parts share."""

    problem: IsospectralProblem
    method: Method
    start: RunState
    t0: float
    dt: float
    grid: SaveGrid
    runner: Runner
    writer: StreamWriter
    sink: Sink
    accumulator: DiagnosticsAccumulator
    memory: bool
    diagnostics: bool
    pools: ThreadPools
    threads: dict[str, int]

    @property
    def shape(self) -> tuple[int, ...]:
        """The state's shape ``(*batch, *core)``."""
        return tuple(self.start.y.shape)

    @property
    def batch(self) -> tuple[int, ...]:
        return self.problem.algebra.batch_shape(self.start.y)

    def emit(self, ks: Array, ys: Array) -> None:
        """Saved states ``ys`` after the steps ``ks`` (owned by the sink from now on)."""
        self.sink.rows(self.t0 + np.asarray(ks, dtype=float) * self.dt, ys)

    def checkpoint(self) -> None:
        """A checkpoint of where the runner stands (copies: the runner goes on)."""
        r = self.runner
        y, st = r.state()
        fails = copy.deepcopy(r.failures) if r.failures.failed.size else None
        self.sink.checkpoint(r.k, np.array(y, copy=True).reshape(self.shape), st, fails)

    def meta(self) -> dict[str, Any]:
        """What a fresh run's writer records about it."""
        alg, W = self.problem.algebra, self.start.y
        meta: dict[str, Any] = {
            "t0": self.t0,
            "dt": self.dt,
            "n_steps": self.grid.k_final,
            "save_every": self.grid.every,
            "method": self.method.name,
            "method_settings": method_settings(self.method),
            "algebra": alg.name,
            "state_shape": list(W.shape),
            "core_shape": list(alg.shape),
            "state_dtype": np.dtype(alg.dtype).str,
            "casimir_scale": np.asarray(alg.casimir_scale(W), dtype=float).tolist(),
        }
        fields = getattr(alg, "fields", None)
        if isinstance(fields, tuple):  # pairs: the fields' names
            meta["fields"] = [str(f) for f in fields]
        if not self.memory:
            meta["model_fingerprint"] = model_fingerprint(self.problem, W)
        return meta


def open_run(
    problem: IsospectralProblem, method: Method, start: RunState, *, t0: float, dt: float,
    grid: SaveGrid, diagnostics: bool, writer: StreamWriter | None, fresh: bool,
    threads: tuple[ThreadRequest, ThreadPools], accumulator: DiagnosticsAccumulator | None = None,
) -> OpenRun:  # fmt: skip
    """Build the runner, the writer and the sink of a run; open the writer of a fresh one
    (a restart continues a writer holding the rows up to ``start.step``). ``threads`` is the
    request and the pools of :func:`run_threads`."""
    alg = problem.algebra
    W = start.y
    memory = writer is None
    out: StreamWriter = (
        MemoryWriter(grid.rows(fresh) - grid.count(0, start.step) + 1, W.shape, alg.dtype)
        if writer is None
        else writer
    )
    if accumulator is None:
        accumulator = DiagnosticsAccumulator(problem, keep_series=memory)
        accumulator.set_first_state(W)
    runner = runner_for(problem, method, start, dt, t0)
    request, pools = threads
    used = _settle_threads(pools, request, runner)
    series = diagnostics or not memory
    background = (
        series and not runner.parallel and grid.count(runner.k, grid.k_final) >= PIPELINE_MIN_ROWS
    )
    runner.threads_beside = 1 if background else 0  # the writer's thread
    sink = Sink(out, accumulator, series, background=background)
    r = OpenRun(problem, method, start, t0, dt, grid, runner, out, sink, accumulator, memory,
                diagnostics, pools, used)  # fmt: skip
    if fresh:
        try:
            out.open(r.meta())
        except IsoflowError:
            raise  # e.g. another process writes the file: its own message
        except OSError as exc:
            raise ResultWriteError(f"creating the result file failed: {exc}") from exc
    return r


@contextmanager
def deferred_sigint() -> Iterator[None]:
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


@dataclass
class _Outcome:
    """How the loop ended: the run's status, its message, the exception to raise."""

    status: int
    message: str
    error: Exception | None = None


def run(r: OpenRun, *, fresh: bool, progress: bool | None, throw: bool,
        clock: CompileClock, status_every: float | None = None) -> Solution:  # fmt: skip
    """The loop over chunks (see the module docstring); returns the :class:`Solution`.
    With ``status_every``, a status line every that many seconds (:mod:`isoflow._status_lines`)."""
    from tqdm.auto import tqdm

    runner, grid = r.runner, r.grid
    n = grid.k_final
    k0 = runner.k
    alg = r.problem.algebra
    M = int(np.prod(r.batch, dtype=np.int64))
    chunks = ChunkPolicy(
        grid,
        max_rows=int(max(1, min(r.writer.chunk_rows, CHUNK_BYTES // max(r.start.y.nbytes, 1)))),
        seconds=PIPELINE_SECONDS if r.sink.pool is not None else CHUNK_SECONDS,
        at_saves=runner.checkpoints_at_saves,
    )
    checkpoints = CheckpointPolicy(not r.memory, r.writer.chunk_rows, r.writer.flush_seconds)
    outcome = _Outcome(RUN_FINISHED, f"{n} steps of dt = {r.dt:g} completed")
    bar = tqdm(  # on a terminal after a second; at once when asked for
        total=n, initial=k0, disable=(None if progress is None else not progress),
        delay=1.0 if progress is None else 0.0, desc=r.method.name, unit="step", leave=False,
    )  # fmt: skip
    status = StatusLines(status_every, n, r.t0, r.dt)
    reported = runner.failures.failed.size
    last_good = (k0, np.array(r.start.y, copy=True).reshape(M, *alg.shape))  # last checked
    try:
        if fresh:  # inside the try: a failure here closes the writer (no temporary files left)
            r.emit(np.array([0]), r.start.y[None].copy())
            if not r.memory:
                r.checkpoint()
        while runner.k < n and runner.failures.alive.any():
            with deferred_sigint():
                k_before = runner.k
                nsteps = chunks.steps(k_before)
                rows = grid.count(k_before, k_before + nsteps)
                if r.memory and not r.sink.pending:  # straight into the result (none queued)
                    assert isinstance(r.writer, MemoryWriter)
                    out = r.writer.rows(rows).reshape(rows, M, *alg.shape)
                else:
                    out = np.empty((rows, M, *alg.shape), dtype=alg.dtype)
                r.pools.refresh()  # limit a library the last chunk loaded (an import)
                t_call = time.perf_counter()
                runner.advance(nsteps, grid, out)
                chunks.took(nsteps, time.perf_counter() - t_call)
                ks = grid.points(k_before, runner.k)
                if ks.size:  # members whose B at a saved state left the normalizer fail
                    last_good = stop_members_leaving_the_space(
                        r.problem, runner, out[: ks.size], ks, last_good
                    )
                done = grid.count(k_before, runner.k)
                if done:
                    r.emit(ks[:done], out[:done].reshape(done, *r.shape))
                bar.update(max(runner.k - k_before, 0))
                status.after_chunk(runner.k)
                newly = runner.failures.failed.size > reported
                finished = runner.k >= n or not runner.failures.alive.any()
                if checkpoints.due(done, finished, newly):
                    r.checkpoint()
                if newly:
                    reported = runner.failures.failed.size
                    outcome = _failed(r)
                    if throw:
                        outcome.error = exception_for(
                            outcome.message, runner.failures, runner.exceptions, r.t0, r.dt
                        )
                        break
        if runner.failures.failed.size and outcome.status == RUN_FINISHED:
            outcome = _failed(r)
        if runner.k < n and not runner.failures.alive.any():
            # every member failed: the run ends at its last good state; save it at its time
            with deferred_sigint():
                if runner.k > k0 and not grid.is_save(runner.k):
                    y, _ = runner.state()
                    r.emit(np.array([runner.k]), np.array(y).reshape(1, *r.shape))
                    if not r.memory:
                        r.checkpoint()
        with deferred_sigint():
            r.sink.wait()
    except BaseException as exc:
        outcome = _Outcome(RUN_INTERRUPTED, f"interrupted: {type(exc).__name__}: {exc}")
        _keep_what_was_computed(r, exc)
        raise
    finally:
        bar.close()
        r.sink.shutdown()
        stats = _stats(runner, k0, time.perf_counter() - clock.started, clock.seconds, r.threads)
        _close(r, outcome, stats)
    if outcome.error is not None:
        raise outcome.error
    return solution(r, outcome, stats)


def _failed(r: OpenRun) -> _Outcome:
    return _Outcome(RUN_FAILED, describe(r.method.name, r.runner.failures, r.batch, r.t0, r.dt))


def _keep_what_was_computed(r: OpenRun, exc: BaseException) -> None:
    """After an exception from outside the numerics: stop the writer's worker and checkpoint
    the state (consistent between chunks), unless writing is what failed."""
    r.sink.shutdown()
    if r.memory or isinstance(exc, ResultWriteError):
        return
    try:
        y, st = r.runner.state()
        fails = r.runner.failures if r.runner.failures.failed.size else None
        r.sink.write_checkpoint(r.runner.k, y.reshape(r.shape), st, fails)
    except Exception:  # pragma: no cover - the original error matters more
        pass


def _close(r: OpenRun, outcome: _Outcome, stats: SolveStats) -> None:
    """End the writer's run with its status, message and statistics."""
    info = {
        "status": outcome.status,
        "message": outcome.message,
        "steps_done": r.runner.k,
        "stats": stats.as_dict(),
    }
    try:
        r.writer.close(info)
    except IsoflowError:
        if outcome.status != RUN_INTERRUPTED:
            raise
    except OSError as exc:
        if outcome.status != RUN_INTERRUPTED:
            raise ResultWriteError(f"closing the result file failed: {exc}") from exc


def _stats(
    runner: Runner, k0: int, wall: float, compile_time: float, threads: dict[str, int]
) -> SolveStats:
    fails = runner.failures
    taken = runner.k - k0
    member_steps = 0
    for m in range(fails.step.shape[0]):
        j = int(fails.step[m])  # the failed step's index: j steps done, step j attempted
        member_steps += taken if j < 0 else max(j + 1 - k0, 0)
    its = runner.iterations_total
    return SolveStats(
        n_steps=runner.k,
        first_step=k0,
        n_iterations=its,
        n_B_evaluations=int(runner.b_evaluations),
        iterations_mean=its / max(member_steps, 1),
        iterations_max=int(runner.iterations_max),
        residual_max=float(runner.residual_max),
        wall_time=wall,
        compile_time=float(compile_time),
        runner=runner.label,
        threads=threads,
    )


def failure_fields(
    fails: MemberFailures, batch: tuple[int, ...]
) -> tuple[Array, dict[tuple[int, ...], str]]:
    """:attr:`Solution.failed_step` and :attr:`Solution.failure_reasons` of a failure record
    (flat member indices) for an ensemble of shape ``batch``."""
    failed_step = fails.step.reshape(batch) if batch else np.asarray(fails.step[0])
    reasons = {
        (tuple(int(i) for i in np.unravel_index(int(m), batch)) if batch else ()): fails.reason(
            int(m)
        )
        for m in fails.failed
    }
    return failed_step, reasons


def solution(r: OpenRun, outcome: _Outcome, stats: SolveStats) -> Solution:
    """The :class:`Solution` of a run that ended: every saved state (in memory), or the first
    and the last state (streamed to a file)."""
    failed_step, reasons = failure_fields(r.runner.failures, r.batch)
    common: dict[str, Any] = {
        "stats": stats,
        "success": outcome.status == RUN_FINISHED,
        "status": outcome.status,
        "message": outcome.message,
        "t0": r.t0,
        "dt": r.dt,
        "n_steps": r.grid.k_final,
        "failed_step": failed_step,
        "failure_reasons": reasons,
    }
    if r.memory:
        assert isinstance(r.writer, MemoryWriter)
        ts, ys = r.writer.arrays()
        diag = r.accumulator.result() if r.diagnostics else None
        return Solution(ts=ts, ys=ys, diagnostics=diag, **common)
    first = r.start
    y_last, _ = r.runner.state()
    t_first = r.t0 + first.step * r.dt
    if r.runner.k == first.step:
        ts, ys = np.array([t_first]), first.y[None]
    else:
        ts = np.array([t_first, r.t0 + r.runner.k * r.dt])
        ys = np.stack([first.y, y_last.reshape(r.shape)])
    return Solution(ts=ts, ys=ys, diagnostics=r.accumulator.result(), **common)
