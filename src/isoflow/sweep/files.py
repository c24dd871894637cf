"""The layout of a sweep directory, its manifest, and atomic JSON writes.

::

    DIR/sweep.json          the manifest: the sweep as read, its members and tasks
    DIR/tasks/<id>.h5       a task's ensemble run (isoflow.io.HDF5Writer, resumable)
    DIR/tasks/<id>.json     the task's summary; its presence marks the task done
    DIR/tasks/<id>.log      what the worker did (attempts, resumes, errors with traceback)
    DIR/tasks/<id>.lock     flock held by the worker running the task (its pid inside)
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .spec import SweepError, SweepSpec

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "TaskPaths",
    "manifest",
    "read_json",
    "read_manifest",
    "task_paths",
    "write_json_atomic",
    "write_manifest",
]

FORMAT = "isoflow-sweep"
FORMAT_VERSION = 1
MANIFEST = "sweep.json"


@dataclass(frozen=True)
class TaskPaths:
    """The files of one task."""

    h5: Path
    json: Path
    log: Path
    lock: Path


def task_paths(directory: str | os.PathLike[str], task_id: str) -> TaskPaths:
    """The files of task ``task_id`` in the sweep directory ``directory``."""
    base = Path(directory) / "tasks"
    return TaskPaths(
        base / f"{task_id}.h5",
        base / f"{task_id}.json",
        base / f"{task_id}.log",
        base / f"{task_id}.lock",
    )


def write_json_atomic(path: Path, obj: Any) -> None:
    """Write ``obj`` as JSON so that ``path`` is either absent, old, or complete and new.

    Written to a temporary file in the same directory, flushed to disk, then renamed over
    ``path`` (atomic on POSIX file systems).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with tmp.open("w") as fh:
        json.dump(obj, fh, indent=1, default=float)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def read_json(path: Path) -> Any:
    """A JSON file (``None`` if absent)."""
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return None


def manifest(spec: SweepSpec) -> dict[str, Any]:
    """The manifest of ``spec``: format, the run settings, the members and the tasks."""
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "model": spec.model,
        "run": spec.run,
        "perturb": spec.perturb,
        "initial": list(spec.initial),
        "members_per_task": spec.members_per_task,
        "members": [{"index": m.index, "params": m.params, "seed": m.seed} for m in spec.members],
        "tasks": [{"id": t.id, "members": [m.index for m in t.members]} for t in spec.tasks],
        "source": spec.source,
    }


def write_manifest(directory: str | os.PathLike[str], spec: SweepSpec, **extra: Any) -> Path:
    """Create the directory layout and write ``sweep.json`` (``extra`` keys added)."""
    d = Path(directory)
    (d / "tasks").mkdir(parents=True, exist_ok=True)
    path = d / MANIFEST
    write_json_atomic(path, manifest(spec) | extra)
    return path


def read_manifest(directory: str | os.PathLike[str]) -> dict[str, Any]:
    """The manifest of a sweep directory.

    Raises
    ------
    SweepError
        Not a sweep directory.
    """
    path = Path(directory) / MANIFEST
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise SweepError(f"{directory}: not a sweep directory (no {MANIFEST})") from None
    except (OSError, ValueError) as exc:
        raise SweepError(f"{path}: unreadable manifest: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise SweepError(f"{path}: not an isoflow sweep manifest")
    return data


def is_sweep_dir(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a directory holding a sweep manifest."""
    return (Path(path) / MANIFEST).is_file()
