"""A plain-text progress bar for the terminal (stderr): share done, poses per second, time left."""

from __future__ import annotations

import sys
import time
from typing import TextIO

from qrfield.simulation.runner import Progress


class TerminalProgress:
    """Callable progress sink for :func:`qrfield.simulation.run_study`.

    On a terminal it redraws one line (carriage return) at most ``interval`` seconds apart; when
    the stream is not a terminal (a log file) it prints a line every 10 %.
    """

    def __init__(self, stream: TextIO | None = None, width: int = 28, interval: float = 0.1) -> None:
        self.stream = stream or sys.stderr
        self.width = width
        self.interval = interval
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last_draw = 0.0
        self._last_decile = -1
        self._drawn = False

    def line(self, p: Progress) -> str:
        filled = round(self.width * p.fraction)
        bar = "#" * filled + "-" * (self.width - filled)
        rate = p.poses_per_second
        left = (p.total_poses - p.done_poses) / rate if rate > 0 else float("nan")
        eta = f"{left:4.0f} s left" if left == left else "   ? s left"
        return (
            f"[{bar}] {100 * p.fraction:5.1f} %  {p.done_poses}/{p.total_poses} poses  "
            f"{rate:7.0f} poses/s  {eta}  {p.combination}"
        )

    def __call__(self, p: Progress) -> None:
        now = time.monotonic()
        if self.tty:
            if now - self._last_draw < self.interval and p.done_poses < p.total_poses:
                return
            self._last_draw = now
            self.stream.write("\r" + self.line(p).ljust(110))
            self._drawn = True
        else:
            decile = int(10 * p.fraction)
            if decile == self._last_decile:
                return
            self._last_decile = decile
            self.stream.write(self.line(p) + "\n")
        self.stream.flush()

    def finish(self) -> None:
        """End the bar's line (call once after the run)."""
        if self.tty and self._drawn:
            self.stream.write("\n")
            self.stream.flush()
