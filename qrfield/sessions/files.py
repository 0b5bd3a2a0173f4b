"""Durable file primitives for sessions: the OS calls appends use (atomic whole-file writes are
:func:`qrfield.files.atomic_write`, re-exported here).

:class:`FileOps` bundles the os calls that appending a row needs so that tests can substitute a
writer that fails (ENOSPC, EACCES, a short write) without touching the real file system.
"""

from __future__ import annotations

import os

from qrfield.files import atomic_write, fsync_dir, unique_path


class FileOps:
    """The OS calls used to append rows (override in tests to inject faults)."""

    def open(self, path: str, flags: int, mode: int = 0o644) -> int:
        return os.open(path, flags, mode)

    def write(self, fd: int, data: bytes) -> int:
        return os.write(fd, data)

    def fsync(self, fd: int) -> None:
        os.fsync(fd)

    def size(self, fd: int) -> int:
        return os.fstat(fd).st_size

    def pread(self, fd: int, length: int, offset: int) -> bytes:
        return os.pread(fd, length, offset)

    def truncate(self, fd: int, length: int) -> None:
        os.ftruncate(fd, length)

    def close(self, fd: int) -> None:
        os.close(fd)


# One home for atomic writes and folder fsyncs: qrfield.files (re-exported for the session code).
__all__ = ["FileOps", "atomic_write", "fsync_dir", "unique_path"]
