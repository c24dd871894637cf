"""The exclusive write lock of a result file: ``fcntl.flock`` on ``<file>.lock`` beside it.

HDF5 takes its own ``flock`` on the data file, and the data file is renamed (``.partial`` to its
name, a recovered copy over it), so the lock lives in a separate file named after the result
file. The lock file holds the pid and host of its writer, for the message a second writer gets.
A writer removes its lock file when it closes; a killed writer's lock is released by the
kernel (the stale file is reused).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import time
from pathlib import Path

from .._errors import ResultFileError

__all__ = ["WriteLock", "is_live", "lock_path"]


def lock_path(path: str | os.PathLike[str]) -> Path:
    """The lock file of the result file ``path``."""
    p = Path(path)
    return p.with_name(p.name + ".lock")


def _holder(lock: Path) -> str:
    try:
        rec = json.loads(lock.read_text())
        return f"pid {int(rec['pid'])} on {rec['host']!s}"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"


class WriteLock:
    """An exclusive lock on writing the result file ``path`` (held until :meth:`release`).

    Parameters
    ----------
    path : str or os.PathLike
        The result file (the lock is a file next to it).
    wait : float
        Seconds to keep trying while the lock is held (default 0.5: a reader's brief shared
        lock, or a race).

    Raises
    ------
    ResultFileError
        Another process holds it (the message names its pid and host).
    """

    def __init__(self, path: str | os.PathLike[str], *, wait: float = 0.5) -> None:
        self.path = lock_path(path)
        self._fd: int | None = None
        deadline = time.monotonic() + wait
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                if time.monotonic() < deadline:  # a reader's brief shared lock, or a race
                    time.sleep(0.02)
                    continue
                raise ResultFileError(
                    f"{Path(path)}: being written by {_holder(self.path)} (lock {self.path}); "
                    "wait for it to finish or stop it"
                ) from None
            try:  # the file we locked must still be the one at the path (not unlinked)
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        record = json.dumps({"pid": os.getpid(), "host": socket.gethostname()}).encode()
        os.ftruncate(fd, 0)
        os.pwrite(fd, record, 0)
        self._fd = fd

    def release(self) -> None:
        """Remove the lock file and release the lock (idempotent)."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.path)
        os.close(self._fd)
        self._fd = None


def is_live(path: str | os.PathLike[str]) -> str | None:
    """``"pid N on HOST"`` if a writer holds the lock of ``path``, else ``None``."""
    lock = lock_path(path)
    try:
        fd = os.open(lock, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return _holder(lock)
    finally:
        os.close(fd)
    return None
