"""Reading a sweep directory: :func:`open_sweep` (one lazy xarray Dataset) and :func:`status`."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .files import read_json, read_manifest, task_paths

__all__ = ["open_sweep", "read_task", "saved_times", "status"]


def saved_times(run: Mapping[str, Any]) -> np.ndarray:
    """The saved times of a sweep's time grid (every ``save_every`` steps and the last)."""
    n, every = int(run["n_steps"]), int(run["save_every"])
    steps = list(range(0, n + 1, every))
    if steps[-1] != n:
        steps.append(n)
    return float(run["t0"]) + np.asarray(steps, dtype=float) * float(run["dt"])


def read_task(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Everything :func:`open_sweep` takes from one task file, member first.

    ``y`` ``(members, time, *shape)``, ``y_final`` ``(members, *shape)`` and each diagnostic
    series ``(members, time, ...)`` (``invariants/<name>`` as ``invariants_<name>``). One read
    of the file (:func:`isoflow.io.load`).
    """
    from .. import io

    run = io.load(path)
    out = {"y": np.moveaxis(run.ys, 0, 1), "y_final": run.ys[-1]}
    for name, arr in run.series.items():
        out[name.replace("/", "_")] = np.moveaxis(arr, 0, 1)
    return out


def _select(where: Any, params: dict[str, Any], seed: Any) -> bool:
    if where is None:
        return True
    if callable(where):
        return bool(where(params | ({} if seed is None else {"seed": seed})))
    values = params | ({} if seed is None else {"seed": seed})
    return all(values.get(k) == v for k, v in where.items())


def _coord(values: list[Any]) -> np.ndarray:
    if all(isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=bool)
    if all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=np.int64)
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=float)
    return np.asarray([v if isinstance(v, str) else json.dumps(v) for v in values], dtype=object)


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
        ``"failed"``, ``"error"``: its task raised, ``"pending"``: not run yet),
        ``failed_step``, ``message``, the per-member drifts (``casimir_drift``, ...) from the
        task summaries, and as dask arrays with one chunk per task file: ``y``
        ``(member, time, ...)``, ``y_final`` and the saved diagnostic series (``casimirs``,
        ``hamiltonian``, ``invariants_<name>``, ...). Nothing is read until computed, and a
        computation reads each task file once; members of unfinished tasks are NaN.
    """
    import dask
    import dask.array as da
    import xarray as xr

    man = read_manifest(directory)
    members = man["members"]
    run = man["run"]
    ts = saved_times(run)
    nt = len(ts)
    summaries = {t["id"]: read_json(task_paths(directory, t["id"]).json) for t in man["tasks"]}
    errors = man.get("errors") or {}
    proto = next((s for s in summaries.values() if s is not None), None)

    order: list[int] = []
    rows: list[dict[str, Any]] = []
    chunks: dict[str, list[Any]] = {}
    for t in man["tasks"]:
        summ = summaries[t["id"]]
        pick = [
            j
            for j, i in enumerate(t["members"])
            if _select(where, members[i]["params"], members[i]["seed"])
        ]
        if not pick:
            continue
        for j in pick:
            i = t["members"][j]
            order.append(i)
            row: dict[str, Any] = {"task": t["id"]}
            if summ is not None:
                row |= {
                    "status": summ["status"][j],
                    "failed_step": summ["failed_step"][j],
                    "message": summ["message"][j],
                }
                row |= {k: v[j] for k, v in summ["drifts"].items()}
            else:
                row |= {
                    "status": "error" if t["id"] in errors else "pending",
                    "failed_step": -1,
                    "message": errors.get(t["id"], ""),
                }
            rows.append(row)
        if proto is None:
            continue
        shapes = {
            "y": ((nt, *proto["state_shape"]), proto["state_dtype"]),
            "y_final": (tuple(proto["state_shape"]), proto["state_dtype"]),
        }
        for name, s in proto["series"].items():
            shapes[name.replace("/", "_")] = ((nt, *s["shape"]), s["dtype"])
        m = len(t["members"])
        if summ is not None:
            path = str(task_paths(directory, t["id"]).h5)
            blob = dask.delayed(read_task, pure=True)(path, dask_key_name=f"read-{t['id']}")
            for name, (shape, dtype) in shapes.items():
                arr = da.from_delayed(blob[name], shape=(m, *shape), dtype=np.dtype(dtype))
                chunks.setdefault(name, []).append(arr if len(pick) == m else arr[pick])
        else:
            for name, (shape, dtype) in shapes.items():
                full = da.full((len(pick), *shape), np.nan, dtype=np.dtype(dtype))
                chunks.setdefault(name, []).append(full)

    coords: dict[str, Any] = {"member": np.asarray(order, dtype=np.int64), "time": ts}
    params = [members[i]["params"] for i in order]
    keys = sorted({k for p in params for k in p})
    for k in keys:
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
    drift_names = sorted({k for s in summaries.values() if s for k in s["drifts"]})
    for k in drift_names:
        data[k] = ("member", np.asarray([r.get(k, np.nan) for r in rows], dtype=float))
    for name, parts in chunks.items():
        arr = da.concatenate(parts, axis=0) if len(parts) > 1 else parts[0]
        dims = ["member"] if name == "y_final" else ["member", "time"]
        dims += [f"{name}_dim{i}" for i in range(arr.ndim - len(dims))]
        data[name] = (tuple(dims), arr)
    ds = xr.Dataset(data, coords=coords)
    ds.attrs["model"] = man["model"]
    ds.attrs["run"] = json.dumps(run)
    ds.attrs["perturb"] = "none" if man.get("perturb") is None else man["perturb"]
    ds.attrs["sweep"] = str(Path(directory).resolve())
    return ds


def status(directory: str | os.PathLike[str]) -> dict[str, Any]:
    """A sweep directory's state, JSON-ready (what ``isoflow info DIR`` prints).

    Keys: ``path``, ``model``, ``run``, ``perturb``, ``members``, ``tasks``, ``done``,
    ``partial`` (result file without summary), ``pending``, ``errors`` (task -> message),
    ``failed_members`` (index -> ``{"step", "message"}``) and ``drifts`` (worst over the finished
    members).
    """
    man = read_manifest(directory)
    done = partial = pending = 0
    failed: dict[str, Any] = {}
    worst: dict[str, float] = {}
    for t in man["tasks"]:
        paths = task_paths(directory, t["id"])
        summ = read_json(paths.json)
        if summ is None:
            if paths.h5.exists():
                partial += 1
            else:
                pending += 1
            continue
        done += 1
        for j, i in enumerate(summ["members"]):
            if summ["status"][j] != "finished":
                failed[str(i)] = {"step": summ["failed_step"][j], "message": summ["message"][j]}
                continue
            for k, v in summ["drifts"].items():
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
        "errors": man.get("errors") or {},
        "failed_members": failed,
        "drifts": worst,
    }
