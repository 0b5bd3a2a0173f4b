"""A UART-speed relay: a pty pair whose far end passes bytes on at a UART's pace, both ways.

A pty carries bytes as fast as they are written, whatever baud is set on it, so it cannot show a
backlog building up on a real 9600-baud line. :class:`UartRelay` is the twin of that line: the link
opens :attr:`UartRelay.device` (the pty's slave end) like a serial device; a thread reads the
master end at once (as a UART driver takes bytes into its ~4 KB buffer) and hands them to the
controller's side no faster than ``bytes_per_s`` (baud / 10 for 8N1), noting when each line's last
byte arrives; what the controller sends (:meth:`UartRelay.send`) reaches the link at the same pace.

Used by the tests (pacing, PING answers at 9600) and by ``qrfield benchmark serial``; never on a
real line. The relay's own clock is ``time.monotonic``; it delivers in steps of ``step_s``.
"""

from __future__ import annotations

import collections
import contextlib
import os
import select
import threading
import time
import tty
from collections.abc import Callable


class UartRelay:
    """See the module doc. ``on_line(line, arrived)`` (the relay's thread) for every line (bytes up
    to and with LF) the controller's side receives, ``arrived`` = time.monotonic() of its last byte.

    Attributes:
        lines: (arrived, line) for every line received, oldest first.
        sent_done: time.monotonic() at which each :meth:`send` had reached the link's side.
    """

    def __init__(
        self,
        bytes_per_s: float,
        *,
        step_s: float = 0.002,
        on_line: Callable[[bytes, float], None] | None = None,
    ) -> None:
        if not bytes_per_s > 0:
            raise ValueError(f"bytes_per_s must be positive, got {bytes_per_s}")
        self.bytes_per_s = float(bytes_per_s)
        self.step_s = float(step_s)
        self.on_line = on_line
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no CR LF translation: bytes as a UART carries them
        self.device = os.ttyname(self.slave)
        self.lines: list[tuple[float, bytes]] = []
        self.sent_done: list[float] = []
        self._to_controller: collections.deque[int] = collections.deque()
        self._to_link: collections.deque[tuple[bytes, int]] = collections.deque()  # (data, index of send)
        self._partial = bytearray()
        self._lock = threading.Lock()
        self._stop = False
        self._sends = 0
        self._thread = threading.Thread(target=self._run, name="uart-relay", daemon=True)
        self._thread.start()

    def send(self, data: bytes) -> None:
        """Bytes the controller writes: they reach the link at the relay's pace, after earlier ones."""
        with self._lock:
            self._to_link.append((bytes(data), self._sends))
            self._sends += 1

    @property
    def backlog(self) -> int:
        """Bytes taken from the link and not yet handed on: the UART driver's buffer."""
        return len(self._to_controller)

    def _run(self) -> None:
        # Credit while bytes wait, capped at 10 steps' worth: a late wake-up of this thread catches
        # up, an idle line banks nothing.
        burst = max(1.0, self.bytes_per_s * self.step_s * 10)
        credit_out = credit_in = 0.0
        last = time.monotonic()
        current: tuple[bytearray, int] | None = None  # the send being passed to the link
        while not self._stop:
            try:
                readable, _, _ = select.select([self.master], [], [], self.step_s)
            except (OSError, ValueError):
                return
            if readable:
                try:
                    data = os.read(self.master, 65536)
                except OSError:
                    return
                self._to_controller.extend(data)
            now = time.monotonic()
            gained = (now - last) * self.bytes_per_s
            last = now
            credit_out = min(credit_out + gained, burst) if self._to_controller else 0.0
            n = int(credit_out)
            if n:
                credit_out -= n
                self._deliver(
                    bytes(self._to_controller.popleft() for _ in range(min(n, len(self._to_controller)))), now
                )
            with self._lock:
                if current is None and self._to_link:
                    data, index = self._to_link.popleft()
                    current = (bytearray(data), index)
            credit_in = min(credit_in + gained, burst) if current is not None else 0.0
            k = int(credit_in)
            if current is not None and k:
                credit_in -= k
                chunk, current[0][:] = bytes(current[0][:k]), current[0][k:]
                with contextlib.suppress(OSError):
                    os.write(self.master, chunk)
                if not current[0]:
                    self.sent_done.append(now)
                    current = None

    def _deliver(self, data: bytes, now: float) -> None:
        self._partial += data
        while (end := self._partial.find(b"\n")) >= 0:
            line = bytes(self._partial[: end + 1])
            del self._partial[: end + 1]
            self.lines.append((now, line))
            if self.on_line is not None:
                self.on_line(line, now)

    def close(self) -> None:
        """Stop the thread and close both ends."""
        self._stop = True
        self._thread.join(2.0)
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> UartRelay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
