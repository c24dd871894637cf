"""Bytes of a result file: method states, failure records, JSON and CRC-32 checksums.

Nothing is pickled or evaluated. Every decoded field is checked before use: a crafted or
damaged file gives a one-line :class:`~isoflow.ResultFileError`, never another exception, and
arrays are only ever of numeric dtypes (never ``object``).
"""

from __future__ import annotations

import json
import math
import struct
import zlib
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._errors import ResultFileError
from .._failures import MemberFailures

__all__ = [
    "MAX_ELEMENTS",
    "crc32",
    "crc_of",
    "decode_failures",
    "decode_json",
    "encode_failures",
    "encode_json",
    "pack_state",
    "unpack_state",
]

Array = NDArray[Any]

#: Largest array (elements) a file may describe: more is a crafted or damaged field.
MAX_ELEMENTS = 1 << 31
#: Numeric dtype kinds an array in a file may have (bool, int, uint, float, complex).
_NUMERIC_KINDS = frozenset("biufc")


def crc32(*parts: bytes | memoryview) -> int:
    """CRC-32 (:func:`zlib.crc32`) of the concatenated ``parts``."""
    crc = 0
    for part in parts:
        crc = zlib.crc32(part, crc)
    return crc


def crc_of(arr: Array, dtype: Any = None) -> int:
    """CRC-32 of the C-ordered bytes of ``arr`` (cast to ``dtype`` first when given)."""
    data = np.ascontiguousarray(arr, dtype=dtype)
    return zlib.crc32(data.data) if data.size else 0


def encode_json(value: Any) -> bytes:
    """UTF-8 JSON of ``value`` (floats that are not JSON numbers are written as floats)."""
    return json.dumps(value, default=float).encode()


def decode_json(raw: bytes | str, what: str, kind: type | None = dict) -> Any:
    """Parse JSON text ``raw`` describing ``what``; with ``kind``, require that type."""
    try:
        text = raw.decode() if isinstance(raw, bytes) else str(raw)
        value = json.loads(text)
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise ResultFileError(f"{what} is not valid JSON") from None
    if kind is not None and not isinstance(value, kind):
        raise ResultFileError(f"{what} is a JSON {type(value).__name__}, not a {kind.__name__}")
    return value


def numeric_dtype(text: Any, what: str) -> np.dtype[Any]:
    """The numeric dtype named by ``text`` (e.g. ``"<f8"``); anything else is an error."""
    try:
        dtype = np.dtype(str(text))
    except (TypeError, ValueError):
        raise ResultFileError(f"{what}: {text!r} is not a dtype") from None
    if dtype.kind not in _NUMERIC_KINDS or dtype.hasobject or dtype.subdtype is not None:
        raise ResultFileError(f"{what}: dtype {dtype} is not numeric")
    return dtype


def check_shape(value: Any, what: str, max_elements: int = MAX_ELEMENTS) -> tuple[int, ...]:
    """``value`` as a shape: a short list of non-negative ints of bounded product."""
    if not isinstance(value, list | tuple) or len(value) > 32:
        raise ResultFileError(f"{what}: {value!r} is not a shape")
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value):
        raise ResultFileError(f"{what}: {value!r} is not a shape")
    if math.prod(value) > max_elements:
        raise ResultFileError(f"{what}: shape {tuple(value)} is too large")
    return tuple(int(v) for v in value)


def _int(value: Any, what: str, lo: int, hi: int) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not lo <= value <= hi:
        raise ResultFileError(f"{what}: {value!r} is not an integer in {lo}..{hi}")
    return int(value)


# ---- method state ------------------------------------------------------------------------------


def pack_state(state: Any) -> tuple[bytes, bytes]:
    """``(blob, description)`` of a method state: ``None`` or a tuple of numbers and arrays.

    Parameters
    ----------
    state : None or tuple
        Items ``None``, ``bool``, ``int``, ``float`` or numeric arrays.

    Returns
    -------
    blob, description : bytes
        The raw item bytes and a JSON list describing each item (kind, offset, bytes, dtype
        and shape of arrays).
    """
    if state is None:
        return b"", encode_json(None)
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
            if arr.dtype.kind not in _NUMERIC_KINDS:
                raise TypeError(f"a method state array must be numeric, got dtype {arr.dtype}")
            raw = arr.tobytes()
            entry = {"kind": "array", "dtype": arr.dtype.str, "shape": list(arr.shape)}
        entry.update(offset=offset, nbytes=len(raw))
        desc.append(entry)
        parts.append(raw)
        offset += len(raw)
    return b"".join(parts), encode_json(desc)


_SCALAR_BYTES = {"bool": 1, "int": 8, "float": 8}


def unpack_state(blob: bytes, description: bytes) -> Any:
    """The method state of :func:`pack_state`, every field checked.

    Raises
    ------
    ResultFileError
        The description is not one :func:`pack_state` writes, or does not fit ``blob``.
    """
    what = "checkpoint method state"
    desc = decode_json(description, what, kind=None)
    if desc is None:
        return None
    if not isinstance(desc, list) or len(desc) > 1024:
        raise ResultFileError(f"{what}: not a list of items")
    out: list[Any] = []
    for i, e in enumerate(desc):
        if not isinstance(e, dict) or e.get("kind") not in (
            "none",
            "bool",
            "int",
            "float",
            "array",
        ):
            raise ResultFileError(f"{what}: item {i} has no known kind")
        kind = e["kind"]
        if kind == "none":
            out.append(None)
            continue
        off = _int(e.get("offset"), f"{what} item {i} offset", 0, len(blob))
        nbytes = _int(e.get("nbytes"), f"{what} item {i} size", 0, len(blob) - off)
        raw = blob[off : off + nbytes]
        if kind in _SCALAR_BYTES and nbytes != _SCALAR_BYTES[kind]:
            raise ResultFileError(f"{what}: item {i} ({kind}) has {nbytes} bytes")
        if kind == "bool":
            out.append(bool(raw[0]))
        elif kind == "int":
            out.append(struct.unpack("<q", raw)[0])
        elif kind == "float":
            out.append(struct.unpack("<d", raw)[0])
        else:
            dtype = numeric_dtype(e.get("dtype"), f"{what} item {i}")
            shape = check_shape(e.get("shape"), f"{what} item {i}")
            if math.prod(shape) * dtype.itemsize != nbytes:
                raise ResultFileError(f"{what}: item {i} shape {shape} does not fit its bytes")
            out.append(np.frombuffer(raw, dtype=dtype).reshape(shape).copy())
    return tuple(out)


# ---- failure record ----------------------------------------------------------------------------


def encode_failures(failures: MemberFailures | None, members: int) -> tuple[Array, bytes]:
    """``(record, messages)``: a ``(members, 4)`` float array and the JSON of the messages.

    Parameters
    ----------
    failures : MemberFailures or None
        The record (``None``: every member alive, step ``-1``).
    members : int
        Number of members.

    Returns
    -------
    record : ndarray, shape (members, 4)
        Step, status, iterations and residual per member.
    messages : bytes
        The failure messages as JSON (empty for ``None``).
    """
    if failures is None:
        rec = np.zeros((members, 4))
        rec[:, 0] = -1.0
        return rec, b""
    rec = np.stack(
        [failures.step, failures.status, failures.iterations, failures.residual], axis=-1
    ).astype(float)
    return rec, encode_json({str(k): v for k, v in failures.messages.items()})


def decode_failures(rec: Array, messages: bytes, members: int) -> MemberFailures | None:
    """The :class:`MemberFailures` of :func:`encode_failures` (``None`` if all are alive).

    Parameters
    ----------
    rec : ndarray, shape (members, 4)
        The stored record.
    messages : bytes
        The stored messages (JSON; empty for none).
    members : int
        Number of members the file records.

    Raises
    ------
    ResultFileError
        A record of the wrong shape or with values out of range, or messages that are not
        about a member.
    """
    what = "checkpoint failure record"
    rec = np.asarray(rec)
    if rec.dtype.kind != "f" or rec.shape != (members, 4):
        raise ResultFileError(f"{what}: shape {rec.shape} for {members} members")
    if not np.all(np.isfinite(rec[:, :3])) or np.any(np.abs(rec[:, :3]) > 2.0**62):
        raise ResultFileError(f"{what}: step, status or iterations out of range")
    if not np.any(rec[:, 0] >= 0):
        return None
    raw = decode_json(messages or b"{}", f"{what} messages")
    msgs: dict[int, str] = {}
    for k, v in raw.items():
        if not k.isdigit() or int(k) >= members or not isinstance(v, str):
            raise ResultFileError(f"{what}: message for {k!r} is not about a member")
        msgs[int(k)] = v
    return MemberFailures(
        step=rec[:, 0].astype(np.int64),
        status=rec[:, 1].astype(np.int64),
        iterations=rec[:, 2].astype(np.int64),
        residual=rec[:, 3].copy(),
        messages=msgs,
    )
