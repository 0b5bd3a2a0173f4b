"""Lines to stdout from a thread of their own: a reader that stops reading never stalls the caller.

``qrfield run`` writes one line per frame to stdout for other programs, and the gripper's serial
line must keep getting fresh poses (and SIGTERM must still stop the run) when the program reading
stdout hangs: stdout is best effort, the serial link is not. :class:`LineWriter` keeps at most
``max_lines`` lines waiting; when the reader falls that far behind, the oldest waiting line is
dropped (and counted), never the caller held up.

Where the stream has a file descriptor the thread writes with ``os.write`` (nothing collects in
Python's buffer, so an interpreter exiting with the pipe full has nothing left to flush and does
not hang); otherwise (tests capture stdout with an object of their own) with ``write`` + ``flush``.
"""

from __future__ import annotations

import collections
import os
import threading
import time
from typing import IO


class LineWriter:
    """Writes text lines to ``stream`` on a daemon thread. ``write`` never blocks.

    Attributes:
        dropped: lines dropped because ``max_lines`` were already waiting.
        broken: the reader went away (EPIPE or another write error); nothing more is written.
    """

    def __init__(self, stream: IO[str], max_lines: int = 1000) -> None:
        if max_lines < 1:
            raise ValueError(f"max_lines must be at least 1, got {max_lines}")
        self._stream = stream
        try:
            self._fd: int | None = stream.fileno()
            stream.flush()
        except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is both
            self._fd = None
        self._lines: collections.deque[bytes] = collections.deque()
        self._max = int(max_lines)
        self._cond = threading.Condition()
        self._closing = False
        self._busy = False
        self.dropped = 0
        self.written = 0
        self.broken = False
        self._thread = threading.Thread(target=self._run, name="stdout lines", daemon=True)
        self._thread.start()

    def write(self, line: str) -> bool:
        """Queue ``line`` (a newline is added); False when it cannot go out (closed or broken)."""
        data = (line.rstrip("\n") + "\n").encode("utf-8", "replace")
        with self._cond:
            if self._closing or self.broken:
                return False
            if len(self._lines) >= self._max:
                self._lines.popleft()
                self.dropped += 1
            self._lines.append(data)
            self._cond.notify()
        return True

    @property
    def waiting(self) -> int:
        """Lines queued or being written."""
        with self._cond:
            return len(self._lines) + (1 if self._busy else 0)

    def close(self, timeout: float = 5.0, *, stalled_after: float | None = None) -> int:
        """Stop taking lines and wait for the waiting ones to go out: up to ``timeout`` s in all,
        or, with ``stalled_after``, for as long as the reader keeps taking one line at least every
        ``stalled_after`` s. Returns how many lines were not written (also added to ``dropped``)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            self._closing = True
            self._cond.notify_all()
            progress_at, written = time.monotonic(), self.written
            while (self._lines or self._busy) and not self.broken:
                now = time.monotonic()
                if self.written != written:
                    progress_at, written = now, self.written
                if stalled_after is not None:
                    if now - progress_at >= stalled_after:
                        break
                elif now >= deadline:
                    break
                self._cond.wait(0.05)
            left = len(self._lines) + (1 if self._busy else 0)
            self._lines.clear()
            self.dropped += left
        return left

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._lines and not self._closing:
                    self._cond.wait()
                if not self._lines:
                    return
                data = self._lines.popleft()
                self._busy = True
            ok = self._write(data)
            with self._cond:
                self._busy = False
                if ok:
                    self.written += 1
                else:
                    self.broken = True
                    self._lines.clear()
                self._cond.notify_all()
                if not ok:
                    return

    def _write(self, data: bytes) -> bool:
        try:
            if self._fd is not None:
                view = memoryview(data)
                while view:
                    view = view[os.write(self._fd, view) :]
            else:
                self._stream.write(data.decode("utf-8"))
                self._stream.flush()
        except (OSError, ValueError):  # BrokenPipeError, a closed stream
            return False
        return True
