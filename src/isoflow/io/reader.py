"""Opening and validating result files: :func:`load`, :func:`info`, :class:`RunData`.

Every field is validated before it is used (the format, the JSON attributes, the time grid and
shapes in ``meta``, the checkpoint's step and row counts, the dataset shapes and dtypes), and
the rows read are checked against the file's CRC-32 checksums (format version 2). A damaged or
crafted file gives a one-line :class:`~isoflow.ResultFileError`; never another exception, never
silently different data, never a hang: a file whose writer is not alive is read through a
:class:`~isoflow.io.safefile.ReadView`, not in HDF5's retrying SWMR mode.
"""

from __future__ import annotations

import math
import os
import struct
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import h5py
import numpy as np
from numpy.typing import NDArray

from .._errors import IsoflowError, ResultFileError
from .._failures import MemberFailures
from .._flags import check_flag
from .._save_grid import SaveGrid
from ..diagnostics import DriftAccumulator
from .codec import (
    check_shape,
    crc_of,
    decode_failures,
    decode_json,
    numeric_dtype,
    unpack_state,
)
from .layout import FORMAT, FORMAT_VERSION, READ_CHUNK, SLOT_BYTES, header_crc, slot_crc
from .lock import is_live
from .safefile import ReadView

__all__ = [
    "Checkpoint",
    "Opened",
    "RunData",
    "info",
    "iter_rows",
    "load",
    "open_result",
    "read_checkpoint",
]

Array = NDArray[Any]

#: Largest saved state a file may describe (bytes); more is a crafted or damaged field.
MAX_STATE_BYTES = 1 << 30
#: Largest byte field of a checkpoint slot (method state, messages, status).
_MAX_SLOT_BYTES = 1 << 28
_MAX_STEPS = 1 << 53
#: Reads of a live file tried before its error is reported.
_LIVE_TRIES = 20
_T = TypeVar("_T")
_TRANSIENT = (KeyError, OSError, ValueError, TypeError, IndexError, OverflowError, RuntimeError)


@dataclass(frozen=True)
class Checkpoint:
    """The last complete checkpoint of a result file.

    Attributes
    ----------
    step, n_rows : int
        Steps done and valid saved rows.
    slot : int
        The checkpoint slot (0 or 1).
    y, method_state, failures :
        What the run continues from.
    n_blocks : int
        Valid checksum blocks (0 in version 1 files).
    run_info : dict or None
        The run's final status, ``None`` while it runs (or when it was killed).
    """

    step: int
    n_rows: int
    slot: int
    y: Array
    method_state: Any
    failures: MemberFailures | None = None
    n_blocks: int = 0
    run_info: dict[str, Any] | None = None


@dataclass
class Opened:
    """An open, validated result file (inside :func:`open_result`).

    Parameters
    ----------
    path : Path
        The file.
    f : h5py.File
        The open file.
    version : int
        The format version (1 or 2).
    config, meta : dict
        The recorded configuration and metadata.
    live : str or None
        ``"pid N on HOST"`` of a writer holding the file's lock, else ``None``.
    flagged : bool
        The file was not closed by its writer, and no writer is alive (a killed run).
    rows : dict of str to h5py.Dataset
        The row datasets: ``ts``, ``ys``, then the diagnostic series.
    checksums : h5py.Dataset or None
        The checksum rows (``None`` in version 1 files).
    """

    path: Path
    f: h5py.File
    version: int
    config: dict[str, Any]
    meta: dict[str, Any]
    live: str | None
    flagged: bool
    rows: dict[str, h5py.Dataset]
    checksums: h5py.Dataset | None

    def fail(self, what: str) -> ResultFileError:
        """A :class:`ResultFileError` about this file.

        Parameters
        ----------
        what : str
            What is wrong (the message after the path).

        Returns
        -------
        ResultFileError
            To be raised by the caller.
        """
        return ResultFileError(f"{self.path}: {what}")


def _number(meta: dict[str, Any], key: str, p: Path, positive: bool = False) -> float:
    v = meta.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise ResultFileError(f"{p}: meta field {key!r} = {v!r} is not a finite number")
    if positive and v <= 0:
        raise ResultFileError(f"{p}: meta field {key!r} = {v!r} is not positive")
    return float(v)


def _integer(meta: dict[str, Any], key: str, p: Path, lo: int, hi: int) -> int:
    v = meta.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise ResultFileError(f"{p}: meta field {key!r} = {v!r} is not an integer in {lo}..{hi}")
    return int(v)


def _validate_meta(meta: dict[str, Any], p: Path) -> None:
    _number(meta, "t0", p)
    _number(meta, "dt", p, positive=True)
    _integer(meta, "n_steps", p, 0, _MAX_STEPS)
    _integer(meta, "save_every", p, 1, _MAX_STEPS)
    for key in ("method", "algebra"):
        if not isinstance(meta.get(key), str):
            raise ResultFileError(f"{p}: meta field {key!r} is not a string")
    try:
        shape = check_shape(meta.get("state_shape"), "state shape", max_elements=1 << 28)
        core = check_shape(meta.get("core_shape", list(shape)), "core shape")
        dtype = numeric_dtype(meta.get("state_dtype", "<f8"), "state dtype")
    except ResultFileError as exc:
        raise ResultFileError(f"{p}: {exc}") from None
    if len(core) > len(shape) or shape[len(shape) - len(core) :] != core:
        raise ResultFileError(f"{p}: core shape {core} does not end the state shape {shape}")
    if math.prod(shape) * dtype.itemsize > MAX_STATE_BYTES:
        raise ResultFileError(f"{p}: a state of shape {shape} is too large for a result file")
    if not _numbers(meta.get("casimir_scale", 1.0), depth=8):
        raise ResultFileError(f"{p}: meta field 'casimir_scale' is not numeric")


def _numbers(value: Any, depth: int) -> bool:
    """``value`` is a number or nested lists of numbers (at most ``depth`` deep)."""
    if isinstance(value, list):
        return depth > 0 and all(_numbers(v, depth - 1) for v in value)
    return isinstance(value, int | float) and not isinstance(value, bool)


def _check_truncated(p: Path, head: bytes) -> None:
    """Compare the superblock's end-of-file address with the file size (superblock v2/v3)."""
    if len(head) >= 36 and head[:8] == b"\x89HDF\r\n\x1a\n" and head[8] in (2, 3):
        if head[9] == 8:
            eof = struct.unpack("<Q", head[28:36])[0]
            size = p.stat().st_size
            if size < eof:
                raise ResultFileError(
                    f"{p}: truncated HDF5 file ({size} of {eof} bytes); not a readable result file"
                )


def _attr_text(f: h5py.File, key: str, p: Path) -> str:
    v = f.attrs.get(key)
    if isinstance(v, bytes):
        v = v.decode(errors="replace")
    if not isinstance(v, str):
        raise ResultFileError(f"{p}: attribute {key!r} is missing or not text")
    return v


def _series(f: h5py.File) -> dict[str, h5py.Dataset]:
    out: dict[str, h5py.Dataset] = {}
    if "diagnostics" not in f:
        return out

    def visit(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Dataset):
            out[name] = obj

    f["diagnostics"].visititems(visit)
    if len(out) > 256:
        raise ResultFileError("too many diagnostics datasets")
    return out


def _validate_datasets(o: Opened) -> None:
    f, meta = o.f, o.meta
    shape = tuple(meta["state_shape"])
    if "ts" not in f:  # a run stopped before its first rows (version 1)
        return
    ts, ys = f["ts"], f["ys"]
    if ts.ndim != 1 or ts.dtype.kind != "f":
        raise o.fail(f"dataset ts has shape {ts.shape} and dtype {ts.dtype}")
    if tuple(ys.shape[1:]) != shape or ys.dtype.kind not in "biufc":
        raise o.fail(f"dataset ys has shape {ys.shape} ({ys.dtype}); meta says states {shape}")
    series = _series(f)
    for name, ds in series.items():
        if ds.ndim < 1 or ds.dtype.kind not in "biufc" or math.prod(ds.shape[1:]) > (1 << 24):
            raise o.fail(f"diagnostics dataset {name} has shape {ds.shape} ({ds.dtype})")
    o.rows = {"ts": ts, "ys": ys, **series}
    if o.version >= 2:
        cs = f["checksums"]
        columns = decode_json(_attr_text(cs, "columns", o.path), "checksum columns", kind=list)
        if columns != ["end", "ts", "ys", *sorted(series)] or cs.ndim != 2:
            raise o.fail("the checksum table does not list the file's datasets")
        if cs.shape[1] != len(columns) or cs.dtype.kind != "i":
            raise o.fail(f"the checksum table has shape {cs.shape} ({cs.dtype})")
        o.checksums = cs


@contextmanager
def open_result(path: str | os.PathLike[str], *, check_live: bool = True) -> Iterator[Opened]:
    """Open and validate a result file for reading.

    Parameters
    ----------
    path : str or Path
    check_live : bool
        Look for a live writer (its lock). The caller holding the lock passes ``False``.

    Raises
    ------
    ResultFileError
        Missing, not a regular file, truncated, not ours, too new, or a field out of range.
    """
    p = Path(path)
    if not p.exists():
        raise ResultFileError(f"{p}: no such file")
    if not p.is_file():
        raise ResultFileError(f"{p}: is {'a directory' if p.is_dir() else 'not a regular file'}")
    try:
        with p.open("rb") as fh:
            head = fh.read(48)
    except OSError as exc:
        raise ResultFileError(f"{p}: cannot read ({exc.strerror})") from None
    _check_truncated(p, head)
    live = is_live(os.path.realpath(p)) if check_live else None  # locks name the target
    view: ReadView | None = None
    try:
        # a live file too: HDF5's SWMR reader does not take a file object, and the writer's
        # flush order keeps what the current checkpoint names readable (see _live_retry)
        view = ReadView(p)
        f = h5py.File(view, "r")
    except OSError:
        if view is not None:
            view.close()
        kind = "not an HDF5 file" if head[:8] != b"\x89HDF\r\n\x1a\n" else "damaged"
        raise ResultFileError(f"{p}: not an isoflow result file ({kind})") from None
    try:
        if f.attrs.get("isoflow_format") != FORMAT:
            raise ResultFileError(f"{p}: an HDF5 file, but not an isoflow result file")
        version = f.attrs.get("isoflow_format_version", -1)
        if not isinstance(version, int | np.integer) or not 1 <= int(version) <= FORMAT_VERSION:
            if isinstance(version, int | np.integer) and version > FORMAT_VERSION:
                raise ResultFileError(
                    f"{p}: result format version {version} is newer than this isoflow reads "
                    f"({FORMAT_VERSION}); upgrade isoflow"
                )
            raise ResultFileError(f"{p}: result format version {version!r} is not valid")
        config_text, meta_text = _attr_text(f, "config", p), _attr_text(f, "meta", p)
        if int(version) >= 2:
            crc = f.attrs.get("header_crc")
            if not isinstance(crc, int | np.integer) or int(crc) != header_crc(
                config_text, meta_text
            ):
                raise ResultFileError(f"{p}: the config/meta attributes are damaged (checksum)")
        try:
            config = decode_json(config_text, "the config attribute")
            meta = decode_json(meta_text, "the meta attribute")
        except ResultFileError as exc:
            raise ResultFileError(f"{p}: {exc}") from None
        _validate_meta(meta, p)
        o = Opened(
            p,
            f,
            int(version),
            config,
            meta,
            live,
            bool(live is None and view.was_flagged),
            {},
            None,
        )
        _validate_datasets(o)
        yield o
    except IsoflowError:
        raise
    except _TRANSIENT as exc:
        msg = " ".join(str(exc).split())[:200]
        raise ResultFileError(f"{p}: damaged isoflow result file ({msg})") from None
    finally:
        f.close()
        if view is not None:
            view.close()


def _read_bytes(ds: h5py.Dataset, what: str, o: Opened) -> bytes:
    if ds.ndim != 1 or ds.dtype != np.uint8 or ds.shape[0] > _MAX_SLOT_BYTES:
        raise o.fail(f"checkpoint field {what} has shape {ds.shape} ({ds.dtype})")
    return bytes(np.asarray(ds[:], dtype=np.uint8)) if ds.shape[0] else b""


def _int_vector(ds: h5py.Dataset, n: int, what: str, o: Opened) -> list[int]:
    if ds.shape != (n,) or ds.dtype.kind not in "iu":
        raise o.fail(f"{what} has shape {ds.shape} ({ds.dtype}), not ({n},) integers")
    return [int(v) for v in np.asarray(ds[:])]


def read_checkpoint(o: Opened) -> Checkpoint | None:
    """The last complete checkpoint, every field validated (``None`` if there is none).

    Parameters
    ----------
    o : Opened
        The open file.

    Returns
    -------
    Checkpoint or None

    Raises
    ------
    ResultFileError
        A damaged or inconsistent checkpoint.
    """
    f, meta = o.f, o.meta
    if "checkpoint" not in f:
        return None
    (slot,) = _int_vector(f["checkpoint"]["current"], 1, "checkpoint/current", o)
    if slot == -1:
        return None
    if slot not in (0, 1):
        raise o.fail(f"checkpoint/current = {slot} names no checkpoint slot")
    g = f["checkpoint"][f"slot{slot}"]
    n_index = 4 if o.version >= 2 else 2
    index = _int_vector(g["index"], n_index, f"checkpoint slot{slot} index", o)
    step, n_rows = index[0], index[1]
    n_steps = int(meta["n_steps"])
    if not 0 <= step <= n_steps:
        raise o.fail(f"checkpoint step {step} outside the run's 0..{n_steps} steps")
    grid = SaveGrid(int(meta["save_every"]), n_steps)
    # the start, the save points up to the step, and the last good state of a run whose
    # members all failed between save points
    most = 1 + grid.count(0, step) + (0 if grid.is_save(step) else 1)
    have = min((ds.shape[0] for ds in o.rows.values()), default=0)
    if not 1 <= n_rows <= min(have, most):
        raise o.fail(
            f"checkpoint claims {n_rows} saved rows; the file holds {have} and step {step} "
            f"allows at most {most}"
        )
    shape = tuple(meta["state_shape"])
    if tuple(g["y"].shape) != shape or g["y"].dtype.kind not in "biufc":
        raise o.fail(f"checkpoint state has shape {g['y'].shape}, meta says {shape}")
    y = np.asarray(g["y"][...])
    core = tuple(meta.get("core_shape", shape))
    members = math.prod(shape[: len(shape) - len(core)])
    rec_ds = g["failures"]
    if rec_ds.shape != (members, 4):
        raise o.fail(f"checkpoint failure record has shape {rec_ds.shape} for {members} members")
    rec = np.asarray(rec_ds[...])
    names = ("state_blob", "state_desc", "failures_msg")
    parts = {k: _read_bytes(g[k], k, o) for k in names}
    n_blocks = 0
    run_info_raw: bytes | None = None
    if o.version >= 2:
        n_blocks = index[2]
        parts["run_info"] = _read_bytes(g["run_info"], "run_info", o)
        assert set(parts) == set(SLOT_BYTES)
        if slot_crc(np.asarray(index), y, rec, parts) != index[3]:
            raise o.fail(f"checkpoint slot{slot} is damaged (checksum mismatch)")
        cs = o.checksums
        assert cs is not None
        if not 1 <= n_blocks <= cs.shape[0]:
            raise o.fail(
                f"checkpoint claims {n_blocks} checksum blocks; the file holds {cs.shape[0]}"
            )
        if int(cs[n_blocks - 1, 0]) != n_rows:
            raise o.fail("the checksum table does not end at the checkpoint's last row")
        run_info_raw = parts["run_info"]
    elif "run_info" in f:
        run_info_raw = _read_bytes(f["run_info"], "run_info", o)
    try:
        state = unpack_state(parts["state_blob"], parts["state_desc"])
        failures = decode_failures(rec, parts["failures_msg"], members)
        run_info = decode_json(run_info_raw, "run_info") if run_info_raw else None
    except ResultFileError as exc:
        raise o.fail(str(exc)) from None
    if run_info is not None and not isinstance(run_info.get("status", 0), int):
        raise o.fail("run_info status is not an integer")
    return Checkpoint(step, n_rows, slot, y, state, failures, n_blocks, run_info)


def iter_rows(
    o: Opened, cp: Checkpoint, names: list[str], *, verify: bool = True
) -> Iterator[tuple[list[tuple[int, int]], dict[str, Array]]]:
    """The valid rows of datasets ``names`` in spans of about :data:`READ_CHUNK` rows.

    Yields ``(blocks, data)``: the checksum blocks ``(start, stop)`` of the span (one per span
    in version 1 files) and ``name -> rows``. With ``verify`` (version 2), every block of every
    dataset read is checked against its CRC-32.

    Parameters
    ----------
    o : Opened
        The open file.
    cp : Checkpoint
        Its checkpoint (how many rows and blocks are valid).
    names : list of str
        The datasets to read (keys of ``o.rows``).
    verify : bool
        Check the CRC-32 of every block (default ``True``; version 2 files only).

    Raises
    ------
    ResultFileError
        A block does not match its checksum (the message names the dataset and rows).
    """
    if o.checksums is None or not verify:
        bounds = [(a, min(a + READ_CHUNK, cp.n_rows)) for a in range(0, cp.n_rows, READ_CHUNK)]
        table = None
    else:
        table = np.asarray(o.checksums[: cp.n_blocks])
        ends = table[:, 0]
        if ends[0] < 1 or np.any(np.diff(ends) < 1) or ends[-1] != cp.n_rows:
            raise o.fail("the checksum table's block ends are not increasing")
        starts = np.concatenate([[0], ends[:-1]])
        bounds = [(int(a), int(b)) for a, b in zip(starts, ends, strict=True)]
        columns = ["ts", "ys", *sorted(list(o.rows)[2:])]
        col = {name: 1 + columns.index(name) for name in names}
    span: list[tuple[int, int]] = []
    for i, (a, b) in enumerate(bounds):
        span.append((a, b))
        if b - span[0][0] < READ_CHUNK and i + 1 < len(bounds):
            continue
        lo, hi = span[0][0], span[-1][1]
        data = {name: np.asarray(o.rows[name][lo:hi]) for name in names}
        if table is not None:
            first = i + 1 - len(span)
            for j, (sa, sb) in enumerate(span):
                for name in names:
                    if crc_of(data[name][sa - lo : sb - lo]) != int(table[first + j, col[name]]):
                        raise o.fail(
                            f"damaged data: {name} rows {sa}..{sb - 1} do not match their checksum"
                        )
        yield span, data
        span = []


def _drifts(o: Opened, cp: Checkpoint | None) -> dict[str, float]:
    """Drifts over the stored diagnostic series (worst member), verified as read."""
    series = list(o.rows)[2:]
    if cp is None or not series:
        return {}
    shape = tuple(o.meta["state_shape"])
    core = tuple(o.meta.get("core_shape", shape[-2:]))
    acc = DriftAccumulator(o.meta.get("casimir_scale", 1.0), len(shape) - len(core))
    for _blocks, data in iter_rows(o, cp, ["ts", *series]):
        acc.absorb(data["ts"], {k: data[k] for k in series})
    return {k: float(np.max(v)) for k, v in acc.drifts().items()}


def run_state(o: Opened, cp: Checkpoint | None) -> tuple[str, str, bool]:
    """``(state, message, resumable)`` of a file: live, complete, killed, stopped or failed."""
    if o.live is not None:
        return "live", f"being written by {o.live}", False
    if cp is None:
        return "killed", "stopped before its first state was saved; start the run again", False
    n_steps = int(o.meta["n_steps"])
    ri = cp.run_info
    if ri is None:
        return (
            "killed",
            "stopped without closing (killed, or a write failed); resume with isoflow run --resume",
            True,
        )
    status = ri.get("status")
    message = str(ri.get("message", ""))
    if status == 0 and cp.step == n_steps:
        return "complete", message, False
    if status == 1:
        return "failed", message, False
    return "stopped", f"{message}; resume with isoflow run --resume", cp.step < n_steps


def _live_retry(path: str | os.PathLike[str], read: Callable[[], _T]) -> _T:
    """``read()``, tried again a few times while a live writer is changing the file."""
    for _ in range(_LIVE_TRIES - 1):
        try:
            return read()
        except ResultFileError:
            if is_live(os.path.realpath(path)) is None:
                raise
            time.sleep(0.05)
    return read()


def info(path: str | os.PathLike[str], *, verify_states: bool = False) -> dict[str, Any]:
    """What a result file holds, as a JSON-ready dict (without loading the states).

    Parameters
    ----------
    path : str or Path
    verify_states : bool
        Also check every saved state against its checksum (reads them all); the times and
        diagnostics are always checked.

    Returns
    -------
    dict
        ``path``, ``isoflow_version``, ``created``, ``config``, ``meta``, ``format_version``,
        ``state`` (``"live"``, ``"complete"``, ``"killed"``, ``"stopped"`` or ``"failed"``),
        ``state_message``, ``resumable``, ``writer`` (pid and host of a live writer),
        ``verified`` (every saved state checked), ``n_saved`` (valid saved states),
        ``t_last``, ``step``, ``complete``, ``run_info`` and ``drifts``.
    """
    check_flag(verify_states, "verify_states")
    return _live_retry(path, lambda: _info(path, verify_states))


def _info(path: str | os.PathLike[str], verify_states: bool) -> dict[str, Any]:
    with open_result(path) as o:
        cp = read_checkpoint(o)
        n_rows = 0 if cp is None else cp.n_rows
        drifts = _drifts(o, cp)
        verified = False
        if verify_states and cp is not None and o.checksums is not None:
            for _ in iter_rows(o, cp, ["ys"]):
                pass
            verified = True
        state, message, resumable = run_state(o, cp)
        return {
            "path": str(path),
            "isoflow_version": str(o.f.attrs.get("isoflow_version", "?")),
            "created": str(o.f.attrs.get("created", "?")),
            "format_version": o.version,
            "config": o.config,
            "meta": o.meta,
            "state": state,
            "state_message": message,
            "resumable": resumable,
            "writer": o.live,
            "verified": verified,
            "n_saved": n_rows,
            "t_last": float(o.rows["ts"][n_rows - 1]) if n_rows else None,
            "step": None if cp is None else cp.step,
            "complete": cp is not None and cp.step == int(o.meta["n_steps"]),
            "run_info": None if cp is None else cp.run_info,
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

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The ensemble's shape (``()`` for one system): the state's leading axes."""
        state = tuple(self.meta.get("state_shape", np.shape(self.ys)[1:]))
        core = tuple(self.meta.get("core_shape", state))
        return state[: len(state) - len(core)]


def load(path: str | os.PathLike[str]) -> RunData:
    """Read a result file (also one whose run was killed: its valid states) into memory.

    Every row read is checked against its checksum (format version 2).

    Parameters
    ----------
    path : str or os.PathLike
        The result file (as written by :class:`~isoflow.io.HDF5Writer`).

    Returns
    -------
    RunData
        Times, states, diagnostic series, the recorded configuration and metadata, the final
        status and the Casimir drifts.

    Raises
    ------
    ResultFileError
        Not a readable result file, no saved state, or damaged rows.
    """
    return _live_retry(path, lambda: _load(path))


def _load(path: str | os.PathLike[str]) -> RunData:
    with open_result(path) as o:
        cp = read_checkpoint(o)
        if cp is None:
            raise o.fail("the run was stopped before its first state was saved")
        names = list(o.rows)
        parts: dict[str, list[Array]] = {k: [] for k in names}
        for _blocks, data in iter_rows(o, cp, names):
            for k in names:
                parts[k].append(data[k])
        full = {k: np.concatenate(v) for k, v in parts.items()}
        return RunData(
            ts=full["ts"],
            ys=full["ys"],
            series={k: full[k] for k in names[2:]},
            config=o.config,
            meta=o.meta,
            run_info=cp.run_info,
            step=cp.step,
            drifts=_drifts(o, cp),
        )
