"""Sweep files: reading and checking a sweep, expanding its members, grouping them into tasks.

Everything here is checked before anything runs; every mistake is one :class:`SweepError`
(one line). The model, method, solver and time-grid rules are those of
:mod:`isoflow.registry` (and :func:`isoflow._solve.time_grid` through it): this module names
nothing itself.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import inspect
import itertools
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from .. import registry
from .._errors import IsoflowError
from .._solve import time_grid

__all__ = [
    "MAX_MEMBERS",
    "MAX_SAVED",
    "MEMBERS_PER_TASK",
    "Member",
    "MissingExtraError",
    "SweepError",
    "SweepSpec",
    "Task",
    "canonical_json",
    "read_spec",
    "require_extra",
]

#: Default largest number of members solved as one ensemble (one task).
MEMBERS_PER_TASK = 32

#: Most members of one sweep (``[[members]]`` rows times the grid), counted before they are
#: listed: beyond it, expanding, checking and recording the members (about 80 us and 80 bytes
#: of manifest each) would take longer than a user waits without knowing why. Split larger
#: sweeps; each part is a sweep of its own.
MAX_MEMBERS = 100_000

#: Most saved states per member (``n_steps / save_every``), also a bound the readers of a
#: sweep directory trust.
MAX_SAVED = 1 << 24

#: Keys of a sweep file (``params``, ``grid`` and ``members`` are tables).
_TOP_KEYS = frozenset(
    {"model", "method", "solver", "rtol", "anderson", "t0", "t1", "dt", "n_steps"}
    | {"save_every", "members_per_task", "perturb", "initial", "chunk_rows", "flush_seconds"}
    | {"out", "params", "grid", "members"}
)
_TIME_KEYS = ("t1", "dt", "n_steps")
_RUN_KEYS = ("method", "solver", "rtol", "anderson", "t0", "save_every")


class SweepError(IsoflowError, ValueError):
    """A sweep file or sweep directory is not usable (one line, said before anything runs)."""


class MissingExtraError(IsoflowError, ImportError):
    """A module of the ``[sweep]`` extra (dask, distributed, xarray) is not installed."""


def require_extra(*modules: str) -> None:
    """Import ``modules`` (of the ``[sweep]`` extra) or say in one line how to install them.

    Raises
    ------
    MissingExtraError
        One of them does not import.
    """
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            raise MissingExtraError(
                f"sweeps need the sweep extra (dask, distributed, xarray), and {name} does not "
                f"import ({' '.join(str(exc).split())}): pip install 'isoflow[sweep]'"
            ) from None


def canonical_json(obj: Any) -> str:
    """``obj`` as JSON that does not depend on key order, hash seed or process.

    Keys sorted, no whitespace, ASCII, floats as Python's shortest round-trip ``repr``; NaN and
    infinities are refused (they have no JSON spelling).
    """
    return json.dumps(
        obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False
    )


@dataclass(frozen=True)
class Member:
    """One run of a sweep.

    Attributes
    ----------
    index : int
        Position in the expanded member table (``[[members]]`` rows times the grid).
    params : dict
        The model parameters, checked and with the model's defaults filled in.
    seed : int or None
        Seed of the perturbation (``perturb``): the model's own ``seed`` parameter when it has
        one, else the member's ``seed`` (default: its index); ``None`` without ``perturb``.
    """

    index: int
    params: dict[str, Any]
    seed: int | None = None

    def key(self) -> dict[str, Any]:
        """What identifies the member's run (its parameters and seed), JSON-ready."""
        return {"params": self.params, "seed": self.seed}


@dataclass(frozen=True)
class Task:
    """Members solved as one ensemble in one worker, written to ``tasks/<id>.h5``.

    Attributes
    ----------
    id : str
        First 20 hex digits of :attr:`digest`: equal tasks of two sweeps share their files.
    members : tuple of Member
    digest : str
        The SHA-256 of the canonical JSON of the model, method, time grid, perturbation and
        members (:meth:`SweepSpec.task_digest`), recorded in the task's result file, which
        is resumed only by the task it names.
    """

    id: str
    members: tuple[Member, ...]
    digest: str = ""


@dataclass(frozen=True)
class SweepSpec:
    """A checked sweep: the shared run settings, the members and their tasks.

    Attributes
    ----------
    model : str
        The model's name (:mod:`isoflow.registry` spelling).
    run : dict
        Method, solver, ``rtol``, ``anderson``, ``t0``, ``dt``, ``n_steps``, ``save_every``
        (normalized by the registry; the time grid as ``dt`` and ``n_steps``).
    members : tuple of Member
    tasks : tuple of Task
    perturb : float or None
        Relative size of the random perturbation of each member's initial state.
    initial : tuple of str
        Parameters that only set the initial state (the model's and the file's ``initial``).
    members_per_task : int
    chunk_rows, flush_seconds :
        As in :class:`isoflow.io.HDF5Writer`.
    out : str or None
        The sweep directory named by the file.
    source : dict
        The file's table as read (recorded in the manifest).
    """

    model: str
    run: dict[str, Any]
    members: tuple[Member, ...]
    tasks: tuple[Task, ...]
    perturb: float | None = None
    initial: tuple[str, ...] = ()
    members_per_task: int = MEMBERS_PER_TASK
    chunk_rows: int = 256
    flush_seconds: float = 1.0
    out: str | None = None
    source: dict[str, Any] = field(default_factory=dict)

    def model_spec(self) -> registry.ModelSpec:
        """The model (:func:`isoflow.registry.load_model`; a user's module is imported)."""
        return registry.load_model(self.model)

    def config(self, member: Member) -> dict[str, Any]:
        """The registry run configuration of ``member`` (what its result file records)."""
        return {"model": self.model, "params": dict(member.params), **self.run}

    def task_digest(self, members: Sequence[Member]) -> str:
        """The content hash of a task of ``members`` (see :class:`Task`)."""
        blob = canonical_json(
            {
                "model": self.model,
                "method": {k: self.run.get(k) for k in ("method", "solver", "rtol", "anderson")},
                "time": {k: self.run[k] for k in ("t0", "dt", "n_steps", "save_every")},
                "perturb": self.perturb,
                "members": [m.key() for m in members],
            }
        )
        return hashlib.sha256(blob.encode()).hexdigest()

    def task_id(self, members: Sequence[Member]) -> str:
        """The content address of a task of ``members``: its digest's first 20 hex digits."""
        return self.task_digest(members)[:20]

    def task_of(self, task_id: str) -> Task:
        """The task called ``task_id``."""
        for t in self.tasks:
            if t.id == task_id:
                return t
        raise SweepError(f"the sweep has no task {task_id!r}")

    def for_task(self, task: Task) -> SweepSpec:
        """This sweep reduced to ``task`` (what a worker needs: its size does not grow with
        the sweep's)."""
        return dataclasses.replace(self, members=task.members, tasks=(task,), source={})


# ---- reading -----------------------------------------------------------------------------------


def read_spec(source: str | os.PathLike[str] | Mapping[str, Any]) -> SweepSpec:
    """Read and check a sweep (a TOML file, or its table as a mapping).

    Parameters
    ----------
    source : path or mapping
        A ``.toml`` file or the equivalent dictionary (see :mod:`isoflow.sweep` for the keys).

    Returns
    -------
    SweepSpec

    Raises
    ------
    SweepError
        Any mistake: unreadable or malformed file, unknown keys or parameters, wrong types, an
        empty table, duplicate members, ``seed`` without ``perturb`` for a model without a
        seed, a time grid that differs between members; one line naming the member.
    """
    if isinstance(source, Mapping):
        table = dict(source)
        where = "sweep"
    else:
        p = Path(source)
        where = str(p)
        table = registry.read_toml(p, "sweep file", SweepError)
    try:
        return _build(table)
    except SweepError as exc:
        raise SweepError(f"{where}: {exc}") from None
    except (IsoflowError, ValueError, TypeError) as exc:
        msg = " ".join(str(exc).split())
        raise SweepError(f"{where}: {msg}") from None


def _int(value: Any, what: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise SweepError(f"{what} must be an integer >= {low}, got {value!r}")
    return int(value)


def _positive(value: Any, what: str) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or value <= 0:
        raise SweepError(f"{what} must be a positive number, got {value!r}")
    return float(value)


def _table(value: Any, what: str) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise SweepError(f"{what} must be a table, got {value!r}")
    return dict(value)


def _grid_column(key: str, value: Any) -> tuple[int, Callable[[], list[Any]]]:
    """A ``[grid]`` column, checked: its length and a function listing its values.

    A list, ``{start, stop[, step]}`` (integers, like ``range``) or ``{start, stop, num}``
    (numbers, like ``linspace``). The length is known before any value is made, so that a
    sweep too large to run is refused before it takes the memory to list it.
    """
    what = f"grid.{key}"
    make: Callable[[], list[Any]]
    if isinstance(value, list):
        length, make = len(value), partial(list, value)
    elif isinstance(value, Mapping):
        keys = set(value)
        if keys in ({"start", "stop"}, {"start", "stop", "step"}):
            start, stop = value["start"], value["stop"]
            step = value.get("step", 1)
            for name, v in (("start", start), ("stop", stop), ("step", step)):
                if isinstance(v, bool) or not isinstance(v, int):
                    raise SweepError(
                        f"{what}: {{start, stop, step}} is a range of integers ({name} = {v!r}; "
                        "for numbers give num, like linspace)"
                    )
            if step == 0:
                raise SweepError(f"{what}: step must not be 0")
            span = range(start, stop, step)
            length, make = len(span), partial(list, span)
        elif keys == {"start", "stop", "num"}:
            start, stop = value["start"], value["stop"]
            for name, v in (("start", start), ("stop", stop)):
                if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                    raise SweepError(f"{what}: {name} must be a number, got {v!r}")
            length = _int(value["num"], f"{what}.num", 1)
            make = partial(_linspace, float(start), float(stop), length)
        else:
            raise SweepError(
                f"{what} must be a list, {{start, stop[, step]}} (integers, like range) or "
                f"{{start, stop, num}} (numbers, like linspace), got keys {sorted(keys)}"
            )
    else:
        raise SweepError(f"{what} must be a list or a table, got {value!r}")
    if length == 0:
        raise SweepError(f"{what} is empty")
    return length, make


def _linspace(start: float, stop: float, num: int) -> list[float]:
    return [float(v) for v in np.linspace(start, stop, num)]


def _check_count(n_rows: int, lengths: dict[str, int]) -> None:
    """Refuse a sweep of more than :data:`MAX_MEMBERS` members, saying how to split it."""
    count = max(n_rows, 1) * math.prod(lengths.values())
    if count <= MAX_MEMBERS:
        return
    factors = ([f"{n_rows} [[members]] row" + "s" * (n_rows > 1)] if n_rows else []) + [
        f"{n} values of {k}" for k, n in lengths.items()
    ]
    raise SweepError(
        f"the sweep has {count:,} members ({' x '.join(factors)}), more than the limit of "
        f"{MAX_MEMBERS:,}: split it into several sweeps of at most {MAX_MEMBERS:,} members "
        "(e.g. one per value of a grid column), each with its own directory"
    )


def _rows(table: dict[str, Any]) -> list[dict[str, Any]]:
    """``[[members]]`` rows times the product of the ``[grid]`` columns (rows outer)."""
    rows = table.get("members")
    if rows is None:
        rows = []
    if not isinstance(rows, list) or not all(isinstance(r, Mapping) for r in rows):
        raise SweepError("members must be an array of tables ([[members]] rows)")
    for i, r in enumerate(rows):
        if not r:
            raise SweepError(f"members[{i}] is an empty table")
    grid = _table(table.get("grid", {}), "grid")
    if not rows and not grid:
        raise SweepError("the sweep has no members: give [[members]] rows and/or a [grid]")
    columns = {k: _grid_column(k, v) for k, v in grid.items()}
    _check_count(len(rows), {k: n for k, (n, _make) in columns.items()})
    values = {k: make() for k, (_n, make) in columns.items()}
    combos = [dict(zip(values, c, strict=True)) for c in itertools.product(*values.values())]
    out = []
    for r in rows or [{}]:
        for c in combos:
            out.append(c | dict(r))  # the member's own value wins
    return out


def _has_seed(model: registry.ModelSpec) -> bool:
    """Whether ``seed`` is a parameter of the model itself (declared, or a named argument of
    a user's plain factory) rather than the seed of the sweep's perturbation."""
    if model.params is not None:
        return "seed" in model.params
    try:
        signature = inspect.signature(model.function())
    except (TypeError, ValueError):  # a callable without a signature: not a named argument
        return False
    seed = signature.parameters.get("seed")
    return seed is not None and seed.kind in (seed.POSITIONAL_OR_KEYWORD, seed.KEYWORD_ONLY)


def _check_saved(n_steps: int, save_every: int) -> None:
    saved = n_steps // save_every + 1
    if saved > MAX_SAVED:
        raise SweepError(
            f"a member would save {saved:,} states (n_steps / save_every), more than "
            f"{MAX_SAVED:,}: save less often (a larger save_every)"
        )


def _build(table: dict[str, Any]) -> SweepSpec:
    unknown = set(table) - _TOP_KEYS
    if unknown:
        raise SweepError(
            f"unknown key(s) {', '.join(sorted(map(str, unknown)))} "
            f"(known: {', '.join(sorted(_TOP_KEYS))})"
        )
    if "model" not in table:
        raise SweepError("the sweep names no model")
    model = registry.load_model(table["model"])
    shared = _table(table.get("params", {}), "params")
    members_per_task = _int(table.get("members_per_task", MEMBERS_PER_TASK), "members_per_task", 1)
    perturb = table.get("perturb")
    if perturb is not None:
        perturb = _positive(perturb, "perturb")
    chunk_rows = _int(table.get("chunk_rows", 256), "chunk_rows", 1)
    flush_seconds = _positive(table.get("flush_seconds", 1.0), "flush_seconds")
    out = table.get("out")
    if out is not None and not (isinstance(out, str) and out):
        raise SweepError(f"out must be a directory name (a string), got {out!r}")
    initial = table.get("initial", [])
    if not isinstance(initial, list) or not all(isinstance(k, str) for k in initial):
        raise SweepError(f"initial must be a list of parameter names, got {initial!r}")
    if model.params is not None:
        for k in initial:
            if k not in model.params:
                raise SweepError(f"initial: model {model.name!r} has no parameter {k!r}")
    if model.builtin:  # its initial-data parameters are declared: the others change B
        for k in initial:
            if k not in model.initial:
                known = ", ".join(model.initial) or "none"
                raise SweepError(
                    f"initial: {k} of the built-in model {model.name!r} changes the model, not "
                    f"only the initial state (its initial-data parameters: {known})"
                )
    initial_all = tuple(dict.fromkeys([*model.initial, *initial]))
    own_seed = _has_seed(model)

    base = {k: table[k] for k in (*_RUN_KEYS, *_TIME_KEYS) if k in table}
    members: list[Member] = []
    grid_of: tuple[float, int] | None = None
    run: dict[str, Any] = {}
    seen: dict[str, int] = {}
    for i, row in enumerate(_rows(table)):
        what = f"member {i}"
        row = dict(row)
        times = {k: row.pop(k) for k in _TIME_KEYS if k in row}
        seed = row.pop("seed", None) if not own_seed else None
        if seed is not None:
            if perturb is None:
                raise SweepError(
                    f"{what}: seed without perturb (model {model.name!r} has no seed "
                    "parameter: a seed chooses the random perturbation of perturb = eps)"
                )
            seed = _int(seed, f"{what} seed", 0)
        params = shared | row
        if times:  # a member's own time keys replace the file's
            config = {k: base[k] for k in _RUN_KEYS if k in base} | times
        else:
            config = dict(base)
        try:
            cfg = registry.normalize_config(
                {"model": model.name, "params": params, **config}, model=model
            )
        except (IsoflowError, ValueError, TypeError) as exc:
            raise SweepError(f"{what}: {' '.join(str(exc).split())}") from None
        dt, n = time_grid(cfg["t0"], cfg.get("t1"), cfg.get("dt"), cfg.get("n_steps"))
        if n < 1:  # a run of no step (its readers want at least one)
            raise SweepError(f"{what}: a sweep takes at least one step, got n_steps = {n}")
        if grid_of is None:
            grid_of = (dt, n)
            run = {k: cfg[k] for k in ("method", "solver", "rtol", "anderson") if k in cfg}
            run |= {"t0": cfg["t0"], "dt": dt, "n_steps": n, "save_every": cfg["save_every"]}
            _check_saved(n, cfg["save_every"])
        elif (dt, n) != grid_of:
            raise SweepError(
                f"{what}: the time grid (dt = {dt:g}, {n} steps) differs from member 0's "
                f"(dt = {grid_of[0]:g}, {grid_of[1]} steps); a sweep has one time grid"
            )
        if perturb is not None:
            if own_seed:
                seed = int(cfg["params"].get("seed", 0))
            elif seed is None:
                seed = i
        m = Member(i, cfg["params"], seed)
        key = canonical_json(m.key())
        if key in seen:
            raise SweepError(
                f"{what} duplicates member {seen[key]} (same parameters and seed): "
                f"{canonical_json(m.params)}"
            )
        seen[key] = i
        members.append(m)

    spec = SweepSpec(
        model=model.name,
        run=run,
        members=tuple(members),
        tasks=(),
        perturb=perturb,
        initial=initial_all,
        members_per_task=members_per_task,
        chunk_rows=chunk_rows,
        flush_seconds=flush_seconds,
        out=out,
        source=json.loads(json.dumps(table, default=str)),
    )
    return _with_tasks(spec)


def _with_tasks(spec: SweepSpec) -> SweepSpec:
    """Group the members by their parameters without the initial-data ones (table order) and
    split each group into ensembles of at most ``members_per_task``."""
    groups: dict[str, list[Member]] = {}
    for m in spec.members:
        dyn = {k: v for k, v in m.params.items() if k not in spec.initial}
        groups.setdefault(canonical_json(dyn), []).append(m)
    tasks = []
    for group in groups.values():
        for start in range(0, len(group), spec.members_per_task):
            chunk = tuple(group[start : start + spec.members_per_task])
            digest = spec.task_digest(chunk)
            tasks.append(Task(digest[:20], chunk, digest))
    return dataclasses.replace(spec, tasks=tuple(tasks))
