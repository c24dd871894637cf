"""Running a sweep on a dask.distributed cluster (a local one by default): :func:`run`.

The client checks each task before it submits it (a task whose summary and result file are
valid is skipped) and keeps a bounded number of tasks in flight, refilled as they finish, so
that neither the client's memory nor the scheduler's graph grows with the sweep; each task
carries only its own members (:meth:`SweepSpec.for_task`).
"""

from __future__ import annotations

import asyncio
import itertools
import os
import sys
import time
import uuid
import warnings
from collections.abc import Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from .files import read_summary, write_manifest
from .spec import SweepError, SweepSpec, Task, read_spec, require_extra
from .task import run_task, task_layouts, watch_client

__all__ = ["CONNECT_TIMEOUT", "SweepResult", "run"]

#: Environment of the worker processes of a local cluster: one BLAS/OpenMP thread each.
WORKER_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}

#: Seconds to wait for a scheduler given by address to answer as a dask scheduler.
CONNECT_TIMEOUT = 30.0

#: Tasks in flight per worker thread (at least :data:`MIN_IN_FLIGHT` in all): enough to keep
#: every worker busy while the client refills, few enough that the graph stays small.
IN_FLIGHT_PER_THREAD = 2
MIN_IN_FLIGHT = 8

#: Seconds between progress lines when stderr is not a terminal (a log file).
PROGRESS_SECONDS = 30.0


@dataclass
class SweepResult:
    """What :func:`run` did.

    Attributes
    ----------
    path : Path
        The sweep directory.
    tasks : int
        Tasks of the sweep.
    computed, skipped : list of str
        Tasks run (or resumed) now, and tasks already done before.
    errors : dict
        Task id -> the one-line error of a task that raised (its members are not done).
    redone : dict
        Task id -> why its summary did not count (damaged, edited, its result file deleted,
        truncated or changed): the task was run again.
    failed_members : list of int
        Members whose solve failed (recorded with step and reason; the others finished).
    """

    path: Path
    tasks: int
    computed: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    errors: dict[str, str] = field(default_factory=dict)
    redone: dict[str, str] = field(default_factory=dict)
    failed_members: list[int] = field(default_factory=list)

    @property
    def success(self) -> bool:
        """Every task done and every member finished."""
        return not self.errors and not self.failed_members

    def dataset(self, **kwargs: Any) -> Any:
        """The results as one xarray Dataset (:func:`isoflow.sweep.open_sweep`)."""
        from .results import open_sweep

        return open_sweep(self.path, **kwargs)

    def __str__(self) -> str:
        done = len(self.computed) + len(self.skipped)
        text = (
            f"{self.path}: {done} of {self.tasks} tasks done ({len(self.computed)} run now, "
            f"{len(self.skipped)} already done)"
        )
        if self.failed_members:
            text += f"; {len(self.failed_members)} member(s) failed"
        if self.errors:
            text += f"; {len(self.errors)} task(s) raised"
        return text


def _count(n: int, what: str, plural: str | None = None) -> str:
    return f"{n} {what if n == 1 else plural or what + 's'}"


def _one_line(exc: BaseException) -> str:
    msg = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


# ---- progress ----------------------------------------------------------------------------------


class _Progress:
    """Tasks done of all and members failed, on ``stream``: a bar on a terminal, else a line
    every :data:`PROGRESS_SECONDS` and one at the end."""

    def __init__(self, total: int, enabled: bool, stream: TextIO | None = None) -> None:
        self.total, self.done, self.failed = total, 0, 0
        self.enabled = enabled
        self.stream = sys.stderr if stream is None else stream
        self.bar: Any = None
        self.last = time.monotonic()
        if enabled and self.stream.isatty():
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, unit="task", file=self.stream)

    def say(self, text: str) -> None:
        """One line (above the bar)."""
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def add(self, failed: int) -> None:
        """One more task done, with ``failed`` failed members."""
        self.done += 1
        self.failed += failed
        if self.bar is not None:
            self.bar.set_postfix_str(f"{self.failed} member(s) failed", refresh=False)
            self.bar.update(1)
        elif self.enabled and time.monotonic() - self.last >= PROGRESS_SECONDS:
            self.line()

    def line(self) -> None:
        self.last = time.monotonic()
        self.say(f"tasks done {self.done}/{self.total}, members failed {self.failed}")

    def close(self, final: bool = True) -> None:
        """End the bar; ``final``: with a last line of the counts (not after an error)."""
        if self.bar is not None:
            self.bar.close()
        elif self.enabled and final:
            self.line()


# ---- the cluster -------------------------------------------------------------------------------


def _capped_workers(workers: int | None) -> int:
    """Worker processes of a local cluster: ``workers``, at most the cores available."""
    from ..threads import available_cores

    cores = available_cores()
    if workers is None:
        return cores
    if workers > cores:
        warnings.warn(
            f"workers = {workers} is more than the {cores} cores available: starting {cores} "
            "(one single-threaded process per core; more only compete for them)",
            RuntimeWarning,
            stacklevel=3,
        )
        return cores
    return workers


async def _identity(address: str, timeout: float) -> dict[str, Any]:
    """What the server at ``address`` says it is (a dask ``identity`` request)."""
    from distributed.comm import connect

    comm = await asyncio.wait_for(connect(address, timeout=timeout), timeout)
    try:
        await asyncio.wait_for(comm.write({"op": "identity", "reply": True}), timeout)
        reply = await asyncio.wait_for(comm.read(), timeout)
    finally:
        comm.abort()
    return reply if isinstance(reply, dict) else {}


def _probe(address: str, timeout: float) -> None:
    """Check within ``timeout`` seconds that ``address`` is a dask scheduler.

    ``distributed.Client`` waits without end for a peer that accepts the connection and never
    answers (its own timeout does not cover the handshake) and may try to allocate whatever
    length a foreign protocol's bytes spell; this asks first, on a thread of its own (a
    running event loop, as in Jupyter, stays untouched).
    """
    with ThreadPoolExecutor(1) as pool:
        try:
            kind = pool.submit(asyncio.run, _identity(address, timeout)).result().get("type")
        except TimeoutError:
            raise SweepError(
                f"no dask scheduler answered at {address} within {timeout:g} s (is it a "
                "scheduler's address? --connect-timeout waits longer)"
            ) from None
        except OSError as exc:
            raise SweepError(f"cannot connect to a dask scheduler at {address}: {exc}") from None
        except Exception as exc:
            raise SweepError(
                f"{address} does not answer as a dask scheduler ({_one_line(exc)[:200]})"
            ) from None
    if kind != "Scheduler":
        raise SweepError(f"{address} answers as a dask {kind or 'peer'}, not a scheduler")


@contextmanager
def _attach(address: str, timeout: float) -> Iterator[Any]:
    """A client of the running scheduler at ``address``."""
    from distributed import Client

    _probe(address, timeout)
    try:
        client = Client(address, timeout=timeout)
    except Exception as exc:
        raise SweepError(
            f"cannot connect to the dask scheduler at {address}: {_one_line(exc)}"
        ) from None
    with client:
        yield client


@contextmanager
def _cluster(
    client: Any, scheduler: str | None, workers: int, retries: int, timeout: float
) -> Iterator[tuple[Any, int | None]]:
    """``(client, pid the workers watch)``: the given client, one attached to ``scheduler``,
    or a new ``LocalCluster`` of ``workers`` single-threaded processes (BLAS pinned)."""
    if client is not None:
        yield client, None
        return
    if scheduler is not None:
        with _attach(scheduler, timeout) as c:
            yield c, None
        return
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": int(retries)}):
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env=dict(WORKER_ENV),
            silence_logs=50,
        )
    try:
        with Client(cluster) as c:
            pid = os.getpid()
            c.run(watch_client, pid)
            yield c, pid
    finally:
        cluster.close()


# ---- submitting --------------------------------------------------------------------------------


def _failed(summary: Mapping[str, Any]) -> list[int]:
    return [
        i for i, s in zip(summary["members"], summary["status"], strict=True) if s != "finished"
    ]


def _to_run(
    spec: SweepSpec, directory: Path, result: SweepResult, progress: _Progress
) -> Iterator[Task]:
    """The tasks that are not done, checked one by one as they are needed; done ones are
    recorded as skipped (a summary that does not hold is recorded in ``result.redone``)."""
    for t in spec.tasks:
        entry = {"id": t.id, "members": [m.index for m in t.members]}
        try:
            summary = read_summary(directory, entry, verify=True)
        except SweepError as exc:
            result.redone[t.id] = str(exc)
            progress.say(f"redoing task {t.id}: {exc}")
            summary = None
        if summary is None:
            yield t
            continue
        result.skipped.append(t.id)
        failed = _failed(summary)
        result.failed_members += failed
        progress.add(len(failed))


def _in_flight(client: Any) -> int:
    return max(MIN_IN_FLIGHT, IN_FLIGHT_PER_THREAD * sum(client.nthreads().values()))


def _run_tasks(
    client: Any,
    spec: SweepSpec,
    directory: Path,
    todo: Iterator[Task],
    watch: int | None,
    result: SweepResult,
    progress: _Progress,
) -> None:
    """Submit ``todo`` with a bounded number in flight and collect what the tasks return."""
    from distributed import as_completed

    running: dict[Any, str] = {}
    done = as_completed()

    def refill() -> None:
        for t in itertools.islice(todo, max(0, _in_flight(client) - len(running))):
            fut = client.submit(
                run_task,
                spec.for_task(t),
                t.id,
                str(directory),
                watch_pid=watch,
                key=f"isoflow-sweep-{t.id}-{uuid.uuid4().hex[:8]}",
                pure=False,
            )
            running[fut] = t.id
            done.add(fut)

    refill()
    for fut in done:
        tid = running.pop(fut)
        failed: list[int] = []
        try:
            failed = _failed(fut.result())
            result.computed.append(tid)
        except Exception as exc:
            result.errors[tid] = _one_line(exc)
        result.failed_members += failed
        progress.add(len(failed))
        refill()


def _check_arguments(
    client: Any, scheduler: str | None, workers: Any, retries: Any, timeout: Any
) -> None:
    if client is not None and scheduler is not None:
        raise SweepError("give a client or a scheduler address, not both")
    if workers is not None and (client is not None or scheduler is not None):
        raise SweepError("workers sets the size of the local cluster: not with client or scheduler")
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise SweepError(f"retries must be an integer >= 0, got {retries!r}")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 1
    ):
        raise SweepError(f"workers must be a positive integer, got {workers!r}")
    if isinstance(timeout, bool) or not isinstance(timeout, int | float) or not timeout > 0:
        raise SweepError(f"connect_timeout must be a positive number of seconds, got {timeout!r}")


def run(
    spec: SweepSpec | str | os.PathLike[str] | Mapping[str, Any],
    out: str | os.PathLike[str] | None = None,
    *,
    client: Any = None,
    scheduler: str | None = None,
    workers: int | None = None,
    retries: int = 2,
    connect_timeout: float = CONNECT_TIMEOUT,
    progress: bool = True,
) -> SweepResult:
    """Run a sweep: every task one batched :func:`isoflow.solve` in a dask worker.

    Parameters
    ----------
    spec : SweepSpec, path or mapping
        The sweep (:func:`isoflow.sweep.read_spec` reads a path or a mapping).
    out : path, optional
        The sweep directory (default: the file's ``out``). Shared by the client and the
        workers (on a cluster: a shared file system).
    client : distributed.Client, optional
        Run on this client's cluster (not closed).
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``) to attach to.
    workers : int, optional
        Worker processes of the local cluster (default: one per core; more than the cores
        available are capped at them, with a ``RuntimeWarning``).
    retries : int
        Worker deaths a task survives (dask's ``distributed.scheduler.allowed-failures``,
        set for the local cluster; a running scheduler keeps its own setting).
    connect_timeout : float
        Seconds to wait for ``scheduler`` to answer as a dask scheduler.
    progress : bool
        Tasks done and members failed on stderr: a bar on a terminal, else a line every 30 s
        and one at the end; and a line for each task whose summary did not hold.

    Returns
    -------
    SweepResult

    Raises
    ------
    MissingExtraError
        dask, distributed or xarray is not installed (``pip install 'isoflow[sweep]'``).
    SweepError
        A bad sweep (before anything runs), no output directory, both ``client`` and
        ``scheduler``, a scheduler that does not answer.
    ResultWriteError
        The sweep directory cannot be written (naming the path).
    """
    require_extra("dask", "distributed", "xarray")
    if not isinstance(spec, SweepSpec):
        spec = read_spec(spec)
    if out is None:
        if spec.out is None:
            raise SweepError("no sweep directory: give out (or out = 'DIR' in the sweep file)")
        out = spec.out
    _check_arguments(client, scheduler, workers, retries, connect_timeout)
    local = client is None and scheduler is None
    n_workers = _capped_workers(workers) if local else 0
    directory = Path(out).resolve()
    result = SweepResult(directory, len(spec.tasks))
    layouts = task_layouts(spec)
    write_manifest(directory, spec, layouts)
    bar = _Progress(len(spec.tasks), progress)
    bar.say(f"{directory}: {_count(len(spec.members), 'member')} in {_count(result.tasks, 'task')}")
    try:
        todo = _to_run(spec, directory, result, bar)
        first = next(todo, None)
        if first is not None:
            if local:
                size = _count(n_workers, "worker process", "worker processes")
                bar.say(f"starting a local cluster of {size}")
            with _cluster(client, scheduler, n_workers, retries, connect_timeout) as (c, watch):
                _run_tasks(c, spec, directory, itertools.chain([first], todo), watch, result, bar)
    except BaseException:
        bar.close(final=False)
        raise
    bar.close()
    result.failed_members.sort()
    write_manifest(directory, spec, layouts, errors=result.errors)
    return result
