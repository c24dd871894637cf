r"""Streaming result files (HDF5), restart, readers, and export to xarray / netCDF.

A run streamed with :class:`HDF5Writer` (``iso.solve(..., writer=HDF5Writer(path))`` or
``isoflow run``) is one HDF5 file:

* attributes ``isoflow_format = "isoflow-run"``, ``isoflow_format_version``, ``isoflow_version``,
  ``config`` (the run configuration, JSON) and ``meta`` (times, method, algebra; JSON). Nothing is
  pickled or evaluated: every structured attribute is ``json.dumps`` text;
* ``ts`` ``(n,)`` and ``ys`` ``(n, *shape)``: saved times and states, resizable and chunked;
* ``diagnostics/...``: per saved state Casimirs, distance to ``V``, Hamiltonian, Lyapunov
  function and the problem's invariants;
* ``checkpoint/slot0`` and ``checkpoint/slot1`` with ``checkpoint/current``: the last checkpoint
  (step index, number of valid rows, state and method state, serialized as raw bytes plus a JSON
  description), written alternately so that one complete checkpoint always exists;
* ``run_info``: JSON of the status, message and statistics, written when the run ends.

Crash safety
------------
The file is written in HDF5's single-writer/multiple-reader (SWMR) mode (``libver="latest"``),
which orders metadata writes so that the file stays readable at every moment, and flushed after
every chunk. Each chunk is written as: rows, flush, the *other* checkpoint slot, flush, the
``current`` slot index, flush. So after a kill at any moment (SIGKILL included) the file opens (with
:func:`load`, :func:`info` or ``isoflow info``), and ``current`` names a complete checkpoint whose
row count says which rows are valid: every state flushed before the kill. Until the initial
state is checkpointed the file is written as ``<path>.partial`` and then renamed, so a kill
during set-up leaves no file at ``path`` (and never replaces an existing one with an empty
file). This is tested by killing ``isoflow run`` with SIGKILL at random moments and resuming.

A file killed while in SWMR write mode keeps HDF5's "open for writing" flag, so HDF5 refuses to
open it for writing again; :func:`resume` then first rewrites its valid part into a fresh file
(chunk by chunk, bounded memory) and replaces the old one. Do not resume a file that another
process is still writing.

Resume
------
:func:`resume` reads the last checkpoint, rebuilds the problem and method from the stored
configuration (:mod:`isoflow.registry`; or takes them as arguments), truncates the file to the
checkpoint and continues appending. The per-step arithmetic, the method state (e.g. IsoMP's warm
start) and the step ranges between saves are those of the uninterrupted run, so the final state
equals an uninterrupted run's bit for bit.
"""

from __future__ import annotations

import json
import os
import struct
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from ._errors import IsoflowError
from ._solve import RunState, Solution, StreamWriter, continue_run
from ._stepping import MemberFailures
from .diagnostics import Diagnostics, DiagnosticsAccumulator, DriftAccumulator
from .methods import Method
from .problems import IsospectralProblem

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "Checkpoint",
    "HDF5Writer",
    "ResultFileError",
    "RunData",
    "StreamWriter",
    "info",
    "load",
    "resume",
    "solution_diagnostics",
    "to_netcdf",
    "to_xarray",
]

Array = NDArray[Any]

FORMAT = "isoflow-run"
FORMAT_VERSION = 1
_READ_CHUNK = 4096


class ResultFileError(IsoflowError, OSError):
    """A path is not a readable isoflow result file (missing, not HDF5, not ours, truncated)."""


def _version() -> str:
    from . import __version__

    return __version__


# --- method state <-> bytes -------------------------------------------------------------------


def _pack_state(state: Any) -> tuple[bytes, bytes]:
    """``(blob, description)`` of a method state: ``None`` or a tuple of floats/ints/arrays."""
    if state is None:
        return b"", json.dumps(None).encode()
    if not isinstance(state, tuple):
        raise TypeError(f"a method state must be None or a tuple, got {type(state).__name__}")
    parts: list[bytes] = []
    desc: list[dict[str, Any]] = []
    offset = 0
    for item in state:
        if item is None:
            desc.append({"kind": "none"})
            continue
        entry: dict[str, Any]
        if isinstance(item, bool | np.bool_):
            raw, entry = bytes([int(item)]), {"kind": "bool"}
        elif isinstance(item, int | np.integer):
            raw, entry = struct.pack("<q", int(item)), {"kind": "int"}
        elif isinstance(item, float | np.floating) and np.ndim(item) == 0:
            raw, entry = struct.pack("<d", float(item)), {"kind": "float"}
        else:
            arr = np.ascontiguousarray(item)
            raw = arr.tobytes()
            entry = {"kind": "array", "dtype": arr.dtype.str, "shape": list(arr.shape)}
        entry.update(offset=offset, nbytes=len(raw))
        desc.append(entry)
        parts.append(raw)
        offset += len(raw)
    return b"".join(parts), json.dumps(desc).encode()


def _unpack_state(blob: bytes, description: bytes) -> Any:
    desc = json.loads(description.decode())
    if desc is None:
        return None
    out: list[Any] = []
    for e in desc:
        if e["kind"] == "none":
            out.append(None)
            continue
        raw = blob[e["offset"] : e["offset"] + e["nbytes"]]
        if e["kind"] == "bool":
            out.append(bool(raw[0]))
        elif e["kind"] == "int":
            out.append(struct.unpack("<q", raw)[0])
        elif e["kind"] == "float":
            out.append(struct.unpack("<d", raw)[0])
        else:
            arr = np.frombuffer(raw, dtype=np.dtype(e["dtype"])).reshape(e["shape"]).copy()
            out.append(arr)
    return tuple(out)


def _write_bytes(ds: h5py.Dataset, data: bytes) -> None:
    ds.resize((len(data),))
    if data:
        ds[:] = np.frombuffer(data, dtype=np.uint8)


def _read_bytes(ds: h5py.Dataset) -> bytes:
    return bytes(np.asarray(ds[:], dtype=np.uint8))


# --- writer -------------------------------------------------------------------------------------


class HDF5Writer:
    """Stream a run to an HDF5 file (see the module docstring for the layout and guarantees).

    Parameters
    ----------
    path : str or Path
        The file to create (an existing file is replaced).
    config : dict, optional
        JSON-ready description of the run, stored as the ``config`` attribute. A configuration
        in :mod:`isoflow.registry` form lets :func:`resume` rebuild the problem by itself.
    chunk_rows : int
        Saved states buffered in memory before they are written (and a checkpoint taken).
    flush_seconds : float
        Also write (and checkpoint) when this much time passed since the last write.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, W0 = iso.models.rigid_body(n=4)
    >>> sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=20,
    ...                 writer=iso.io.HDF5Writer("rb.h5"))  # doctest: +SKIP
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        config: dict[str, Any] | None = None,
        *,
        chunk_rows: int = 256,
        flush_seconds: float = 1.0,
    ) -> None:
        if int(chunk_rows) < 1:
            raise ValueError(f"chunk_rows must be >= 1, got {chunk_rows!r}")
        self.path = Path(path)
        self.config = {} if config is None else dict(config)
        json.dumps(self.config)  # fail early on anything that is not JSON
        self.chunk_rows = int(chunk_rows)
        self.flush_seconds = float(flush_seconds)
        self._f: h5py.File | None = None
        self._partial: Path | None = None
        self._meta: dict[str, Any] | None = None
        self._n_rows = 0
        self._slot = -1

    # the protocol -------------------------------------------------------------------------

    def open(self, meta: dict[str, Any]) -> None:
        """Create the file with its attributes; datasets follow with the first rows."""
        self._meta = dict(meta)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # written under a temporary name until the first checkpoint, so that a kill while the
        # file is being set up never leaves (or replaces) a file at ``path`` without states
        self._partial = self.path.with_name(self.path.name + ".partial")
        f = h5py.File(self._partial, "w", libver="latest")
        f.attrs["isoflow_format"] = FORMAT
        f.attrs["isoflow_format_version"] = FORMAT_VERSION
        f.attrs["isoflow_version"] = _version()
        f.attrs["created"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        f.attrs["config"] = json.dumps(self.config)
        f.attrs["meta"] = json.dumps(self._meta)
        self._f = f
        self._n_rows = 0
        self._slot = -1

    def _create(self, ys: Array, series: dict[str, Array]) -> None:
        f = self._f
        assert f is not None
        shape = ys.shape[1:]
        members = int(np.prod(shape[: len(shape) - len(self._meta_core())], dtype=np.int64))
        row_bytes = max(int(np.prod(shape)) * ys.dtype.itemsize, 1)
        crow = max(1, min(self.chunk_rows, (1 << 20) // row_bytes))
        f.create_dataset("ts", shape=(0,), maxshape=(None,), chunks=(max(crow, 64),), dtype="f8")
        f.create_dataset(
            "ys", shape=(0, *shape), maxshape=(None, *shape), chunks=(crow, *shape), dtype=ys.dtype
        )
        g = f.create_group("diagnostics")
        for name, v in series.items():
            s = v.shape[1:]
            g.create_dataset(
                name, shape=(0, *s), maxshape=(None, *s), chunks=(max(crow, 64), *s), dtype=v.dtype
            )
        cp = f.create_group("checkpoint")
        for i in (0, 1):
            slot = cp.create_group(f"slot{i}")
            slot.create_dataset("y", shape=shape, dtype=ys.dtype)
            slot.create_dataset("index", shape=(2,), dtype="i8", data=np.array([-1, 0]))
            slot.create_dataset("failures", shape=(members, 4), dtype="f8")
            for name in ("state_blob", "state_desc", "failures_msg"):
                slot.create_dataset(name, shape=(0,), maxshape=(None,), chunks=(4096,), dtype="u1")
        cp.create_dataset("current", shape=(1,), dtype="i8", data=np.array([-1]))
        f.create_dataset("run_info", shape=(0,), maxshape=(None,), chunks=(1024,), dtype="u1")
        f.swmr_mode = True  # from here on: no new objects or attributes, only data and resizes

    def _meta_core(self) -> tuple[int, ...]:
        """The shape of one member's state (from the run's algebra shape in ``meta``)."""
        assert self._meta is not None
        return tuple(self._meta.get("core_shape", self._meta["state_shape"]))

    def append(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        """Write saved states ``ys`` at ``ts`` and their diagnostics (durable at checkpoint)."""
        f = self._f
        if f is None:
            raise ValueError("HDF5Writer.append before open")
        if "ys" not in f:
            self._create(ys, series)
        n0, m = self._n_rows, len(ts)
        for name, data in (("ts", ts), ("ys", ys)):
            ds = f[name]
            ds.resize(n0 + m, axis=0)
            ds[n0:] = data
        for name, v in series.items():
            ds = f["diagnostics"][name]
            ds.resize(n0 + m, axis=0)
            ds[n0:] = v
        self._n_rows = n0 + m

    def checkpoint(
        self, step: int, y: Array, method_state: Any, failures: MemberFailures | None = None
    ) -> None:
        """Flush the rows, then write a complete checkpoint into the spare slot and point to it."""
        f = self._f
        assert f is not None
        f.flush()
        slot = 1 - self._slot if self._slot >= 0 else 0
        g = f["checkpoint"][f"slot{slot}"]
        blob, desc = _pack_state(method_state)
        g["y"][...] = y
        _write_bytes(g["state_blob"], blob)
        _write_bytes(g["state_desc"], desc)
        rec = g["failures"]
        if failures is None:
            rec[...] = np.array([-1.0, 0.0, 0.0, 0.0])
            _write_bytes(g["failures_msg"], b"")
        else:
            rec[...] = np.stack(
                [failures.step, failures.status, failures.iterations, failures.residual], axis=-1
            )
            msgs = {str(k): v for k, v in failures.messages.items()}
            _write_bytes(g["failures_msg"], json.dumps(msgs).encode())
        g["index"][:] = np.array([int(step), self._n_rows])
        f.flush()
        f["checkpoint"]["current"][0] = slot
        f.flush()
        self._slot = slot
        self._publish()

    def _publish(self) -> None:
        """Move the file from its temporary name to ``path`` (after the first checkpoint)."""
        if self._partial is not None:
            os.replace(self._partial, self.path)
            self._partial = None

    def close(self, info: dict[str, Any]) -> None:
        """Store the run's final status and statistics and close the file."""
        f = self._f
        if f is None:
            return
        try:
            if "run_info" in f:
                _write_bytes(f["run_info"], json.dumps(info, default=float).encode())
            f.flush()
        finally:
            f.close()
            self._f = None
            self._publish()

    # resuming -------------------------------------------------------------------------------

    @classmethod
    def _reopen(
        cls, path: Path, n_rows: int, slot: int, chunk_rows: int, flush_seconds: float
    ) -> HDF5Writer:
        """Open an existing file for appending after row ``n_rows`` (checkpoint ``slot``)."""
        w = cls(path, chunk_rows=chunk_rows, flush_seconds=flush_seconds)
        f = h5py.File(path, "a", libver="latest")
        w.config = json.loads(f.attrs["config"])
        w._meta = json.loads(f.attrs["meta"])
        for name in ("ts", "ys"):
            f[name].resize(n_rows, axis=0)
        for ds in _series_datasets(f):
            ds.resize(n_rows, axis=0)
        _write_bytes(f["run_info"], b"")
        f.flush()
        f.swmr_mode = True
        w._f, w._n_rows, w._slot = f, n_rows, slot
        return w


def _series_datasets(f: h5py.File) -> list[h5py.Dataset]:
    out: list[h5py.Dataset] = []
    f["diagnostics"].visititems(
        lambda _n, obj: out.append(obj) if isinstance(obj, h5py.Dataset) else None
    )
    return out


# --- reading ------------------------------------------------------------------------------------


def _check_not_truncated(p: Path) -> None:
    """Compare the superblock's end-of-file address with the file size (HDF5 superblock v2/v3).

    A cut file would otherwise make HDF5's SWMR reader retry its reads for a long time.
    """
    with p.open("rb") as fh:
        head = fh.read(36)
    if len(head) < 36 or head[:8] != b"\x89HDF\r\n\x1a\n":
        return  # not HDF5 (or superblock at an offset): h5py reports it
    if head[8] in (2, 3) and head[9] == 8:
        eof = struct.unpack("<Q", head[28:36])[0]
        size = p.stat().st_size
        if size < eof:
            raise ResultFileError(
                f"{p}: truncated HDF5 file ({size} of {eof} bytes); not a readable result file"
            )


@contextmanager
def _open_read(path: str | os.PathLike[str]) -> Iterator[h5py.File]:
    p = Path(path)
    if not p.exists():
        raise ResultFileError(f"{p}: no such file")
    if p.is_dir():
        raise ResultFileError(f"{p}: is a directory, not a result file")
    _check_not_truncated(p)
    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        if "already open for write" not in str(exc):
            kind = "truncated or not an HDF5 file" if not h5py.is_hdf5(p) else "damaged"
            raise ResultFileError(f"{p}: not an isoflow result file ({kind})") from None
        # a run still being written, or killed while writing (SWMR): open it as a SWMR reader
        try:
            f = h5py.File(p, "r", swmr=True)
        except OSError as exc2:
            raise ResultFileError(f"{p}: unreadable result file ({exc2})") from None
    try:
        if f.attrs.get("isoflow_format") != FORMAT:
            raise ResultFileError(f"{p}: an HDF5 file, but not an isoflow result file")
        version = int(f.attrs.get("isoflow_format_version", -1))
        if version > FORMAT_VERSION:
            raise ResultFileError(
                f"{p}: result format version {version} is newer than this isoflow reads "
                f"({FORMAT_VERSION}); upgrade isoflow"
            )
        yield f
    except (KeyError, OSError, ValueError) as exc:
        if isinstance(exc, IsoflowError):
            raise
        raise ResultFileError(f"{p}: damaged isoflow result file ({exc})") from None
    finally:
        f.close()


@dataclass(frozen=True)
class Checkpoint:
    """The last complete checkpoint of a result file."""

    step: int
    n_rows: int
    slot: int
    y: Array
    method_state: Any
    failures: MemberFailures | None = None


def _read_checkpoint(f: h5py.File) -> Checkpoint | None:
    if "checkpoint" not in f:
        return None
    slot = int(f["checkpoint"]["current"][0])
    if slot < 0:
        return None
    g = f["checkpoint"][f"slot{slot}"]
    step, n_rows = (int(v) for v in g["index"][:])
    state = _unpack_state(_read_bytes(g["state_blob"]), _read_bytes(g["state_desc"]))
    failures = None
    if "failures" in g:
        rec = np.asarray(g["failures"][...], dtype=float)
        if np.any(rec[:, 0] >= 0):
            msg = _read_bytes(g["failures_msg"])
            failures = MemberFailures(
                step=rec[:, 0].astype(np.int64),
                status=rec[:, 1].astype(np.int64),
                iterations=rec[:, 2].astype(np.int64),
                residual=rec[:, 3].copy(),
                messages={int(k): str(v) for k, v in json.loads(msg or b"{}").items()},
            )
    return Checkpoint(step, n_rows, slot, np.asarray(g["y"][...]), state, failures)


def _read_run_info(f: h5py.File) -> dict[str, Any] | None:
    if "run_info" not in f or f["run_info"].shape[0] == 0:
        return None
    return json.loads(_read_bytes(f["run_info"]).decode())


def _accumulate(f: h5py.File, n_rows: int) -> dict[str, Any]:
    """Drifts over the stored diagnostic series, read chunk by chunk (worst member)."""
    dsets = {ds.name.split("/diagnostics/", 1)[1]: ds for ds in _series_datasets(f)}
    if not n_rows or not dsets:
        return {}
    meta = json.loads(f.attrs["meta"])
    shape = tuple(meta["state_shape"])
    core = tuple(meta.get("core_shape", shape[-2:]))
    acc = DriftAccumulator(meta.get("casimir_scale", 1.0), len(shape) - len(core))
    for start in range(0, n_rows, _READ_CHUNK):
        stop = min(start + _READ_CHUNK, n_rows)
        acc.absorb(
            np.asarray(f["ts"][start:stop]),
            {k: np.asarray(ds[start:stop]) for k, ds in dsets.items()},
        )
    return {k: float(np.max(v)) for k, v in acc.drifts().items()}


def info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What a result file holds, as a JSON-ready dict (without loading the states).

    Keys: ``path``, ``isoflow_version``, ``created``, ``config``, ``meta``, ``n_saved`` (valid
    saved states), ``t_last``, ``step`` (steps behind the last checkpoint), ``complete``,
    ``run_info`` (``None`` when the run was killed) and ``drifts`` (over the valid states).
    """
    with _open_read(path) as f:
        config = json.loads(f.attrs["config"])
        meta = json.loads(f.attrs["meta"])
        cp = _read_checkpoint(f)
        n_rows = 0 if cp is None else cp.n_rows
        run_info = _read_run_info(f)
        t_last = float(f["ts"][n_rows - 1]) if n_rows else None
        drifts = _accumulate(f, n_rows) if n_rows else {}
        return {
            "path": str(path),
            "isoflow_version": str(f.attrs.get("isoflow_version", "?")),
            "created": str(f.attrs.get("created", "?")),
            "config": config,
            "meta": meta,
            "n_saved": n_rows,
            "t_last": t_last,
            "step": None if cp is None else cp.step,
            "complete": cp is not None and cp.step == int(meta.get("n_steps", -1)),
            "run_info": run_info,
            "drifts": drifts,
        }


@dataclass(frozen=True)
class RunData:
    """A result file read into memory (:func:`load`).

    Attributes
    ----------
    ts, ys : ndarray
        The valid saved times and states (time first).
    series : dict
        Per saved state diagnostics: ``casimirs``, ``distance``, ``hamiltonian``, ... and
        ``invariants/<name>``.
    config, meta : dict
        The run configuration and the run's times/method/algebra description.
    run_info : dict or None
        Status, message and statistics of the finished run; ``None`` if it was killed.
    step : int
        Steps behind the last saved state.
    drifts : dict
        Drifts over all saved states (as ``Diagnostics.summary``).
    """

    ts: Array
    ys: Array
    series: dict[str, Array]
    config: dict[str, Any]
    meta: dict[str, Any]
    run_info: dict[str, Any] | None
    step: int
    drifts: dict[str, float] = field(default_factory=dict)

    @property
    def y_final(self) -> Array:
        """The last saved state."""
        return self.ys[-1]

    @property
    def complete(self) -> bool:
        """Whether all requested steps are in the file."""
        return self.step == int(self.meta.get("n_steps", -1))


def load(path: str | os.PathLike[str]) -> RunData:
    """Read a result file (also one whose run was killed: its valid states) into memory."""
    with _open_read(path) as f:
        cp = _read_checkpoint(f)
        if cp is None:
            raise ResultFileError(f"{path}: the run was stopped before its first state was saved")
        n = cp.n_rows
        series = {
            ds.name.split("/diagnostics/", 1)[1]: np.asarray(ds[:n]) for ds in _series_datasets(f)
        }
        return RunData(
            ts=np.asarray(f["ts"][:n]),
            ys=np.asarray(f["ys"][:n]),
            series=series,
            config=json.loads(f.attrs["config"]),
            meta=json.loads(f.attrs["meta"]),
            run_info=_read_run_info(f),
            step=cp.step,
            drifts=_accumulate(f, n),
        )


def _recover(path: Path) -> None:
    """Rewrite the valid part of a killed file into a fresh file (clears HDF5's write flag)."""
    tmp = path.with_name(path.name + ".recover")
    with _open_read(path) as src, h5py.File(tmp, "w", libver="latest") as dst:
        cp = _read_checkpoint(src)
        assert cp is not None
        n = cp.n_rows
        for key, value in src.attrs.items():
            dst.attrs[key] = value

        def copy_rows(name: str, ds: h5py.Dataset) -> None:
            out = dst.create_dataset(
                name,
                shape=(n, *ds.shape[1:]),
                maxshape=ds.maxshape,
                chunks=ds.chunks,
                dtype=ds.dtype,
            )
            for start in range(0, n, _READ_CHUNK):
                stop = min(start + _READ_CHUNK, n)
                out[start:stop] = ds[start:stop]

        copy_rows("ts", src["ts"])
        copy_rows("ys", src["ys"])
        for ds in _series_datasets(src):
            copy_rows(ds.name, ds)
        src.copy(src["checkpoint"], dst, name="checkpoint")
        dst.create_dataset("run_info", shape=(0,), maxshape=(None,), chunks=(1024,), dtype="u1")
    os.replace(tmp, path)


def resume(
    path: str | os.PathLike[str],
    *,
    problem: IsospectralProblem | None = None,
    method: Method | None = None,
    progress: bool | None = None,
    throw: bool = True,
    chunk_rows: int = 256,
    flush_seconds: float = 1.0,
) -> Solution:
    """Continue a streamed run from its last checkpoint, appending to the same file.

    Parameters
    ----------
    path : str or Path
        A result file written by :class:`HDF5Writer` (complete, stopped or killed).
    problem, method : optional
        The run's problem and method; by default rebuilt from the file's configuration with
        :func:`isoflow.registry.build` (needed for runs of your own problems).
    progress, throw :
        As in :func:`isoflow.solve`.
    chunk_rows, flush_seconds :
        As in :class:`HDF5Writer`.

    Returns
    -------
    Solution
        As :func:`isoflow.solve` with a writer: the checkpoint state and the final state, and the
        drifts over all saved states of the file.
    """
    p = Path(path)
    with _open_read(p) as f:
        config = json.loads(f.attrs["config"])
        meta = json.loads(f.attrs["meta"])
        cp = _read_checkpoint(f)
    if cp is None:
        raise ResultFileError(f"{p}: no checkpoint to resume from (start the run again)")
    if problem is None or method is None:
        if not config.get("model"):
            raise ResultFileError(
                f"{p}: the file's configuration names no registered model; pass problem= and "
                "method= to resume it"
            )
        from .registry import build

        prob_b, _y0, meth_b, _kw = build(config)
        problem = problem if problem is not None else prob_b
        method = method if method is not None else meth_b
    if method.name != meta.get("method"):
        raise ResultFileError(f"{p}: the run used {meta.get('method')!r}, not {method.name!r}")
    try:
        writer = HDF5Writer._reopen(p, cp.n_rows, cp.slot, chunk_rows, flush_seconds)
    except OSError:
        _recover(p)
        writer = HDF5Writer._reopen(p, cp.n_rows, cp.slot, chunk_rows, flush_seconds)
    acc = DiagnosticsAccumulator(problem)
    try:
        f = writer._f
        assert f is not None
        acc.set_first_state(np.asarray(f["ys"][0]))
        dsets = {ds.name.split("/diagnostics/", 1)[1]: ds for ds in _series_datasets(f)}
        for start in range(0, cp.n_rows, _READ_CHUNK):
            stop = min(start + _READ_CHUNK, cp.n_rows)
            acc.absorb(
                np.asarray(f["ts"][start:stop]),
                {k: np.asarray(ds[start:stop]) for k, ds in dsets.items()},
            )
    except BaseException:
        writer.close({"status": 2, "message": "resume failed", "steps_done": cp.step})
        raise
    return continue_run(
        problem,
        method,
        RunState(cp.step, cp.y, cp.method_state, cp.failures),
        t0=float(meta["t0"]),
        dt=float(meta["dt"]),
        n_steps=int(meta["n_steps"]),
        save_every=int(meta["save_every"]),
        writer=writer,
        accumulator=acc,
        progress=progress,
        throw=throw,
    )


# --- export -------------------------------------------------------------------------------------


def to_xarray(path: str | os.PathLike[str]) -> Any:
    """The valid saved states and diagnostics of a result file as an :class:`xarray.Dataset`.

    Variables: ``y`` (or ``y_real``/``y_imag`` for complex states, so that netCDF can hold
    them) with dimensions ``("time", "dim_0", ...)`` and the diagnostic series; attributes
    ``config`` and ``meta`` as JSON strings.
    """
    try:
        import xarray as xr
    except ImportError as exc:  # pragma: no cover - optional dependency
        raise IsoflowError("to_xarray needs xarray: pip install 'isoflow[xarray]'") from exc
    run = load(path)
    data_vars: dict[str, Any] = {}

    def add(name: str, arr: Array) -> None:
        dims = ("time", *(f"{name}_dim{i}" for i in range(arr.ndim - 1)))
        if np.iscomplexobj(arr):
            data_vars[f"{name}_real"] = (dims, arr.real)
            data_vars[f"{name}_imag"] = (dims, arr.imag)
        else:
            data_vars[name] = (dims, arr)

    add("y", run.ys)
    for name, arr in run.series.items():
        add(name.replace("/", "_"), arr)
    return xr.Dataset(
        data_vars,
        coords={"time": run.ts},
        attrs={
            "config": json.dumps(run.config),
            "meta": json.dumps(run.meta),
            "isoflow_step": run.step,
        },
    )


def to_netcdf(path: str | os.PathLike[str], out: str | os.PathLike[str]) -> Path:
    """Export a result file to netCDF-4 (engine ``h5netcdf``); returns the output path."""
    ds = to_xarray(path)
    ds.to_netcdf(out, engine="h5netcdf")
    return Path(out)


def solution_diagnostics(run: RunData, problem: IsospectralProblem) -> Diagnostics:
    """Full :class:`Diagnostics` (time series and drifts) of a loaded run for ``problem``."""
    acc = DiagnosticsAccumulator(problem)
    acc.set_first_state(run.ys[0])
    acc.absorb(run.ts, run.series)
    d = acc.result()
    return Diagnostics(
        ts=run.ts,
        casimirs=run.series["casimirs"],
        casimir_drift=d.casimir_drift,
        distance=run.series["distance"],
        max_distance=d.max_distance,
        hamiltonian=run.series.get("hamiltonian"),
        hamiltonian_drift=d.hamiltonian_drift,
        hamiltonian_relative_drift=d.hamiltonian_relative_drift,
        lyapunov=run.series.get("lyapunov"),
        lyapunov_max_decrease=d.lyapunov_max_decrease,
        invariants={k: run.series[f"invariants/{k}"] for k in d.invariants},
        invariant_drift=d.invariant_drift,
    )
