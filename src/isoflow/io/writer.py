"""The streaming writer: :class:`HDF5Writer` (the layout is in :mod:`isoflow.io.layout`).

Crash safety
------------
The file is written in HDF5's single-writer/multiple-reader (SWMR) mode (``libver="latest"``),
which orders metadata writes so that the file stays readable at every moment. Each chunk is
written as: rows and their checksum row, flush, the *other* checkpoint slot, flush, the
``current`` slot index, flush. So after a kill at any moment (SIGKILL included) ``current`` names
a complete checkpoint whose row count says which rows are valid. Until the initial state is
checkpointed the file is written as ``<path>.partial`` and then renamed, so a kill during set-up
never leaves (or replaces) a file at ``path`` without states.

Every write goes through a :class:`~isoflow.io.safefile.SafeFile`: a failed write (disk full,
I/O error) leaves the disk as a kill at that write would, and the run stops with
:class:`~isoflow.ResultWriteError`; the file then resumes. An exclusive lock
(:mod:`isoflow.io.lock`) keeps a second writer away while the file is written.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import stat
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from .._errors import ParameterError, ResultFileError, ResultWriteError
from .._failures import MemberFailures
from .._flags import check_flag
from .layout import Handles, create_layout, write_attrs
from .lock import WriteLock
from .safefile import SafeFile

__all__ = ["HDF5Writer", "check_target"]

Array = NDArray[Any]


def check_target(path: Path, *, force: bool, resumable: bool = True) -> Path:
    """The file a writer may create at ``path`` (a symlink's target), else an error (which
    points to ``--resume`` for a ``resumable`` result file).

    Raises
    ------
    ResultFileError
        ``path`` exists and is not a regular file (a device, a directory, a dangling or odd
        symlink), even with ``force``; or it exists and ``force`` is false.
    """
    target = Path(os.path.realpath(path)) if path.is_symlink() else path
    try:
        st = os.stat(target)
    except FileNotFoundError:
        if path.is_symlink():
            raise ResultFileError(f"{path}: a symlink to nothing; not writing through it") from None
        return target
    except OSError as exc:
        raise ResultFileError(f"{path}: cannot check the output path ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise ResultFileError(f"{path} exists and is {kind}; not replacing it")
    if not force:
        resume = f", or --resume {path} to continue it" if resumable else ""
        raise ResultFileError(f"{path} exists (use --force / force=True to replace it{resume})")
    return target


def _warn_if_the_disk_is_too_small(target: Path, meta: dict[str, Any]) -> None:
    """Warn when the run's saved states alone need more than the free space beside ``target``:
    it would stop with a :class:`~isoflow.ResultWriteError` when the disk fills (its file
    keeps every state up to then and resumes). Not refused: a run may be meant to be stopped
    early."""
    try:
        rows = int(meta["n_steps"]) // int(meta["save_every"]) + 1
        row = int(np.prod(meta["state_shape"])) * np.dtype(meta["state_dtype"]).itemsize
        free = shutil.disk_usage(target.parent).free
    except (KeyError, TypeError, ValueError, OSError):
        return
    need = float(rows) * row
    if need > free:
        warnings.warn(
            f"{target}: the run's saved states need about {need / 2**30:.3g} GiB, more than the "
            f"{free / 2**30:.3g} GiB free there; it will stop with a ResultWriteError when the "
            "disk fills (its file resumes): save less often (save_every) or free space",
            UserWarning,
            stacklevel=4,
        )


def check_writer_settings(chunk_rows: Any, flush_seconds: Any) -> None:
    """``chunk_rows`` an integer >= 1 and ``flush_seconds`` a number >= 0 (``inf``: every
    ``chunk_rows`` states only), else a :class:`~isoflow.ParameterError`; ``None`` is not
    checked (a resume's setting not given: the run's recorded one)."""
    if chunk_rows is not None and (
        isinstance(chunk_rows, bool)
        or not isinstance(chunk_rows, (int, np.integer))
        or (chunk_rows < 1)
    ):
        raise ParameterError(f"chunk_rows must be an integer >= 1, got {chunk_rows!r}")
    if flush_seconds is not None and (
        isinstance(flush_seconds, bool)
        or not isinstance(flush_seconds, (int, float, np.integer, np.floating))
        or not flush_seconds >= 0  # NaN fails too
    ):
        raise ParameterError(
            f"flush_seconds must be a number of seconds >= 0, got {flush_seconds!r}"
        )


class HDF5Writer:
    """Stream a run to an HDF5 file (see :mod:`isoflow.io` for the layout and guarantees).

    Parameters
    ----------
    path : str or Path
        The file to create. An existing regular file is replaced only with ``force``;
        anything else (a directory, a device) never.
    config : dict, optional
        JSON-ready description of the run, stored as the ``config`` attribute. A configuration
        in :mod:`isoflow.registry` form lets :func:`~isoflow.io.resume` rebuild the problem.
    chunk_rows : int
        Saved states buffered in memory before they are written (and a checkpoint taken).
    flush_seconds : float
        Also write (and checkpoint) when this much time passed since the last write.
    force : bool
        Replace an existing regular file at ``path``.

    Raises
    ------
    ResultFileError
        ``path`` exists (without ``force``) or is not a regular file; or, when the run starts,
        another process is writing it.

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
        force: bool = False,
    ) -> None:
        if chunk_rows is None or flush_seconds is None:  # None means "recorded" to resume only
            raise ParameterError(
                f"chunk_rows and flush_seconds must be numbers, got {chunk_rows!r} and "
                f"{flush_seconds!r}"
            )
        check_writer_settings(chunk_rows, flush_seconds)
        check_flag(force, "force")  # "no" would count as true: a lost file
        self.path = Path(path)
        self.force = bool(force)
        self._target = check_target(self.path, force=self.force)
        if config is not None and not isinstance(config, Mapping):
            raise ParameterError(
                f"config must be a mapping (a dict) or None, got {type(config).__name__}"
            )
        self.config = {} if config is None else dict(config)
        try:
            json.dumps(self.config)  # fail early on anything that is not JSON
        except (TypeError, ValueError) as exc:
            raise ParameterError(
                f"config must be JSON-ready (numbers, strings, lists): {exc}"
            ) from None
        self.chunk_rows = int(chunk_rows)
        self.flush_seconds = float(flush_seconds)
        self._sf: SafeFile | None = None
        self._f: h5py.File | None = None
        self._h: Handles | None = None
        self._lock: WriteLock | None = None
        self._partial: Path | None = None
        self._meta: dict[str, Any] = {}
        self._slot = -1
        self._last: tuple[int, Array, Any, MemberFailures | None] | None = None

    # the protocol ---------------------------------------------------------------------------

    def open(self, meta: dict[str, Any]) -> None:
        """Lock the path and create the file (as ``<path>.partial``) with its attributes.

        Parameters
        ----------
        meta : dict
            What describes the run (times, method, algebra, ...; JSON-ready), stored as the
            file's ``meta`` attribute together with the writer's settings.

        Raises
        ------
        ResultFileError
            Another process writes the file (the lock), or the path is no longer a valid
            target (it exists and ``force`` is false, it is a directory, a dangling symlink).
        """
        flush = self.flush_seconds if math.isfinite(self.flush_seconds) else None
        # what a resume writes with unless told otherwise (:func:`isoflow.io.resume`)
        self._meta = {**meta, "writer": {"chunk_rows": self.chunk_rows, "flush_seconds": flush}}
        self._target.parent.mkdir(parents=True, exist_ok=True)
        self._lock = WriteLock(self._target)
        try:
            self._target = check_target(self.path, force=self.force)
            _warn_if_the_disk_is_too_small(self._target, meta)
            self._partial = self._target.with_name(self._target.name + ".partial")
            self._sf = SafeFile(self._partial, create=True)
            self._f = h5py.File(self._sf, "w", libver="latest")
            write_attrs(self._f, self.config, self._meta)
        except BaseException:
            self._abandon()
            raise
        self._slot = -1

    def _abandon(self) -> None:
        """Close everything without publishing (a run that never saved a state)."""
        if self._f is not None:
            with contextlib.suppress(Exception):
                self._f.close()
        if self._sf is not None:
            self._sf.close()
        if self._partial is not None:
            with contextlib.suppress(OSError):
                self._partial.unlink()
        self._f = self._sf = self._h = None
        self._partial = None
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def _check(self) -> None:
        """Raise :class:`ResultWriteError` once a write to disk failed."""
        if self._sf is not None and self._sf.error is not None:
            raise self._error(self._sf.error, published=self._partial is None)

    def _error(self, err: OSError, *, published: bool) -> ResultWriteError:
        """The error that stops the run after the failed write ``err``."""
        what = f"{err.strerror or err}" + (f" (errno {err.errno})" if err.errno else "")
        if not published:
            return ResultWriteError(f"{self.path}: writing failed: {what}; no state was saved")
        return ResultWriteError(
            f"{self.path}: writing failed: {what}; the file keeps the run up to its last "
            f"checkpoint and can be resumed (isoflow run --resume {self.path})"
        )

    def append(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        """Write saved states ``ys`` at ``ts`` and their diagnostics (durable at checkpoint).

        The first call creates the row datasets from the shapes and dtypes of its arguments.

        Parameters
        ----------
        ts : ndarray, shape (n,)
            Times of the saved states.
        ys : ndarray, shape (n, *batch, *shape)
            The saved states, time first.
        series : dict of str to ndarray
            The diagnostics of the same rows, name to array ``(n, ...)``.

        Raises
        ------
        ValueError
            Called before :meth:`open`.
        ResultWriteError
            A write failed.
        """
        if self._f is None:
            raise ValueError("HDF5Writer.append before open")
        if self._h is None:
            shape = tuple(ys.shape[1:])
            core = tuple(self._meta.get("core_shape", shape))
            members = int(np.prod(shape[: len(shape) - len(core)], dtype=np.int64))
            create_layout(
                self._f, shape, ys.dtype,
                {k: (tuple(v.shape[1:]), v.dtype) for k, v in series.items()},
                members, self.chunk_rows,
            )  # fmt: skip
            self._f.swmr_mode = True  # from here on: no new objects or attributes
            self._h = Handles(self._f)
        self._h.write_block(ts, ys, series)
        self._check()

    def _flush(self) -> None:
        assert self._f is not None
        self._f.flush()
        self._check()

    def _commit(
        self, step: int, y: Array, method_state: Any, failures: MemberFailures | None,
        run_info: dict[str, Any] | None,
    ) -> None:  # fmt: skip
        h = self._h
        assert h is not None
        self._flush()
        slot = 1 - self._slot if self._slot >= 0 else 0
        h.write_slot(slot, step, y, method_state, failures, run_info)
        self._flush()
        h.point_to(slot)
        self._flush()
        self._slot = slot

    def checkpoint(
        self, step: int, y: Array, method_state: Any, failures: MemberFailures | None = None
    ) -> None:
        """Flush the rows, then write a complete checkpoint into the spare slot and point to it.

        The first checkpoint moves the file from ``<path>.partial`` to ``path``.

        Parameters
        ----------
        step : int
            Number of steps taken to reach ``y``.
        y : ndarray, shape (*batch, *shape)
            The state after ``step`` steps.
        method_state : object
            The method's state (``None`` or a flat tuple of numbers and arrays) for a resume
            bit for bit.
        failures : MemberFailures, optional
            Which ensemble members failed, when and why (``None``: none recorded).

        Raises
        ------
        ValueError
            Called before the first :meth:`append`.
        ResultWriteError
            A write failed.
        """
        if self._f is None or self._h is None:
            raise ValueError("HDF5Writer.checkpoint before the first rows")
        self._commit(step, y, method_state, failures, None)
        self._last = (int(step), y, method_state, failures)
        self._publish()

    def _publish(self) -> None:
        """Move the file from its temporary name to ``path`` (after the first checkpoint)."""
        if self._partial is not None:
            check_target(self.path, force=True)  # still not a directory or a device
            os.replace(self._partial, self._target)
            self._partial = None

    def close(self, info: dict[str, Any]) -> None:
        """Publish the run's final status with its last checkpoint, close and unlock the file.

        A file that never received a checkpoint is removed. Nothing happens when the writer
        is not open.

        Parameters
        ----------
        info : dict
            The run's final status: status, message and :class:`~isoflow.SolveStats`
            (JSON-ready), written with the last checkpoint.

        Raises
        ------
        ResultWriteError
            A write failed (now or earlier): the file on disk holds the run up to its last
            complete checkpoint and resumes.
        """
        if self._f is None:
            return
        err: OSError | None = None
        published = self._partial is None
        try:
            if self._last is not None and self._h is not None and self._sf is not None:
                if self._sf.error is None:
                    step, y, st, fails = self._last
                    self._commit(step, y, st, fails, info)
        finally:
            f, sf = self._f, self._sf
            self._f = self._sf = self._h = None
            try:
                f.close()
            finally:
                if sf is not None:
                    err = sf.error
                    sf.close()
                if err is None and self._partial is not None and self._last is not None:
                    self._publish()
                self._abandon()  # removes a file never published; releases the lock
        if err is not None:
            raise self._error(err, published=published)

    # resuming -------------------------------------------------------------------------------

    @classmethod
    def reopen(
        cls,
        path: Path,
        lock: WriteLock,
        *,
        n_rows: int,
        n_blocks: int,
        slot: int,
        last: tuple[int, Array, Any, MemberFailures | None],
        chunk_rows: int,
        flush_seconds: float,
    ) -> HDF5Writer:
        """Open a (closed, version 2) file for appending after row ``n_rows``.

        ``lock`` is held by the caller and released by :meth:`close`; ``last`` is the
        checkpoint ``slot`` holds.

        Parameters
        ----------
        path : Path
            The result file (published, not ``.partial``).
        lock : WriteLock
            The file's write lock, already held.
        n_rows : int
            Number of valid rows; the row datasets are cut to it.
        n_blocks : int
            Number of valid checksum rows (blocks); the checksums are cut to it.
        slot : int
            The checkpoint slot (0 or 1) the file points to.
        last : (int, ndarray, object, MemberFailures or None)
            The checkpoint in ``slot``: step, state, method state, failures.
        chunk_rows : int
            Rows between checkpoints from now on.
        flush_seconds : float
            Seconds between checkpoints from now on.

        Returns
        -------
        HDF5Writer
            Open for :meth:`append` and :meth:`checkpoint`.
        """
        w = cls.__new__(cls)
        w.path = w._target = Path(path)
        w.force = True
        w.chunk_rows, w.flush_seconds = int(chunk_rows), float(flush_seconds)
        w._lock, w._partial, w._h, w._f = lock, None, None, None
        w._sf = SafeFile(path, create=False)
        try:
            f = h5py.File(w._sf, "r+", libver="latest")
            w._f = f
            w.config = json.loads(f.attrs["config"])
            w._meta = json.loads(f.attrs["meta"])
            w._h = Handles(f, n_rows, n_blocks)
            w._h.truncate()
            f.flush()
            f.swmr_mode = True
            w._check()
        except BaseException:
            w._last = None
            w._abandon()
            raise
        w._slot, w._last = slot, last
        return w
