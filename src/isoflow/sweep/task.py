"""One task: build its members' ensemble, run (or resume) it into ``tasks/<id>.h5``, summarize.

:func:`run_task` is what a dask worker executes; it imports no dask. A task is idempotent:
done (summary present) it returns the summary; partial (a result file with a checkpoint) it
resumes bit for bit with :func:`isoflow.io.resume`; otherwise it starts afresh.
"""

from __future__ import annotations

import fcntl
import os
import signal
import socket
import threading
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import IsoflowError, ModelChangedError
from .._solve import Solution, solve
from .files import read_json, task_paths, write_json_atomic
from .spec import Member, SweepSpec, Task, canonical_json

__all__ = ["build_member", "build_task", "member_run", "run_task", "watch_client"]

Array = Any


def build_member(
    spec: SweepSpec, member: Member, _made: dict[str, tuple[Any, Any]] | None = None
) -> tuple[Any, Array]:
    """``(problem, y0)`` of one member: the model's, then perturbed if the sweep says so.

    With ``perturb = eps`` the initial state is ``project(y0 + eps |y0| R / |R|)`` where ``R``
    is a random element of the space drawn from the member's seed (norms are Frobenius norms
    over all entries).
    """
    key = canonical_json(member.params)
    if _made is not None and key in _made:  # members differing only in the perturbation seed
        problem, y0 = _made[key]
    else:
        problem, y0 = spec.model_spec().make(member.params)
        if _made is not None:
            _made[key] = (problem, y0)
    y0 = np.array(y0)
    if spec.perturb is not None:
        alg = problem.algebra
        R = np.asarray(alg.random(np.random.default_rng(member.seed)))
        y0 = np.asarray(alg.project(y0 + spec.perturb * np.linalg.norm(y0) * R / np.linalg.norm(R)))
    return problem, y0


def _method(spec: SweepSpec) -> Any:
    """The sweep's method with its solver (the registry's, as :func:`~isoflow.registry.build`)."""
    from ..registry import METHODS, make_method, make_solver

    run = spec.run
    solver = None
    if METHODS[run["method"]].implicit:
        solver = make_solver(run["solver"], rtol=run["rtol"], anderson=run.get("anderson", 0))
    return make_method(run["method"], solver)


def build_task(spec: SweepSpec, task: Task) -> tuple[Any, Array, Any, dict[str, Any]]:
    """``(problem, Y, method, solve_kwargs)`` of a task: ``Y`` stacks its members' states.

    The members of a task differ only in initial-data parameters
    (:attr:`isoflow.registry.ModelSpec.initial`), so the first member's problem is every
    member's.
    """
    problem = None
    states = []
    made: dict[str, tuple[Any, Any]] = {}
    for m in task.members:
        p, y0 = build_member(spec, m, made)
        problem = p if problem is None else problem
        states.append(y0)
    run = spec.run
    kwargs = {k: run[k] for k in ("t0", "dt", "n_steps", "save_every")}
    return problem, np.stack(states), _method(spec), kwargs


def member_run(spec: SweepSpec, i: int, **solve_kwargs: Any) -> Solution:
    """Member ``i`` of the sweep as its own serial run (in memory, ``throw=False``).

    A sweep's stored states of the member equal this run's saved states bit for bit.
    """
    problem, y0 = build_member(spec, spec.members[i])
    run = spec.run
    kwargs = {k: run[k] for k in ("t0", "dt", "n_steps", "save_every")}
    kwargs = kwargs | {"progress": False, "throw": False} | solve_kwargs
    return solve(problem, _method(spec), y0, **kwargs)


# ---- the worker side ---------------------------------------------------------------------------

_watching: set[int] = set()


def watch_client(pid: int, interval: float = 0.25) -> None:
    """End this process (and its parent, a dask nanny) when process ``pid`` is gone.

    The workers of a sweep's own ``LocalCluster`` run this so that they die with the client
    (``kill -9`` of ``isoflow sweep``) instead of finishing orphaned tasks. Idempotent.
    """
    if pid in _watching or pid == os.getpid():
        return
    _watching.add(pid)

    def loop() -> None:
        while True:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                parent = os.getppid()
                if parent not in (1, pid):
                    try:
                        os.kill(parent, signal.SIGKILL)
                    except OSError:
                        pass
                os._exit(3)
            except PermissionError:  # pragma: no cover - pid reused by another user
                os._exit(3)
            time.sleep(interval)

    threading.Thread(target=loop, name="isoflow-sweep-watch", daemon=True).start()


def _log(path: Path, text: str) -> None:
    stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    with path.open("a") as fh:
        fh.write(f"{stamp} [{socket.gethostname()} pid {os.getpid()}] {text}\n")


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on ``path`` (waits while another worker holds it)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a+") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            fh.seek(0)
            fh.truncate()
            fh.write(f"{os.getpid()}\n")
            fh.flush()
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def _per_member(value: Any, m: int) -> list[float]:
    arr = np.asarray(value, dtype=float)
    return [float(v) for v in np.broadcast_to(arr.reshape(-1) if arr.size == m else arr, (m,))]


def _summary(spec: SweepSpec, task: Task, sol: Solution, problem: Any, Y: Array) -> dict:
    from ..diagnostics import series

    m = len(task.members)
    failed = np.asarray(sol.failed_step).reshape(-1)
    if failed.size != m:
        failed = np.broadcast_to(failed, (m,))
    reasons = {int(k[0]) if k else 0: v for k, v in sol.failure_reasons.items()}
    drifts: dict[str, list[float]] = {}
    d = sol.diagnostics
    if d is not None:
        for name in (
            "casimir_drift",
            "max_distance",
            "hamiltonian_drift",
            "hamiltonian_relative_drift",
            "lyapunov_max_decrease",
        ):
            v = getattr(d, name)
            if v is not None:
                drifts[name] = _per_member(v, m)
        for name, v in d.invariant_drift.items():
            drifts[f"{name}_drift"] = _per_member(v, m)
    shapes = {
        name: {"shape": list(np.shape(v)[2:]), "dtype": str(np.asarray(v).dtype)}
        for name, v in series(problem, Y[None]).items()
    }
    return {
        "id": task.id,
        "members": [mem.index for mem in task.members],
        "status": ["failed" if f >= 0 else "finished" for f in failed],
        "failed_step": [int(f) for f in failed],
        "message": [reasons.get(j, "") for j in range(m)],
        "run_message": sol.message,
        "drifts": drifts,
        "state_shape": list(Y.shape[1:]),
        "state_dtype": str(Y.dtype),
        "series": shapes,
        "n_saved": int(np.shape(sol.ts)[0]) if sol.ts is not None else None,
        "stats": {
            k: (float(v) if isinstance(v, int | float | np.number) else None)
            for k, v in vars(sol.stats).items()
            if isinstance(v, int | float | np.number)
        },
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "finished_at": time.time(),
    }


def run_task(
    spec: SweepSpec,
    task_id: str,
    directory: str | os.PathLike[str],
    *,
    watch_pid: int | None = None,
) -> dict[str, Any]:
    """Run one task of ``spec`` into ``directory/tasks`` and return its summary.

    Parameters
    ----------
    spec : SweepSpec
    task_id : str
    directory : path
        The sweep directory (shared by client and workers).
    watch_pid : int, optional
        End this process when process ``watch_pid`` (the client of a local cluster) is gone.

    Returns
    -------
    dict
        The summary also written to ``tasks/<id>.json`` (per member: status, failed step,
        message, drifts; the run's statistics).

    Notes
    -----
    BLAS and numba run one thread each inside the task. A task whose summary exists is not
    run again; one whose result file holds a checkpoint is resumed.
    """
    from .. import io
    from ..threads import thread_limits

    started = time.perf_counter()
    if watch_pid is not None:
        watch_client(watch_pid)
    task = spec.task_of(task_id)
    paths = task_paths(directory, task.id)
    done = read_json(paths.json)
    if done is not None:
        return dict(done)
    paths.h5.parent.mkdir(parents=True, exist_ok=True)
    with _locked(paths.lock), thread_limits(blas=1, numba=1):
        done = read_json(paths.json)  # finished by another worker while we waited
        if done is not None:
            return dict(done)
        try:
            problem, Y, method, kwargs = build_task(spec, task)
            sol = None
            if paths.h5.exists():
                try:
                    sol = io.resume(
                        paths.h5,
                        problem=problem,
                        method=method,
                        progress=False,
                        throw=False,
                        chunk_rows=spec.chunk_rows,
                        flush_seconds=spec.flush_seconds,
                    )
                    _log(paths.log, f"resumed {paths.h5.name}")
                except ModelChangedError:
                    raise  # the sweep's other tasks ran the recorded model: not started again
                except (IsoflowError, OSError) as exc:  # no checkpoint, unreadable file
                    _log(paths.log, f"cannot resume ({exc}); starting again")
                    sol = None
            if sol is None:
                _log(paths.log, f"start: {len(task.members)} member(s)")
                writer = io.HDF5Writer(
                    paths.h5,
                    spec.config(task.members[0]),
                    chunk_rows=spec.chunk_rows,
                    flush_seconds=spec.flush_seconds,
                    force=True,  # starting again replaces a file that did not resume
                )
                sol = solve(
                    problem, method, Y, progress=False, throw=False, writer=writer, **kwargs
                )
            summary = _summary(spec, task, sol, problem, Y)
            summary["task_seconds"] = time.perf_counter() - started
            write_json_atomic(paths.json, summary)
            _log(paths.log, f"done: {sol.message}")
            return summary
        except BaseException as exc:
            _log(paths.log, "error: " + "".join(traceback.format_exception(exc)).rstrip())
            raise
