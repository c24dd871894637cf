"""File objects that h5py reads and writes through (``h5py.File(fileobj, ...)``).

:class:`SafeFile` makes a failed write harmless to HDF5: the first write the operating system
refuses (no space, I/O error, file too large) is recorded and *not* raised into HDF5. From then
on the disk is not touched again; later writes go to memory, so HDF5 goes on and closes cleanly
(an exception inside HDF5's write path leaves it in a state that crashes at close). The writer
checks :attr:`SafeFile.error` after each chunk and stops the run with
:class:`~isoflow.ResultWriteError`; what is on disk is what a kill at that write leaves: the run
up to its last complete checkpoint.

:class:`ReadView` shows a file as it would be had its writer closed it: a file killed while in
HDF5's single-writer/multiple-reader mode keeps the superblock's "open for writing" flags, which
make HDF5 refuse a plain open and retry reads (for minutes, on a damaged file) in SWMR mode. The
view clears the flags in the superblock it reads (recomputing the superblock checksum, Bob
Jenkins' lookup3 as HDF5 uses it) and leaves the file untouched.
"""

from __future__ import annotations

import errno
import io
import os
from collections.abc import Callable
from typing import Any

__all__ = ["ReadView", "SafeFile", "lookup3", "superblock_flags"]

#: Test hook: called as ``hook(safefile, offset, data)`` before every write to disk. It may
#: raise ``OSError`` (a failing disk) or copy the file (a kill at this write).
write_hook: Callable[[SafeFile, int, bytes], None] | None = None

_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_M32 = 0xFFFFFFFF


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _M32


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle`` of ``data``, the checksum of HDF5's metadata.

    Parameters
    ----------
    data : bytes
        The bytes to hash.
    initval : int
        The initial value (default 0, as HDF5 uses).

    Returns
    -------
    int
        The 32-bit hash.
    """
    length = len(data)
    a = b = c = (0xDEADBEEF + length + initval) & _M32
    i = 0
    while length > 12:
        a = (a + int.from_bytes(data[i : i + 4], "little")) & _M32
        b = (b + int.from_bytes(data[i + 4 : i + 8], "little")) & _M32
        c = (c + int.from_bytes(data[i + 8 : i + 12], "little")) & _M32
        a = (a - c) & _M32; a ^= _rot(c, 4); c = (c + b) & _M32  # fmt: skip  # noqa: E702
        b = (b - a) & _M32; b ^= _rot(a, 6); a = (a + c) & _M32  # fmt: skip  # noqa: E702
        c = (c - b) & _M32; c ^= _rot(b, 8); b = (b + a) & _M32  # fmt: skip  # noqa: E702
        a = (a - c) & _M32; a ^= _rot(c, 16); c = (c + b) & _M32  # fmt: skip  # noqa: E702
        b = (b - a) & _M32; b ^= _rot(a, 19); a = (a + c) & _M32  # fmt: skip  # noqa: E702
        c = (c - b) & _M32; c ^= _rot(b, 4); b = (b + a) & _M32  # fmt: skip  # noqa: E702
        length -= 12
        i += 12
    if length == 0:
        return c
    tail = data[i:] + bytes(12 - length)
    a = (a + int.from_bytes(tail[0:4], "little")) & _M32
    b = (b + int.from_bytes(tail[4:8], "little")) & _M32
    c = (c + int.from_bytes(tail[8:12], "little")) & _M32
    c ^= b; c = (c - _rot(b, 14)) & _M32  # fmt: skip  # noqa: E702
    a ^= c; a = (a - _rot(c, 11)) & _M32  # fmt: skip  # noqa: E702
    b ^= a; b = (b - _rot(a, 25)) & _M32  # fmt: skip  # noqa: E702
    c ^= b; c = (c - _rot(b, 16)) & _M32  # fmt: skip  # noqa: E702
    a ^= c; a = (a - _rot(c, 4)) & _M32  # fmt: skip  # noqa: E702
    b ^= a; b = (b - _rot(a, 14)) & _M32  # fmt: skip  # noqa: E702
    c ^= b; c = (c - _rot(b, 24)) & _M32  # fmt: skip  # noqa: E702
    return c


def _superblock(head: bytes) -> tuple[int, int] | None:
    """``(length, flags)`` of a version 2/3 superblock with 8-byte addresses, else ``None``."""
    if len(head) < 48 or head[:8] != _SIGNATURE or head[8] not in (2, 3) or head[9] != 8:
        return None
    return 48, head[11]


def superblock_flags(head: bytes) -> int | None:
    """The file consistency flags of a v2/v3 superblock (``head``: the file's first bytes)."""
    sb = _superblock(head)
    return None if sb is None else sb[1]


class _Overlaid(io.RawIOBase):
    """A file descriptor read through an overlay of byte ranges held in memory."""

    def __init__(self, fd: int, size: int) -> None:
        super().__init__()
        self._fd = fd
        self._pos = 0
        self._size = size
        self._overlay: list[tuple[int, bytes]] = []
        self._disk_size = size

    def readable(self) -> bool:
        return True

    def fileno(self) -> int:
        """The file descriptor (the file may have been renamed since it was opened)."""
        return self._fd

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._pos, io.SEEK_END: self._size}[whence]
        self._pos = max(0, base + offset)
        return self._pos

    def tell(self) -> int:
        return self._pos

    def readinto(self, buffer: Any) -> int:
        """Read from the current position into ``buffer`` (the overlay applied, zeros past
        the end of the file on disk); return the bytes read.

        Parameters
        ----------
        buffer : writable buffer
            Filled with up to ``len(buffer)`` bytes.
        """
        view = memoryview(buffer).cast("B")
        n = len(view)
        start = self._pos
        data = bytearray(os.pread(self._fd, n, start)) if start < self._disk_size else bytearray()
        if len(data) < n:
            data += bytes(n - len(data))
        for off, chunk in self._overlay:
            lo, hi = max(off, start), min(off + len(chunk), start + n)
            if lo < hi:
                data[lo - start : hi - start] = chunk[lo - off : hi - off]
        view[:] = data
        self._pos += n
        return n

    def close(self) -> None:
        if not self.closed:
            os.close(self._fd)
        super().close()


class SafeFile(_Overlaid):
    """A writable file for h5py whose first failed write is recorded, not raised.

    Parameters
    ----------
    path : str or PathLike
        The file.
    create : bool
        Create (truncate) the file; else open an existing one for reading and writing.

    Attributes
    ----------
    error : OSError or None
        The first write the operating system refused; from then on nothing reaches the disk.
    writes : int
        Writes to disk so far (for fault-injection tests).
    """

    def __init__(self, path: str | os.PathLike[str], *, create: bool) -> None:
        flags = os.O_RDWR | (os.O_CREAT | os.O_TRUNC if create else 0)
        fd = os.open(path, flags | getattr(os, "O_CLOEXEC", 0), 0o644)
        super().__init__(fd, os.fstat(fd).st_size)
        self.path = os.fspath(path)
        self.error: OSError | None = None
        self.writes = 0

    def writable(self) -> bool:
        return True

    def write(self, data: Any) -> int:
        """Write ``data`` at the current position; a failed write is recorded in
        :attr:`error` and kept in memory, and later writes go to memory only.

        Parameters
        ----------
        data : bytes-like
            The bytes to write.

        Returns
        -------
        int
            ``len(data)`` (always: HDF5 sees every write succeed).
        """
        raw = bytes(memoryview(data).cast("B"))
        start = self._pos
        self._pos += len(raw)
        self._size = max(self._size, self._pos)
        if self.error is None:
            try:
                if write_hook is not None:
                    write_hook(self, start, raw)
                done = 0
                while done < len(raw):
                    done += os.pwrite(self._fd, raw[done:], start + done)
                self.writes += 1
                self._disk_size = max(self._disk_size, start + len(raw))
                return len(raw)
            except OSError as exc:
                self.error = exc
        self._overlay.append((start, raw))
        return len(raw)

    def truncate(self, size: int | None = None) -> int:
        size = self._pos if size is None else int(size)
        if self.error is None:
            try:
                os.ftruncate(self._fd, size)
                self._disk_size = size
            except OSError as exc:
                self.error = exc
        self._size = size
        return size

    def flush(self) -> None:
        """Nothing is buffered here (HDF5's flush hands every byte to the kernel)."""


class ReadView(_Overlaid):
    """A read-only view of a file with the superblock's "open for writing" flags cleared.

    ``flags=5`` sets them instead (write and SWMR-write access): the view of a file a live
    writer writes through :class:`SafeFile`, for HDF5's SWMR reader.

    Attributes
    ----------
    was_flagged : bool
        The file's superblock flags differed from ``flags`` (for ``flags=0``: the file's
        writer did not close it).

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    flags : int
        The superblock's file-consistency flags to show (default 0: closed).
    """

    def __init__(self, path: str | os.PathLike[str], *, flags: int = 0) -> None:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
        super().__init__(fd, os.fstat(fd).st_size)
        head = os.pread(fd, 48, 0)
        self.was_flagged = False
        sb = _superblock(head)
        if (
            sb is not None
            and sb[1] != flags
            and lookup3(head[:44]) == int.from_bytes(head[44:48], "little")
        ):
            patched = bytearray(head[:44])
            patched[11] = flags
            patched += lookup3(bytes(patched)).to_bytes(4, "little")
            self._overlay.append((0, bytes(patched)))
            self.was_flagged = True

    def writable(self) -> bool:
        return False

    def write(self, data: Any) -> int:
        """Refuse: the view is read-only.

        Parameters
        ----------
        data : bytes-like
            Ignored.

        Raises
        ------
        OSError
            Always (``EBADF``).
        """
        raise OSError(errno.EBADF, "read-only view")
