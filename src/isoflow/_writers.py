"""The writer's side of the time loop: the :class:`StreamWriter` protocol, the in-memory
writer of a run without a file, and the :class:`Sink` that feeds a writer (diagnostics of the
saved rows, appends, checkpoints), in a thread of its own when that pays."""

from __future__ import annotations

import math
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from ._errors import IsoflowError, ParameterError, ResultWriteError
from ._failures import MemberFailures
from .diagnostics import DiagnosticsAccumulator

__all__ = ["PIPELINE_MIN_ROWS", "PIPELINE_SECONDS", "MemoryWriter", "Sink", "StreamWriter"]

Array = NDArray[Any]

#: Target wall time of a chunk when the saved rows are processed by the writer thread (a
#: pipeline: the diagnostics of one chunk overlap the stepping of the next). Long against
#: the interpreter's thread switch interval (5 ms), short against the loop's chunks.
PIPELINE_SECONDS = 0.05
#: Fewest saved rows for which the writer thread is worth starting.
PIPELINE_MIN_ROWS = 256


@runtime_checkable
class StreamWriter(Protocol):
    """What :func:`isoflow.solve` needs from a streaming writer (:class:`isoflow.io.HDF5Writer`).

    The loop calls :meth:`open` once, then for every chunk :meth:`append` with its saved
    states, and :meth:`checkpoint` (on time, every ``flush_seconds``, and when ``chunk_rows``
    rows were appended since the last one) with the step index, the state, the method state and
    the per-member failure record after the last appended row; the writer makes the rows and
    the checkpoint durable together, so what it holds is always a consistent set.
    :meth:`close` ends the run (also after a failure or an interrupt). An ``OSError`` from the
    writer stops the run with :class:`~isoflow.ResultWriteError`.
    """

    chunk_rows: int
    flush_seconds: float

    def open(self, meta: dict[str, Any]) -> None:
        """Start a run described by ``meta`` (times, method, algebra; JSON-ready)."""

    def append(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        """Saved states ``ys`` at ``ts`` (time first) and their diagnostic ``series``."""

    def checkpoint(
        self, step: int, y: Array, method_state: Any, failures: MemberFailures | None
    ) -> None:
        """The state after ``step`` steps, the method state and the failure record.

        Parameters
        ----------
        step : int
            Number of steps taken to reach ``y``.
        y : ndarray, shape (*batch, *shape)
            The state after ``step`` steps (after the last appended row).
        method_state : object
            The method's state (``None`` or a flat tuple of numbers and arrays).
        failures : MemberFailures or None
            Which ensemble members failed, when and why.
        """

    def close(self, info: dict[str, Any]) -> None:
        """End the run; ``info`` holds the status, message and :class:`~isoflow.SolveStats`."""


class MemoryWriter:
    """The in-memory "stream" of :func:`isoflow.solve` without a writer: keeps every saved state.

    The rows are preallocated (the loop knows how many states it saves) and the compiled
    runner writes its saved states straight into them (:meth:`rows`), so memory holds the saved
    states once, not also in chunk buffers or a final concatenation.
    """

    chunk_rows = 2**62
    flush_seconds = math.inf

    def __init__(self, total: int, shape: tuple[int, ...], dtype: Any) -> None:
        """Rows for ``total`` saved states of ``shape``.

        Raises
        ------
        ParameterError
            The rows do not fit in memory (the message says how many bytes they need).
        """
        try:
            self._ts = np.empty(total)
            self._ys = np.empty((total, *shape), dtype=dtype)
        except (MemoryError, ValueError):
            size = float(total) * math.prod(shape) * np.dtype(dtype).itemsize
            raise ParameterError(
                f"the solution would hold {total} saved states of shape {tuple(shape)} in "
                f"memory ({size:.3g} bytes), more than can be allocated: save fewer "
                "(a larger save_every) or stream them to a file (writer=iso.io.HDF5Writer(...))"
            ) from None
        self._n = 0

    def rows(self, count: int) -> Array:
        """A view of the next ``count`` rows (``count`` at most the rows left)."""
        return self._ys[self._n : self._n + count]

    def open(self, meta: dict[str, Any]) -> None:
        """Nothing to prepare."""

    def append(self, ts: Array, ys: Array, series: dict[str, Array]) -> None:
        m = len(ts)
        dst = self._ys[self._n : self._n + m]
        if not np.shares_memory(dst, ys):  # rows written in place need no copy
            dst[...] = ys
        self._ts[self._n : self._n + m] = ts
        self._n += m

    def checkpoint(self, step: int, y: Array, method_state: Any, failures: Any) -> None:
        """In memory there is nothing to make durable."""

    def close(self, info: dict[str, Any]) -> None:
        """Nothing to release."""

    def arrays(self) -> tuple[Array, Array]:
        """All saved times and states, time first."""
        return self._ts[: self._n], self._ys[: self._n]


class Sink:
    """The writer's side of the loop: diagnostics of the saved rows, appends, checkpoints and
    the final close, in the order they are given.

    With ``background=True`` they run in one worker thread, overlapping with the next chunk
    (the compiled drivers release the GIL; NumPy's eigenvalue routines and h5py's writes do
    too), so saving every step costs little more than stepping on a machine with a core to
    spare. Work is queued at most two items deep; an error in the worker is raised in the
    loop at its next call (an ``OSError`` as :class:`ResultWriteError`).
    """

    def __init__(
        self, writer: StreamWriter, accumulator: DiagnosticsAccumulator, series: bool,
        background: bool,
    ) -> None:  # fmt: skip
        self.writer = writer
        self.accumulator = accumulator
        self.series = series
        self.pool: Any = None
        self.pending: list[Any] = []
        if background:
            from concurrent.futures import ThreadPoolExecutor

            self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="isoflow-writer")

    def _do(self, fn: Any, *args: Any) -> None:
        if self.pool is None:
            fn(*args)
            return
        self.pending.append(self.pool.submit(fn, *args))
        while len(self.pending) > 2:
            self.pending.pop(0).result()

    def _rows(self, ts: Array, ys: Array) -> None:
        series = self.accumulator.update(ts, ys) if self.series else {}
        try:
            self.writer.append(ts, ys, series)
        except IsoflowError:
            raise  # already says what failed (a lock, a failed write): not wrapped again
        except OSError as exc:
            raise ResultWriteError(f"writing the saved states failed: {exc}") from exc

    def write_checkpoint(self, k: int, y: Array, st: Any, fails: MemberFailures | None) -> None:
        """A checkpoint, written now (not queued): after an error, with the worker stopped."""
        try:
            self.writer.checkpoint(k, y, st, fails)
        except IsoflowError:
            raise
        except OSError as exc:
            raise ResultWriteError(f"writing a checkpoint failed: {exc}") from exc

    def rows(self, ts: Array, ys: Array) -> None:
        """Saved states (owned by the sink from now on) and their diagnostics."""
        self._do(self._rows, ts, ys)

    def checkpoint(self, k: int, y: Array, st: Any, fails: MemberFailures | None) -> None:
        """A checkpoint (``y``, ``st`` and ``fails`` must not change afterwards: copies)."""
        self._do(self.write_checkpoint, k, y, st, fails)

    def wait(self) -> None:
        """Everything handed over is done (raises the first error of the worker)."""
        pending, self.pending = self.pending, []
        for f in pending:
            f.result()

    def shutdown(self) -> None:
        """Wait for the worker without raising (after another error)."""
        for f in self.pending:
            try:
                f.result()
            except BaseException:  # the error that stopped the run matters more
                pass
        self.pending = []
        if self.pool is not None:
            self.pool.shutdown(wait=True)
            self.pool = None
