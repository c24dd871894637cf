r"""Streaming result files (HDF5), restart, readers, and export to xarray / netCDF.

A run streamed with :class:`HDF5Writer` (``iso.solve(..., writer=HDF5Writer(path))`` or
``isoflow run``) is one HDF5 file, laid out as :mod:`isoflow.io.layout` describes (format
version 2: checksummed rows, two checkpoint slots, the final status published with the last
checkpoint). One job per module:

* :mod:`~isoflow.io.codec`: method states, failure records and JSON to and from bytes; CRC-32;
* :mod:`~isoflow.io.layout`: what a file holds and the low-level writes;
* :mod:`~isoflow.io.safefile`: the file objects HDF5 goes through (a failed write is recorded,
  never raised into HDF5; a read-only view of a killed file);
* :mod:`~isoflow.io.lock`: the exclusive write lock (``<file>.lock``);
* :mod:`~isoflow.io.writer`: :class:`HDF5Writer`;
* :mod:`~isoflow.io.reader`: :func:`load`, :func:`info`, validation of every field;
* :mod:`~isoflow.io.recovery`: rewriting a killed or version 1 file;
* :mod:`~isoflow.io.resume`: :func:`resume`;
* :mod:`~isoflow.io.export`: :func:`to_xarray`, :func:`to_netcdf`, :func:`solution_diagnostics`.

A sweep directory (:mod:`isoflow.sweep`) is read by :func:`isoflow.sweep.open_sweep`.

Guarantees
----------
After a kill at any moment (SIGKILL included), a full disk or a failing write, the file opens
and holds the run up to its last checkpoint; :func:`resume` continues it and the final state
equals an uninterrupted run's bit for bit. A second writer gets :class:`ResultFileError` naming
the live writer. A damaged or crafted file gives a one-line :class:`ResultFileError` (naming the
damaged rows where a checksum fails), never silently different data.
"""

from __future__ import annotations

from .._errors import ModelChangedError, ResultFileError, ResultWriteError
from .._solve import StreamWriter
from .export import solution_diagnostics, to_netcdf, to_xarray
from .layout import FORMAT, FORMAT_VERSION
from .reader import Checkpoint, RunData, info, load
from .resume import resume
from .writer import HDF5Writer

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "Checkpoint",
    "HDF5Writer",
    "ModelChangedError",
    "ResultFileError",
    "ResultWriteError",
    "RunData",
    "StreamWriter",
    "info",
    "load",
    "resume",
    "solution_diagnostics",
    "to_netcdf",
    "to_xarray",
]
