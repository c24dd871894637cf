"""What a result file holds (format version 2), and the low-level writes shared by the writer
and recovery.

A file is one HDF5 file:

* attributes ``isoflow_format = "isoflow-run"``, ``isoflow_format_version``, ``isoflow_version``,
  ``created``, ``config`` (the run configuration, JSON), ``meta`` (times, method, algebra; JSON)
  and ``header_crc`` (CRC-32 of config and meta). Nothing is pickled or evaluated;
* ``ts`` ``(n,)`` and ``ys`` ``(n, *shape)``: saved times and states, resizable and chunked;
* ``diagnostics/...``: per saved state Casimirs, distance to ``V``, Hamiltonian, Lyapunov
  function and the problem's invariants and observables;
* ``checksums`` ``(n_blocks, 3 + n_series)`` (int64): one row per block of rows written
  together: its end row, then the CRC-32 of the block's bytes of ``ts``, ``ys`` and of every
  diagnostics dataset (in the order of the dataset's ``columns`` attribute);
* ``checkpoint/slot0`` and ``checkpoint/slot1``: ``index = [step, n_rows, n_blocks, crc]``,
  the state ``y``, the method state (``state_blob``, ``state_desc``), the failure record
  (``failures``, ``failures_msg``) and the run's final status (``run_info``, JSON; empty while
  the run goes on), ``crc`` being the CRC-32 of all of them; ``checkpoint/current`` names the
  slot of the last complete checkpoint. Slots are written alternately, so one complete
  checkpoint always exists, and the final status is published with the last checkpoint.

Version 1 files (no ``checksums``, ``index = [step, n_rows]``, a top-level ``run_info``) are
still read, without checksum checks; :func:`isoflow.io.resume` rewrites them to version 2.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from .._failures import MemberFailures
from .._version import __version__
from .codec import crc32, crc_of, encode_failures, encode_json, pack_state

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "READ_CHUNK",
    "Handles",
    "create_layout",
    "header_crc",
    "slot_crc",
    "write_attrs",
]

Array = NDArray[Any]

FORMAT = "isoflow-run"
FORMAT_VERSION = 2
#: Rows read at a time by the readers (bounded memory).
READ_CHUNK = 4096
#: The byte datasets of a checkpoint slot, in the order the slot CRC covers them.
SLOT_BYTES = ("state_blob", "state_desc", "failures_msg", "run_info")


def header_crc(config_text: str, meta_text: str) -> int:
    """CRC-32 of the ``config`` and ``meta`` attributes.

    Parameters
    ----------
    config_text, meta_text : str
        The two attributes as stored (JSON text).

    Returns
    -------
    int
    """
    return crc32(config_text.encode(), b"\0", meta_text.encode())


def slot_crc(index: Array, y: Array, failures: Array, parts: dict[str, bytes]) -> int:
    """CRC-32 of a checkpoint slot: ``index[:3]``, ``y``, the failure record and its bytes.

    Parameters
    ----------
    index : ndarray of int
        The slot's index ``(step, n_rows, n_blocks, crc)``; the first three are covered.
    y : ndarray
        The slot's state, in its stored dtype.
    failures : ndarray, shape (members, 4)
        The failure record (:func:`~isoflow.io.codec.encode_failures`).
    parts : dict of str to bytes
        The slot's byte datasets by name (:data:`SLOT_BYTES`, all of them).

    Returns
    -------
    int
    """
    crc = crc32(np.ascontiguousarray(index[:3], dtype="<i8").tobytes())
    crc = crc32(np.ascontiguousarray(y).tobytes(), crc.to_bytes(4, "little"))
    crc = crc32(np.ascontiguousarray(failures, dtype="<f8").tobytes(), crc.to_bytes(4, "little"))
    for name in SLOT_BYTES:
        crc = crc32(parts[name], crc.to_bytes(4, "little"))
    return crc


def write_attrs(f: h5py.File, config: dict[str, Any], meta: dict[str, Any]) -> None:
    """The file's attributes (before SWMR mode: attributes cannot be added afterwards).

    Parameters
    ----------
    f : h5py.File
        The new file.
    config : dict
        The run configuration (JSON-ready), stored as ``config``.
    meta : dict
        The run's metadata (JSON-ready), stored as ``meta``; both covered by ``header_crc``.
    """
    config_text, meta_text = json.dumps(config), json.dumps(meta)
    f.attrs["isoflow_format"] = FORMAT
    f.attrs["isoflow_format_version"] = FORMAT_VERSION
    f.attrs["isoflow_version"] = __version__
    f.attrs["created"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    f.attrs["config"] = config_text
    f.attrs["meta"] = meta_text
    f.attrs["header_crc"] = header_crc(config_text, meta_text)


def _bytes_dataset(g: h5py.Group, name: str) -> None:
    g.create_dataset(name, shape=(0,), maxshape=(None,), chunks=(4096,), dtype="u1")


def create_layout(
    f: h5py.File,
    shape: tuple[int, ...],
    dtype: Any,
    series: dict[str, tuple[tuple[int, ...], Any]],
    members: int,
    chunk_rows: int,
) -> None:
    """Create every dataset of a run with states of ``shape`` and diagnostic ``series``.

    Parameters
    ----------
    f : h5py.File
        A new file holding only its attributes.
    shape, dtype :
        One saved state (ensemble axes included).
    series : dict
        Diagnostics dataset name -> (shape of one row, dtype).
    members : int
        Ensemble members (rows of the failure record).
    chunk_rows : int
        Rows per write.
    """
    row_bytes = max(int(np.prod(shape)) * np.dtype(dtype).itemsize, 1)
    crow = max(1, min(chunk_rows, (1 << 20) // row_bytes))
    f.create_dataset("ts", shape=(0,), maxshape=(None,), chunks=(max(crow, 64),), dtype="f8")
    f.create_dataset(
        "ys", shape=(0, *shape), maxshape=(None, *shape), chunks=(crow, *shape), dtype=dtype
    )
    g = f.create_group("diagnostics")
    for name, (s, dt) in series.items():
        g.create_dataset(
            name, shape=(0, *s), maxshape=(None, *s), chunks=(max(crow, 64), *s), dtype=dt
        )
    names = sorted(series)
    cs = f.create_dataset(
        "checksums", shape=(0, 3 + len(names)), maxshape=(None, 3 + len(names)),
        chunks=(256, 3 + len(names)), dtype="i8",
    )  # fmt: skip
    cs.attrs["columns"] = json.dumps(["end", "ts", "ys", *names])
    cp = f.create_group("checkpoint")
    for i in (0, 1):
        slot = cp.create_group(f"slot{i}")
        slot.create_dataset("y", shape=shape, dtype=dtype)
        slot.create_dataset("index", shape=(4,), dtype="i8", data=np.array([-1, 0, 0, 0]))
        slot.create_dataset("failures", shape=(members, 4), dtype="f8")
        for name in SLOT_BYTES:
            _bytes_dataset(slot, name)
    cp.create_dataset("current", shape=(1,), dtype="i8", data=np.array([-1]))


def _write_bytes(ds: h5py.Dataset, data: bytes) -> None:
    ds.resize((len(data),))
    if data:
        ds[:] = np.frombuffer(data, dtype=np.uint8)


@dataclass
class _Slot:
    y: h5py.Dataset
    index: h5py.Dataset
    failures: h5py.Dataset
    parts: dict[str, h5py.Dataset]


class Handles:
    """The datasets of an open file, looked up once (not on every write).

    Parameters
    ----------
    f : h5py.File
        A file with the layout of :func:`create_layout`.
    n_rows, n_blocks : int
        Rows and checksum blocks already valid (default 0: a new file).

    Attributes
    ----------
    n_rows, n_blocks : int
        Rows and checksum blocks written so far.
    """

    def __init__(self, f: h5py.File, n_rows: int = 0, n_blocks: int = 0) -> None:
        self.f = f
        self.ts = f["ts"]
        self.ys = f["ys"]
        self.checksums = f["checksums"]
        columns = json.loads(self.checksums.attrs["columns"])
        self.series: dict[str, h5py.Dataset] = {n: f["diagnostics"][n] for n in columns[3:]}
        cp = f["checkpoint"]
        self.current = cp["current"]
        self.slots = [
            _Slot(
                cp[f"slot{i}"]["y"],
                cp[f"slot{i}"]["index"],
                cp[f"slot{i}"]["failures"],
                {name: cp[f"slot{i}"][name] for name in SLOT_BYTES},
            )
            for i in (0, 1)
        ]
        self.n_rows = n_rows
        self.n_blocks = n_blocks

    def truncate(self) -> None:
        """Cut every row dataset to ``n_rows`` and the checksums to ``n_blocks``."""
        for ds in (self.ts, self.ys, *self.series.values()):
            ds.resize(self.n_rows, axis=0)
        self.checksums.resize(self.n_blocks, axis=0)

    def write_block(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        """Append one block of rows and its checksum row.

        Parameters
        ----------
        ts : ndarray, shape (m,)
            Times of the rows.
        ys : ndarray, shape (m, *batch, *shape)
            The states.
        series : dict of str to ndarray
            Every diagnostic series of the file, ``(m, ...)`` each.
        """
        n0, m = self.n_rows, len(ts)
        crcs = [n0 + m]
        for ds, data in (
            (self.ts, ts),
            (self.ys, ys),
            *((self.series[k], series[k]) for k in self.series),
        ):
            block = np.ascontiguousarray(data, dtype=ds.dtype)
            ds.resize(n0 + m, axis=0)
            ds[n0:] = block
            crcs.append(crc_of(block))
        self.checksums.resize(self.n_blocks + 1, axis=0)
        self.checksums[self.n_blocks] = np.asarray(crcs, dtype=np.int64)
        self.n_rows = n0 + m
        self.n_blocks += 1

    def write_slot(
        self,
        slot: int,
        step: int,
        y: Array,
        method_state: Any,
        failures: MemberFailures | None,
        run_info: dict[str, Any] | None,
    ) -> None:
        """Write a complete checkpoint into ``slot`` (not yet pointed to).

        Parameters
        ----------
        slot : int
            The slot, 0 or 1.
        step : int
            Steps done.
        y : ndarray, shape (*batch, *shape)
            The state after ``step`` steps.
        method_state : object
            The method's state (:func:`~isoflow.io.codec.pack_state`).
        failures : MemberFailures or None
            The failure record.
        run_info : dict or None
            The run's final status (``None`` while it runs).
        """
        g = self.slots[slot]
        blob, desc = pack_state(method_state)
        rec, msgs = encode_failures(failures, g.failures.shape[0])
        parts = {
            "state_blob": blob,
            "state_desc": desc,
            "failures_msg": msgs,
            "run_info": b"" if run_info is None else encode_json(run_info),
        }
        yv = np.ascontiguousarray(y, dtype=g.y.dtype)
        index = np.array([int(step), self.n_rows, self.n_blocks, 0], dtype=np.int64)
        index[3] = slot_crc(index, yv, rec, parts)
        g.y[...] = yv
        g.failures[...] = rec
        for name, data in parts.items():
            _write_bytes(g.parts[name], data)
        g.index[:] = index

    def point_to(self, slot: int) -> None:
        """Make ``slot`` the current checkpoint."""
        self.current[0] = slot
