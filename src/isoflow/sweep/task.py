"""One task: build its members' ensemble, run (or resume) it into ``tasks/<id>.h5``, summarize.

:func:`run_task` is what a dask worker executes; it imports no dask. A task is idempotent:
done (a valid summary, its result file unchanged) it returns the summary; partial (a result
file of this task, as its ``sweep`` mark says, with a checkpoint) it resumes bit for bit with
:func:`isoflow.io.resume`; otherwise (nothing, a damaged file, another task's file) it starts
afresh.
"""

from __future__ import annotations

import dataclasses
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
from .files import TaskPaths, file_sha256, read_summary, seal, task_paths, write_json_atomic
from .spec import Member, SweepError, SweepSpec, Task, canonical_json

__all__ = [
    "build_member",
    "build_task",
    "layout_of",
    "member_run",
    "run_task",
    "sweep_mark",
    "task_layouts",
    "watch_client",
    "with_member_ids",
]

Array = Any


def build_member(
    spec: SweepSpec, member: Member, *, cache: dict[str, tuple[Any, Any]] | None = None
) -> tuple[Any, Array]:
    """``(problem, y0)`` of one member: the model's, then perturbed if the sweep says so.

    With ``perturb = eps`` the initial state is ``project(y0 + eps |y0| R / |R|)`` where ``R``
    is a random element of the space drawn from the member's seed (norms are Frobenius norms
    over all entries).

    Parameters
    ----------
    spec : SweepSpec
    member : Member
    cache : dict, optional
        Models built so far, by their parameters: members that differ only in the
        perturbation's seed share one (filled as models are built).
    """
    key = canonical_json(member.params)
    if cache is not None and key in cache:  # members differing only in the perturbation seed
        problem, y0 = cache[key]
    else:
        problem, y0 = spec.model_spec().make(member.params)
        if cache is not None:
            cache[key] = (problem, y0)
    y0 = np.array(y0)
    if spec.perturb is not None:
        alg = problem.algebra
        R = np.asarray(alg.random(np.random.default_rng(member.seed)))
        y0 = np.asarray(alg.project(y0 + spec.perturb * np.linalg.norm(y0) * R / np.linalg.norm(R)))
    return problem, y0


def with_member_ids(problem: Any, members: list[Member]) -> Any:
    """The problem whose noise keys its members by their index in the sweep (not in the task):
    a task's ensemble then draws the increments one ensemble of the whole sweep draws
    (:class:`isoflow.noise.TransportNoise`)."""
    if getattr(problem, "noise", None) is None:
        return problem
    return dataclasses.replace(
        problem, noise=problem.noise.with_members([m.index for m in members])
    )


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

    Parameters
    ----------
    spec : SweepSpec
        The sweep.
    task : Task
        One of ``spec.tasks``.

    Returns
    -------
    problem : IsospectralProblem
        The members' problem, with the members' ids (their noise keys).
    Y : ndarray, shape (members, *shape)
        The members' initial states.
    method : Method
        The sweep's method with its solver.
    solve_kwargs : dict
        ``t0``, ``dt``, ``n_steps`` and ``save_every`` of the run.
    """
    problem = None
    states = []
    made: dict[str, tuple[Any, Any]] = {}
    seen: dict[str, Any] = {}
    # the sweep's own initial-data names (the model's are declared by the model and trusted)
    declared = set(spec.initial) - set(spec.model_spec().initial)
    for m in task.members:
        p, y0 = build_member(spec, m, cache=made)
        if problem is None:
            problem, first = p, m
        elif p is not problem and any(first.params.get(k) != m.params.get(k) for k in declared):
            _check_same_model(first, problem, states[0], m, p, y0, seen)  # must not change B
        states.append(y0)
    run = spec.run
    kwargs = {k: run[k] for k in ("t0", "dt", "n_steps", "save_every")}
    return with_member_ids(problem, list(task.members)), np.stack(states), _method(spec), kwargs


def _check_same_model(
    first: Member, problem: Any, y_first: Array, m: Member, p: Any, y0: Array,
    seen: dict[str, Any],
) -> None:  # fmt: skip
    """Raise unless member ``m``'s problem ``p`` is the task's (its first member's): the
    same state shape, and the same ``B``, Hamiltonian and diagnostics at the fingerprint's
    probe state (``seen`` keeps the first member's fingerprint). A parameter declared initial
    data (the sweep's ``initial``) that changes the model would otherwise run the member with
    the first member's ``B``.

    Raises
    ------
    SweepError
    """
    from .._fingerprint import fingerprint_changes, model_fingerprint

    differ = sorted(k for k in {*first.params, *m.params} if first.params.get(k) != m.params.get(k))
    names = ", ".join(differ) or "their parameters"
    if np.shape(y0) != np.shape(y_first):
        changes = [f"the state shape {np.shape(y0)} is not {np.shape(y_first)}"]
    else:
        if "first" not in seen:  # the task's own, once
            seen["first"] = model_fingerprint(problem, y_first[None])
        changes = fingerprint_changes(seen["first"], model_fingerprint(p, y_first[None]))
    if changes:
        raise SweepError(
            f"members {first.index} and {m.index} share a task but {names} change the model "
            f"({changes[0]}): only parameters that set the initial state alone may be listed "
            "in initial"
        )


def member_run(spec: SweepSpec, i: int, **solve_kwargs: Any) -> Solution:
    """Member ``i`` of the sweep as its own serial run (in memory, ``throw=False``).

    A sweep's stored states of the member equal this run's saved states bit for bit.

    Raises
    ------
    SweepError
        ``spec`` is not a :class:`~isoflow.sweep.SweepSpec` (read one with
        :func:`~isoflow.sweep.read_spec`), or ``i`` is not one of its members.
    """
    if not isinstance(spec, SweepSpec):
        raise SweepError(
            f"member_run needs a SweepSpec (iso.sweep.read_spec(...)), got {type(spec).__name__}"
        )
    if (
        isinstance(i, bool)
        or not isinstance(i, (int, np.integer))
        or not 0 <= i < len(spec.members)
    ):
        raise SweepError(f"member_run: no member {i!r} (the sweep has {len(spec.members)})")
    problem, y0 = build_member(spec, spec.members[i])
    problem = with_member_ids(problem, [spec.members[i]])
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

    Parameters
    ----------
    pid : int
        The process to watch (this process's own id is ignored).
    interval : float
        Seconds between two checks (default 0.25).
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


def layout_of(problem: Any, Y: Array) -> dict[str, Any]:
    """Shapes and dtypes of a member's state and saved series (``Y``: members first).

    Parameters
    ----------
    problem : IsospectralProblem
        The members' problem (which series are saved).
    Y : ndarray, shape (members, *shape)
        States, members first.

    Returns
    -------
    dict
        ``state_shape``, ``state_dtype`` and, per series, its ``shape`` and ``dtype``.
    """
    from ..diagnostics import series

    shapes = {
        name: {"shape": list(np.shape(v)[2:]), "dtype": str(np.asarray(v).dtype)}
        for name, v in series(problem, Y[None]).items()
    }
    return {"state_shape": list(Y.shape[1:]), "state_dtype": str(Y.dtype), "series": shapes}


def task_layouts(spec: SweepSpec) -> dict[str, dict[str, Any] | None]:
    """Task id -> :func:`layout_of` its members (``None`` where the model cannot be built).

    One member is built per group of tasks that share a problem (the same parameters but the
    initial-data ones), so that the readers know the shape of a task's results before it ran.

    Parameters
    ----------
    spec : SweepSpec
        The sweep.

    Returns
    -------
    dict of str to (dict or None)
    """
    out: dict[str, dict[str, Any] | None] = {}
    known: dict[str, dict[str, Any] | None] = {}
    for t in spec.tasks:
        first = t.members[0]
        group = canonical_json({k: v for k, v in first.params.items() if k not in spec.initial})
        if group not in known:
            try:
                problem, y0 = build_member(spec, first)
                known[group] = layout_of(problem, y0[None])
            except Exception:  # the task's own run reports why (status "error")
                known[group] = None
        out[t.id] = known[group]
    return out


def _summary(spec: SweepSpec, task: Task, sol: Solution, problem: Any, Y: Array) -> dict:
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
    return {
        "id": task.id,
        "members": [mem.index for mem in task.members],
        "status": ["failed" if f >= 0 else "finished" for f in failed],
        "failed_step": [int(f) for f in failed],
        "message": [reasons.get(j, "") for j in range(m)],
        "run_message": sol.message,
        "drifts": drifts,
        **layout_of(problem, Y),
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


def sweep_mark(task: Task) -> dict[str, str]:
    """What a task's result file records (config key ``sweep``) to name its task."""
    return {"task": task.id, "digest": task.digest}


def _done(directory: str | os.PathLike[str], task: Task, log: Path) -> dict[str, Any] | None:
    """The task's valid summary (result file verified), or ``None`` (an invalid one removed)."""
    entry = {"id": task.id, "members": [m.index for m in task.members]}
    try:
        return read_summary(directory, entry, verify=True)
    except SweepError as exc:
        _log(log, f"redoing the task: {exc}")
        task_paths(directory, task.id).json.unlink(missing_ok=True)
        return None


def _resumed(spec: SweepSpec, task: Task, paths: TaskPaths, problem: Any, method: Any) -> Any:
    """The task continued from its result file, or ``None`` if that file cannot be continued
    (no checkpoint, unreadable, or another task's)."""
    from .. import io

    if not paths.h5.exists():
        return None
    try:
        mark = io.info(paths.h5)["config"].get("sweep")
        if mark != sweep_mark(task):
            _log(paths.log, f"{paths.h5.name} is not this task's result file; starting again")
            return None
        sol = io.resume(
            paths.h5,
            problem=problem,
            method=method,
            progress=False,
            throw=False,
            chunk_rows=spec.chunk_rows,
            flush_seconds=spec.flush_seconds,
        )
    except ModelChangedError as exc:  # the sweep's other tasks ran the recorded model
        raise ModelChangedError(
            f"{paths.h5}: the model changed since this task started ({'; '.join(exc.changes)}); "
            "resuming would mix two models in one task: restore the model, or delete this "
            "file to run the task again from its start with this one",
            changes=exc.changes,
        ) from exc
    except (IsoflowError, OSError) as exc:  # no checkpoint, unreadable file
        _log(paths.log, f"cannot resume ({exc}); starting again")
        return None
    _log(paths.log, f"resumed {paths.h5.name}")
    return sol


def _started(spec: SweepSpec, task: Task, paths: TaskPaths) -> tuple[Any, Array, Solution]:
    """``(problem, Y, solution)`` of the task run from its start (or resumed)."""
    problem, Y, method, kwargs = build_task(spec, task)
    sol = _resumed(spec, task, paths, problem, method)
    if sol is None:
        _log(paths.log, f"start: {len(task.members)} member(s)")
        writer = _writer(spec, task, paths.h5)
        sol = solve(problem, method, Y, progress=False, throw=False, writer=writer, **kwargs)
    return problem, Y, sol


def _writer(spec: SweepSpec, task: Task, path: Path) -> Any:
    """The result file of a task's run (replacing one that did not resume)."""
    from .. import io

    return io.HDF5Writer(
        path,
        spec.config(task.members[0]) | {"sweep": sweep_mark(task)},
        chunk_rows=spec.chunk_rows,
        flush_seconds=spec.flush_seconds,
        force=True,
    )


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
        message, drifts; the run's statistics; the size and SHA-256 of the result file; the
        SHA-256 of the summary itself).

    Notes
    -----
    BLAS and numba run one thread each inside the task. A task with a valid summary whose
    result file is unchanged is not run again; otherwise a result file of this task with a
    checkpoint is resumed, and anything else started afresh.
    """
    from ..threads import thread_limits

    started = time.perf_counter()
    if watch_pid is not None:
        watch_client(watch_pid)
    task = spec.task_of(task_id)
    paths = task_paths(directory, task.id)
    paths.h5.parent.mkdir(parents=True, exist_ok=True)
    with _locked(paths.lock), thread_limits(blas=1, numba=1):
        done = _done(directory, task, paths.log)
        if done is not None:
            return done
        try:
            problem, Y, sol = _started(spec, task, paths)
            summary = _summary(spec, task, sol, problem, Y)
            summary["task_seconds"] = time.perf_counter() - started
            summary["file_size"] = paths.h5.stat().st_size
            summary["file_sha256"] = file_sha256(paths.h5)
            summary = seal(summary)
            write_json_atomic(paths.json, summary)
            _log(paths.log, f"done: {sol.message}")
            return summary
        except BaseException as exc:
            _log(paths.log, "error: " + "".join(traceback.format_exception(exc)).rstrip())
            raise
