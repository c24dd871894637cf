"""The layout of a sweep directory: its manifest, the task summaries, atomic JSON writes.

::

    DIR/sweep.json          the manifest: the sweep as read, its members and tasks
    DIR/tasks/<id>.h5       a task's ensemble run (isoflow.io.HDF5Writer, resumable)
    DIR/tasks/<id>.json     the task's summary; a valid one marks the task done
    DIR/tasks/<id>.log      what the worker did (attempts, resumes, errors with traceback)
    DIR/tasks/<id>.lock     flock held by the worker running the task (its pid inside)

Everything read back is checked first: a manifest or a summary that is not what this module
wrote (empty, truncated, edited, from another task) is one :class:`SweepError` line naming the
file. A summary carries the SHA-256 of its own content and of its task's result file, so that
a summary whose result file was deleted, truncated, scrambled or replaced does not count.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._errors import ResultFileError, ResultWriteError
from .spec import MAX_MEMBERS, MAX_SAVED, SweepError, SweepSpec

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MANIFEST",
    "TaskPaths",
    "file_sha256",
    "manifest",
    "read_manifest",
    "read_summary",
    "seal",
    "task_paths",
    "write_json_atomic",
    "write_manifest",
]

FORMAT = "isoflow-sweep"
#: Version 2: layouts in the manifest; summaries checksummed and tied to their result file.
FORMAT_VERSION = 2
MANIFEST = "sweep.json"

_TASK_ID = re.compile(r"^[0-9a-f]{20}$")
_SHA256 = re.compile(r"^[0-9a-f]{64}$")
#: What a member of a finished task can be.
MEMBER_STATUSES = ("finished", "failed")


@dataclass(frozen=True)
class TaskPaths:
    """The files of one task.

    Parameters
    ----------
    h5 : Path
        The result file, ``tasks/<id>.h5``.
    json : Path
        The summary, ``tasks/<id>.json``.
    log : Path
        The log, ``tasks/<id>.log``.
    lock : Path
        The lock file of the task's worker, ``tasks/<id>.lock``.
    """

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


# ---- writing -----------------------------------------------------------------------------------


def write_json_atomic(path: Path, obj: Any) -> None:
    """Write ``obj`` as JSON so that ``path`` is either absent, old, or complete and new.

    Written to a temporary file in the same directory, flushed to disk, then renamed over
    ``path`` (atomic on POSIX file systems).

    Raises
    ------
    ResultWriteError
        The directory or the file cannot be written (a full disk, permissions): one line
        naming ``path``; no temporary file is left behind.
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tmp.open("w") as fh:
            json.dump(obj, fh, indent=1, default=float)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise ResultWriteError(f"{path}: cannot write: {exc.strerror or exc}") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _canonical(obj: Any) -> str:
    """JSON independent of key order (NaN allowed: drifts of failed members are NaN)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True)


def _checksum(obj: Mapping[str, Any]) -> str:
    content = {k: v for k, v in obj.items() if k != "checksum"}
    return hashlib.sha256(_canonical(content).encode()).hexdigest()


def seal(summary: Mapping[str, Any]) -> dict[str, Any]:
    """``summary`` as it reads back from JSON, with the SHA-256 of its content (``checksum``)."""
    plain = json.loads(json.dumps(summary, default=float))
    return plain | {"checksum": _checksum(plain)}


def file_sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex).

    Parameters
    ----------
    path : Path
        The file.

    Returns
    -------
    str
    """
    with path.open("rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def manifest(spec: SweepSpec, layouts: Mapping[str, dict[str, Any] | None]) -> dict[str, Any]:
    """The manifest of ``spec``: format, the run settings, the members and the tasks.

    ``layouts`` maps a task id to the shapes and dtypes of its member's state and saved series
    (``None`` where unknown), stored once per distinct layout.
    """
    table: list[dict[str, Any]] = []
    index: dict[str, int] = {}
    tasks = []
    for t in spec.tasks:
        lay = layouts.get(t.id)
        k = None
        if lay is not None:
            k = index.setdefault(_canonical(lay), len(table))
            if k == len(table):
                table.append(lay)
        tasks.append({"id": t.id, "members": [m.index for m in t.members], "layout": k})
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "model": spec.model,
        "run": spec.run,
        "perturb": spec.perturb,
        "initial": list(spec.initial),
        "members_per_task": spec.members_per_task,
        "members": [{"index": m.index, "params": m.params, "seed": m.seed} for m in spec.members],
        "layouts": table,
        "tasks": tasks,
        "source": spec.source,
    }


def write_manifest(
    directory: str | os.PathLike[str],
    spec: SweepSpec,
    layouts: Mapping[str, dict[str, Any] | None],
    **extra: Any,
) -> Path:
    """Create the directory layout and write ``sweep.json`` (``extra`` keys added).

    Parameters
    ----------
    directory : str or os.PathLike
        The sweep directory (created with its ``tasks`` directory).
    spec : SweepSpec
        The sweep.
    layouts : mapping of str to (dict or None)
        Task id to its layout (:func:`~isoflow.sweep.task.task_layouts`).
    **extra
        Further keys of the manifest.

    Returns
    -------
    Path
        The manifest file.

    Raises
    ------
    ResultWriteError
        The directory cannot be created or the manifest not written (naming the path).
    """
    d = Path(directory)
    try:
        (d / "tasks").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ResultWriteError(f"{d / 'tasks'}: cannot create: {exc.strerror or exc}") from None
    path = d / MANIFEST
    write_json_atomic(path, manifest(spec, layouts) | extra)
    return path


# ---- reading: one checker per field ------------------------------------------------------------


class _Bad(Exception):
    """A field of a JSON file is not what the writer writes (the message says which)."""


def _need(ok: bool, what: str) -> None:
    if not ok:
        raise _Bad(what)


def _is_int(v: Any, lo: int = 0, hi: int = 1 << 62) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _field(data: Mapping[str, Any], key: str, check: Callable[[Any], bool], what: str) -> Any:
    _need(key in data, f"no {key!r}")
    value = data[key]
    _need(check(value), f"{key!r} is not {what}")
    return value


def _list_of(value: Any, check: Callable[[Any], bool], n: int | None = None) -> bool:
    return isinstance(value, list) and (n is None or len(value) == n) and all(map(check, value))


def _layout(value: Any) -> dict[str, Any]:
    """A state/series layout ``{state_shape, state_dtype, series: {name: {shape, dtype}}}``."""
    from ..io.codec import check_shape, numeric_dtype  # the io package loads h5py

    _need(isinstance(value, dict), "a layout is not a table")
    try:
        check_shape(value.get("state_shape"), "state_shape", max_elements=1 << 28)
        numeric_dtype(value.get("state_dtype"), "state_dtype")
        series = value.get("series")
        _need(isinstance(series, dict), "the layout's 'series' is not a table")
        for name, s in series.items():
            _need(isinstance(s, dict) and bool(name), f"series {name!r} is not a table")
            check_shape(s.get("shape"), f"series {name!r} shape", max_elements=1 << 28)
            numeric_dtype(s.get("dtype"), f"series {name!r} dtype")
    except ResultFileError as exc:
        raise _Bad(str(exc)) from None
    return value


def _run(run: Any) -> None:
    _need(isinstance(run, dict), "'run' is not a table")
    _field(run, "t0", _is_number, "a finite number")
    _field(run, "dt", lambda v: _is_number(v) and v > 0, "a positive number")
    n = _field(run, "n_steps", lambda v: _is_int(v, 1), "an integer >= 1")
    every = _field(run, "save_every", lambda v: _is_int(v, 1), "an integer >= 1")
    _need(n // every + 1 <= MAX_SAVED, f"'run' saves more than {MAX_SAVED} states")


def _members(members: Any) -> None:
    _need(isinstance(members, list), "'members' is not a list")
    _need(0 < len(members) <= MAX_MEMBERS, f"'members' does not hold 1..{MAX_MEMBERS} members")
    for i, m in enumerate(members):
        _need(isinstance(m, dict), f"member {i} is not a table")
        _need(m.get("index") == i, f"member {i} has index {m.get('index')!r}")
        _need(isinstance(m.get("params"), dict), f"member {i} has no 'params' table")
        seed = m.get("seed")
        _need(seed is None or _is_int(seed), f"member {i} has seed {seed!r}")


def _tasks(tasks: Any, n_members: int, n_layouts: int) -> None:
    _need(isinstance(tasks, list) and len(tasks) > 0, "'tasks' is not a non-empty list")
    seen: set[int] = set()
    for k, t in enumerate(tasks):
        _need(isinstance(t, dict), f"task {k} is not a table")
        tid = t.get("id")
        _need(isinstance(tid, str) and bool(_TASK_ID.match(tid)), f"task {k} has id {tid!r}")
        members = t.get("members")
        ok = _list_of(members, lambda i: _is_int(i, 0, n_members - 1)) and len(members) > 0
        _need(ok, f"task {tid} lists members that the manifest does not have")
        _need(not seen & set(members), f"task {tid} repeats members of another task")
        seen |= set(members)
        lay = t.get("layout")
        _need(lay is None or _is_int(lay, 0, n_layouts - 1), f"task {tid} has layout {lay!r}")
    _need(len(seen) == n_members, "some members belong to no task")


def _check_manifest(data: Any) -> None:
    _need(isinstance(data, dict), f"a JSON {type(data).__name__}, not a table")
    _need(data.get("format") == FORMAT, "not an isoflow sweep manifest")
    version = data.get("format_version")
    _need(
        version == FORMAT_VERSION,
        f"format version {version!r}, not {FORMAT_VERSION} (run the sweep again with this "
        "isoflow to rewrite it)",
    )
    _field(data, "model", lambda v: isinstance(v, str) and bool(v), "a model name")
    _run(data.get("run"))
    perturb = data.get("perturb")
    _need(perturb is None or (_is_number(perturb) and perturb > 0), "'perturb' is not > 0")
    _members(data.get("members"))
    layouts = _field(data, "layouts", lambda v: isinstance(v, list), "a list")
    for lay in layouts:
        _layout(lay)
    _tasks(data.get("tasks"), len(data["members"]), len(layouts))
    errors = data.get("errors", {})
    _need(
        isinstance(errors, dict) and all(isinstance(v, str) for v in errors.values()),
        "'errors' is not a table of messages",
    )


def _read_text(path: Path) -> str | None:
    try:
        return path.read_text()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise SweepError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None


def _parse(text: str, path: Path) -> Any:
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        what = "empty" if not text.strip() else "not valid JSON (truncated?)"
        raise SweepError(f"{path}: {what}") from None


def read_manifest(directory: str | os.PathLike[str]) -> dict[str, Any]:
    """The manifest of a sweep directory, every field the readers use checked.

    Raises
    ------
    SweepError
        Not a sweep directory, or a manifest that is not what :func:`write_manifest` writes
        (one line naming the file and the field).
    """
    path = Path(directory) / MANIFEST
    text = _read_text(path)
    if text is None:
        raise SweepError(f"{directory}: not a sweep directory (no {MANIFEST})")
    data = _parse(text, path)
    try:
        _check_manifest(data)
    except _Bad as exc:
        raise SweepError(f"{path}: {exc}") from None
    return dict(data)


def _check_summary(data: Any, task: Mapping[str, Any]) -> None:
    _need(isinstance(data, dict), f"a JSON {type(data).__name__}, not a table")
    _need(
        data.get("checksum") == _checksum(data), "its checksum does not match (damaged or edited)"
    )
    _need(data.get("id") == task["id"], f"the summary of task {data.get('id')!r}")
    _need(data.get("members") == task["members"], "its members are not the task's")
    m = len(task["members"])
    _field(data, "status", lambda v: _list_of(v, MEMBER_STATUSES.__contains__, m), "a status list")
    _field(data, "failed_step", lambda v: _list_of(v, lambda s: _is_int(s, -1), m), "a step list")
    _field(data, "message", lambda v: _list_of(v, lambda s: isinstance(s, str), m), "a text list")
    drifts = _field(data, "drifts", lambda v: isinstance(v, dict), "a table")
    for name, v in drifts.items():
        ok = _list_of(v, lambda x: isinstance(x, int | float) and not isinstance(x, bool), m)
        _need(ok, f"drift {name!r} is not a list of {m} numbers")
    _layout({k: data.get(k) for k in ("state_shape", "state_dtype", "series")})
    _field(data, "file_size", _is_int, "a size in bytes")
    _field(data, "file_sha256", lambda v: isinstance(v, str) and bool(_SHA256.match(v)), "a hash")


def _check_result_file(summary: Mapping[str, Any], path: Path, verify: bool) -> None:
    try:
        _need(
            path.stat().st_size == summary["file_size"], f"its result file {path.name} changed size"
        )
        if verify:
            ok = file_sha256(path) == summary["file_sha256"]
            _need(ok, f"its result file {path.name} changed")
    except FileNotFoundError:
        raise _Bad(f"its result file {path.name} is missing") from None
    except OSError as exc:
        raise _Bad(f"its result file {path.name} cannot be read: {exc.strerror or exc}") from None


def read_summary(
    directory: str | os.PathLike[str], task: Mapping[str, Any], *, verify: bool = False
) -> dict[str, Any] | None:
    """The summary of a done task, or ``None`` if there is none.

    Parameters
    ----------
    directory : path
        The sweep directory.
    task : mapping
        ``{"id": ..., "members": [indices]}`` (a manifest's task entry).
    verify : bool
        Also compare the result file's SHA-256 with the one recorded (reads the file); without
        it only its size is compared.

    Raises
    ------
    SweepError
        The summary is not this task's valid summary or its result file is not the one it
        describes (missing, truncated, replaced; with ``verify``, any changed byte): one line
        naming the summary. Running the sweep again redoes the task.
    """
    paths = task_paths(directory, task["id"])
    text = _read_text(paths.json)
    if text is None:
        return None
    data = _parse(text, paths.json)
    try:
        _check_summary(data, task)
        _check_result_file(data, paths.h5, verify)
    except _Bad as exc:
        raise SweepError(f"{paths.json}: {exc}") from None
    return dict(data)
