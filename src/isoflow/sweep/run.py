"""Running a sweep on a dask.distributed cluster (a local one by default)."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .files import read_json, task_paths, write_manifest
from .spec import SweepError, SweepSpec, read_spec
from .task import run_task, watch_client

__all__ = ["SweepResult", "sweep"]

#: Environment of the worker processes of a local cluster: one BLAS/OpenMP thread each.
WORKER_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


@dataclass
class SweepResult:
    """What :func:`sweep` did.

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
    failed_members : list of int
        Members whose solve failed (recorded with step and reason; the others finished).
    """

    path: Path
    tasks: int
    computed: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    errors: dict[str, str] = field(default_factory=dict)
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


def _one_line(exc: BaseException) -> str:
    msg = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


@contextmanager
def _cluster(
    client: Any, scheduler: str | None, workers: int | None, retries: int
) -> Iterator[tuple[Any, int | None]]:
    """``(client, pid the workers watch)``: the given client, one attached to ``scheduler``,
    or a new ``LocalCluster`` (one single-threaded process per core, BLAS pinned)."""
    if client is not None:
        yield client, None
        return
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        with Client(scheduler) as c:
            yield c, None
        return
    from ..threads import available_cores

    n = workers if workers is not None else available_cores()
    with dask.config.set({"distributed.scheduler.allowed-failures": int(retries)}):
        cluster = LocalCluster(
            n_workers=int(n),
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


def sweep(
    spec: SweepSpec | str | os.PathLike[str] | Mapping[str, Any],
    out: str | os.PathLike[str] | None = None,
    *,
    client: Any = None,
    scheduler: str | None = None,
    workers: int | None = None,
    retries: int = 2,
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
        Worker processes of the local cluster (default: one per core).
    retries : int
        Worker deaths a task survives (dask's ``distributed.scheduler.allowed-failures``,
        set for the local cluster; a running scheduler keeps its own setting).
    progress : bool
        A progress bar over tasks (tqdm, on stderr).

    Returns
    -------
    SweepResult

    Raises
    ------
    SweepError
        A bad sweep (before anything runs), no output directory, both ``client`` and
        ``scheduler``.
    """
    if not isinstance(spec, SweepSpec):
        spec = read_spec(spec)
    if out is None:
        if spec.out is None:
            raise SweepError("no sweep directory: give out (or out = 'DIR' in the sweep file)")
        out = spec.out
    if client is not None and scheduler is not None:
        raise SweepError("give a client or a scheduler address, not both")
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise SweepError(f"retries must be an integer >= 0, got {retries!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)):
        raise SweepError(f"workers must be a positive integer, got {workers!r}")
    if workers is not None and workers < 1:
        raise SweepError(f"workers must be a positive integer, got {workers!r}")
    directory = Path(out).resolve()
    write_manifest(directory, spec)
    result = SweepResult(directory, len(spec.tasks))
    todo = []
    for t in spec.tasks:
        if task_paths(directory, t.id).json.exists():
            result.skipped.append(t.id)
        else:
            todo.append(t)
    if todo:
        with _cluster(client, scheduler, workers, retries) as (c, watch):
            from distributed import as_completed

            futures = {
                c.submit(
                    run_task,
                    spec,
                    t.id,
                    str(directory),
                    watch_pid=watch,
                    key=f"isoflow-sweep-{t.id}-{uuid.uuid4().hex[:8]}",
                    pure=False,
                ): t.id
                for t in todo
            }
            bar = None
            if progress:
                from tqdm.auto import tqdm

                bar = tqdm(total=len(spec.tasks), initial=len(result.skipped), unit="task")
            try:
                for fut in as_completed(futures):
                    tid = futures[fut]
                    try:
                        fut.result()
                        result.computed.append(tid)
                    except Exception as exc:
                        result.errors[tid] = _one_line(exc)
                    if bar is not None:
                        bar.update(1)
            finally:
                if bar is not None:
                    bar.close()
    for t in spec.tasks:
        summary = read_json(task_paths(directory, t.id).json)
        if summary is None:
            continue
        result.failed_members += [
            i for i, s in zip(summary["members"], summary["status"], strict=True) if s != "finished"
        ]
    result.failed_members.sort()
    write_manifest(directory, spec, errors=result.errors)
    return result
