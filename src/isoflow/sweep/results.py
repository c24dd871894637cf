"""Reading a sweep directory: :func:`open_sweep` (one lazy xarray Dataset) and :func:`status`."""

from __future__ import annotations

import json
import operator
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._save_grid import SaveGrid
from .files import MEMBER_STATUSES, read_manifest, read_summary, task_paths
from .spec import SweepError, require_extra

__all__ = ["open_sweep", "read_task", "saved_times", "status"]


def saved_times(run: Mapping[str, Any]) -> np.ndarray:
    """The saved times of a sweep's time grid (the start, every ``save_every`` steps and the
    last).

    Parameters
    ----------
    run : mapping
        The sweep's run settings (``t0``, ``dt``, ``n_steps``, ``save_every``).

    Returns
    -------
    ndarray, shape (n_saved,)
    """
    steps = SaveGrid(int(run["save_every"]), int(run["n_steps"])).saved_steps()
    return float(run["t0"]) + steps.astype(float) * float(run["dt"])


def _on_grid(arr: np.ndarray, n_on: int, n_grid: int) -> np.ndarray:
    """A task file's rows (time first) on the sweep's ``n_grid`` saved times.

    The first ``n_on`` rows are on the grid. A run whose members all failed ends early, with
    its last good state as its last row (off the grid if it fell between saves); the missing
    times hold that state, as a failed member of a run that goes on is frozen at it.
    """
    if n_on >= n_grid:
        return arr[:n_grid]
    return np.concatenate([arr[:n_on], np.repeat(arr[-1:], n_grid - n_on, axis=0)])


def read_task(
    path: str | os.PathLike[str], task_id: str, layout: Mapping[str, Any], n_members: int
) -> dict[str, np.ndarray]:
    """Everything :func:`open_sweep` takes from one task file, member first.

    ``y`` ``(members, time, *shape)``, ``y_final`` ``(members, *shape)`` and each diagnostic
    series ``(members, time, ...)`` (``invariants/<name>`` as ``invariants_<name>``, likewise
    ``observables/<name>``), on the sweep's time grid. One read of the file
    (:func:`isoflow.io.load`, every row checked).

    Parameters
    ----------
    path : str or os.PathLike
        The task's result file.
    task_id : str
        The task's id (checked against the file's ``sweep`` mark).
    layout : mapping
        The layout the manifest records for the task (:func:`~isoflow.sweep.task.layout_of`).
    n_members : int
        The task's number of members.

    Returns
    -------
    dict of str to ndarray

    Raises
    ------
    SweepError
        The file is not task ``task_id``'s result (its ``sweep`` mark), or does not hold
        ``n_members`` members of the ``layout`` the sweep recorded.
    ResultFileError
        The file is damaged.
    """
    from .. import io

    run = io.load(path)
    mark = run.config.get("sweep")
    if not isinstance(mark, dict) or mark.get("task") != task_id:
        raise SweepError(f"{path}: not the result file of task {task_id} (run the sweep again)")
    meta = run.meta
    grid = SaveGrid(int(meta["save_every"]), int(meta["n_steps"]))
    n_grid = grid.rows(fresh=True)
    off_grid = not grid.is_save(run.step)  # the last good state of a failed run
    n_on = len(run.ts) - int(off_grid)
    expect = {"y": (n_members, *layout["state_shape"])}
    expect |= {
        name.replace("/", "_"): (n_members, *s["shape"]) for name, s in layout["series"].items()
    }
    arrays = {"y": run.ys, **{k.replace("/", "_"): v for k, v in run.series.items()}}
    out: dict[str, np.ndarray] = {}
    for name, shape in expect.items():
        arr = arrays.get(name)
        if arr is None or tuple(arr.shape[1:]) != shape:
            got = None if arr is None else tuple(arr.shape[1:])
            raise SweepError(f"{path}: {name} has shape {got} per saved state, not {shape}")
        out[name] = np.moveaxis(_on_grid(arr, n_on, n_grid), 0, 1)
    out["y_final"] = out["y"][:, -1]
    return out


def _select(where: Any, params: dict[str, Any], seed: Any) -> bool:
    if where is None:
        return True
    values = params | ({} if seed is None else {"seed": seed})
    if callable(where):
        return bool(where(values))
    return all(values.get(k) == v for k, v in where.items())


def _coord(values: list[Any]) -> np.ndarray:
    if all(isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=bool)
    if all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=np.int64)
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=float)
    return np.asarray([v if isinstance(v, str) else json.dumps(v) for v in values], dtype=object)


@dataclass
class _TaskState:
    """A task of a sweep directory as the readers see it."""

    entry: dict[str, Any]
    summary: dict[str, Any] | None
    damage: str  # why a summary present does not count ("" if none)
    layout: dict[str, Any] | None


def _task_states(
    directory: str | os.PathLike[str], man: dict[str, Any], verify: bool
) -> list[_TaskState]:
    out = []
    for t in man["tasks"]:
        try:
            summary, damage = read_summary(directory, t, verify=verify), ""
        except SweepError as exc:
            summary, damage = None, f"{exc}; run the sweep again to redo the task"
        layout: dict[str, Any] | None
        if summary is not None:
            layout = {k: summary[k] for k in ("state_shape", "state_dtype", "series")}
        else:
            layout = None if t["layout"] is None else man["layouts"][t["layout"]]
        out.append(_TaskState(t, summary, damage, layout))
    return out


def _member_row(state: _TaskState, j: int, errors: dict[str, str]) -> dict[str, Any]:
    tid = state.entry["id"]
    s = state.summary
    if s is not None:
        row = {"status": s["status"][j], "failed_step": s["failed_step"][j]}
        return row | {"message": s["message"][j], **{k: v[j] for k, v in s["drifts"].items()}}
    if tid in errors:
        return {"status": "error", "failed_step": -1, "message": errors[tid]}
    return {"status": "pending", "failed_step": -1, "message": state.damage}


def _common_layout(states: list[_TaskState], members: list[dict[str, Any]]) -> Any:
    """The one layout of the selected tasks' results (``None`` if none is known)."""
    seen: dict[str, dict[str, Any]] = {}
    for st in states:
        if st.layout is not None:
            first = members[st.entry["members"][0]]["params"]
            seen.setdefault(json.dumps(st.layout, sort_keys=True), first)
    if len(seen) > 1:
        shown = "; ".join(f"{tuple(json.loads(k)['state_shape'])} ({p})" for k, p in seen.items())
        raise SweepError(
            f"the members' results have different shapes ({shown}): open members of one "
            "shape at a time, e.g. open_sweep(DIR, where={...})"
        )
    return json.loads(next(iter(seen))) if seen else None


def _arrays(
    directory: str | os.PathLike[str],
    picked: list[tuple[_TaskState, list[int]]],
    layout: dict[str, Any],
    nt: int,
) -> dict[str, Any]:
    """Name -> dask array ``(member, ...)`` of the picked members: one chunk per task, read
    from its file (one read shared by every variable) or NaN for a task not done.

    The graph is written out directly (one entry per task and variable, no tokenizing of
    thousands of small collections): a sweep of 100,000 members opens in seconds.
    """
    import dask.array as da
    from dask.base import tokenize
    from dask.highlevelgraph import HighLevelGraph

    shapes = {"y": ((nt, *layout["state_shape"]), layout["state_dtype"])}
    shapes["y_final"] = (tuple(layout["state_shape"]), layout["state_dtype"])
    for name, s in layout["series"].items():
        shapes[name.replace("/", "_")] = ((nt, *s["shape"]), s["dtype"])
    files = [(st.entry["id"], st.summary and st.summary["file_sha256"]) for st, _ in picked]
    token = tokenize(str(Path(directory).resolve()), files, layout)
    read_layer = f"isoflow-sweep-read-{token}"
    reads: dict[Any, Any] = {}
    blocks: dict[str, dict[Any, Any]] = {name: {} for name in shapes}
    counts: list[int] = []
    positions: list[int] = []
    for k, (st, pick) in enumerate(picked):
        tid, m = st.entry["id"], len(st.entry["members"])
        positions += [sum(counts) + j for j in pick]
        counts.append(m)
        if st.summary is not None:
            path = str(task_paths(directory, tid).h5)
            reads[(read_layer, k)] = (read_task, path, tid, layout, m)
        for name, (shape, dtype) in shapes.items():
            key = (f"isoflow-sweep-{name}-{token}", k) + (0,) * len(shape)
            if st.summary is not None:
                blocks[name][key] = (operator.getitem, (read_layer, k), name)
            else:
                blocks[name][key] = (np.full, (m, *shape), np.nan, np.dtype(dtype))
    out = {}
    for name, (shape, dtype) in shapes.items():
        layer = f"isoflow-sweep-{name}-{token}"
        graph = HighLevelGraph(
            {read_layer: reads, layer: blocks[name]}, {read_layer: set(), layer: {read_layer}}
        )
        chunks = (tuple(counts), *((d,) for d in shape))
        arr = da.Array(graph, layer, chunks=chunks, dtype=np.dtype(dtype))
        out[name] = arr if len(positions) == sum(counts) else arr[np.asarray(positions)]
    return out


def open_sweep(
    directory: str | os.PathLike[str],
    where: Mapping[str, Any] | Callable[[dict[str, Any]], bool] | None = None,
) -> Any:
    """A sweep's results as one :class:`xarray.Dataset` with a ``member`` dimension.

    Parameters
    ----------
    directory : path
        A sweep directory.
    where : mapping or callable, optional
        Select members: ``{"n": 10}`` (parameters equal to these) or a function of a member's
        parameters (with ``seed``) returning a bool.

    Returns
    -------
    xarray.Dataset
        Coordinates: ``member`` (the member's index in the sweep table; members are ordered
        task by task, ``ds.sortby("member")`` restores the table order), ``time``, every
        parameter, ``seed`` (with ``perturb``), ``task``. Variables: ``status`` (``"finished"``,
        ``"failed"``, ``"error"``: its task raised, ``"pending"``: not run yet, or its summary
        does not hold, as ``message`` says), ``failed_step``, ``message``, the per-member
        drifts (``casimir_drift``, ...) from the task summaries, and as dask arrays with one
        chunk per task file: ``y`` ``(member, time, ...)``, ``y_final`` and the saved
        diagnostic series (``casimirs``, ``hamiltonian``, ``invariants_<name>``, ...). Nothing
        is read until computed, and a computation reads each task file once; members of
        unfinished tasks are NaN (of the shape the sweep recorded when it started).

    Raises
    ------
    MissingExtraError
        dask or xarray is not installed (``pip install 'isoflow[sweep]'``).
    SweepError
        Not a sweep directory, a damaged manifest, or selected members whose results differ
        in shape (select members of one shape with ``where``).
    """
    require_extra("dask", "xarray")
    import xarray as xr

    man = read_manifest(directory)
    members = man["members"]
    ts = saved_times(man["run"])
    errors = man.get("errors", {})
    if isinstance(where, Mapping):  # a name no member has selects nothing: say so
        known = {k for m in members for k in m["params"]} | {"seed"}
        unknown = sorted(set(where) - known)
        if unknown:
            raise SweepError(
                f"where: the sweep's members have no parameter {', '.join(unknown)} (they "
                f"have {', '.join(sorted(known))})"
            )
    picked: list[tuple[_TaskState, list[int]]] = []
    order: list[int] = []
    rows: list[dict[str, Any]] = []
    for st in _task_states(directory, man, verify=False):
        idx = st.entry["members"]
        pick = [
            j for j, i in enumerate(idx) if _select(where, members[i]["params"], members[i]["seed"])
        ]
        if pick:
            picked.append((st, pick))
            order += [idx[j] for j in pick]
            rows += [_member_row(st, j, errors) | {"task": st.entry["id"]} for j in pick]

    coords: dict[str, Any] = {"member": np.asarray(order, dtype=np.int64), "time": ts}
    params = [members[i]["params"] for i in order]
    for k in sorted({k for p in params for k in p}):
        coords[k] = ("member", _coord([p.get(k) for p in params]))
    seeds = [members[i]["seed"] for i in order]
    if any(s is not None for s in seeds):
        coords["seed"] = ("member", np.asarray([-1 if s is None else s for s in seeds]))
    coords["task"] = ("member", np.asarray([r["task"] for r in rows], dtype=object))
    data: dict[str, Any] = {
        "status": ("member", np.asarray([r["status"] for r in rows], dtype=object)),
        "failed_step": ("member", np.asarray([r["failed_step"] for r in rows], dtype=np.int64)),
        "message": ("member", np.asarray([r["message"] for r in rows], dtype=object)),
    }
    drift_names = sorted({k for st, _ in picked if st.summary for k in st.summary["drifts"]})
    for k in drift_names:
        data[k] = ("member", np.asarray([r.get(k, np.nan) for r in rows], dtype=float))
    layout = _common_layout([st for st, _ in picked], members)
    if layout is not None:
        for name, arr in _arrays(directory, picked, layout, len(ts)).items():
            dims = ["member"] if name == "y_final" else ["member", "time"]
            dims += [f"{name}_dim{i}" for i in range(arr.ndim - len(dims))]
            data[name] = (tuple(dims), arr)
    ds = xr.Dataset(data, coords=coords)
    ds.attrs["model"] = man["model"]
    ds.attrs["run"] = json.dumps(man["run"])
    ds.attrs["perturb"] = "none" if man.get("perturb") is None else man["perturb"]
    ds.attrs["sweep"] = str(Path(directory).resolve())
    return ds


def status(directory: str | os.PathLike[str], *, verify: bool = False) -> dict[str, Any]:
    """A sweep directory's state, JSON-ready (what ``isoflow info DIR`` prints).

    Parameters
    ----------
    directory : path
    verify : bool
        Compare every result file with the SHA-256 its summary recorded (reads them all);
        without it only their sizes are compared.

    Returns
    -------
    dict
        ``path``, ``model``, ``run``, ``perturb``, ``members``, ``tasks``, ``done``,
        ``partial`` (result file without summary), ``pending``, ``damaged`` (task -> why its
        summary does not count; the sweep redoes it), ``errors`` (task -> message),
        ``failed_members`` (index -> ``{"step", "message"}``) and ``drifts`` (worst over the
        finished members).

    Raises
    ------
    SweepError
        Not a sweep directory, or a damaged manifest (one line naming it).
    """
    man = read_manifest(directory)
    done = partial = pending = 0
    damaged: dict[str, str] = {}
    failed: dict[str, Any] = {}
    worst: dict[str, float] = {}
    for st in _task_states(directory, man, verify):
        s = st.summary
        if s is None:
            if st.damage:
                damaged[st.entry["id"]] = st.damage
            elif task_paths(directory, st.entry["id"]).h5.exists():
                partial += 1
            else:
                pending += 1
            continue
        done += 1
        for j, i in enumerate(s["members"]):
            if s["status"][j] != MEMBER_STATUSES[0]:
                failed[str(i)] = {"step": s["failed_step"][j], "message": s["message"][j]}
                continue
            for k, v in s["drifts"].items():
                worst[k] = max(worst.get(k, -np.inf), float(v[j]))
    return {
        "path": str(Path(directory).resolve()),
        "model": man["model"],
        "run": man["run"],
        "perturb": man.get("perturb"),
        "members": len(man["members"]),
        "tasks": len(man["tasks"]),
        "done": done,
        "partial": partial,
        "pending": pending,
        "damaged": damaged,
        "errors": man.get("errors", {}),
        "failed_members": failed,
        "drifts": worst,
    }
