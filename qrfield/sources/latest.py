"""Read a source on its own thread and keep only the newest frame (so processing never lags).

A live camera delivers frames whether or not anyone is ready for them; if each frame were
processed in turn, a slow step would let frames pile up in the driver's buffer and the result
would trail the scene. :class:`LatestFrameReader` reads continuously and hands out only the newest
frame, counting the ones it dropped.
"""

from __future__ import annotations

import threading

from qrfield.mailbox import Mailbox
from qrfield.sources.base import Frame, FrameSource, SourceError


class LatestFrameReader:
    """Reads an opened source on a daemon thread; :meth:`get` returns the newest unread frame.

    The frames go through a :class:`qrfield.mailbox.Mailbox`: a frame not taken before the next
    one is read is dropped (:attr:`dropped`). For a source that is not ``live`` (the virtual
    bench, a file) the reader renders ahead by one frame only: it waits until its frame is taken
    before reading the next, so no work is thrown away and no frame is dropped. When the source
    raises (SourceError, EndOfStream or anything else), the reader stops and :meth:`get` raises
    that error (as SourceError) once the frames before it are consumed. The reader does not close
    the source: its owner does, after :meth:`stop`.
    """

    def __init__(self, source: FrameSource) -> None:
        self.source = source
        self._box: Mailbox[Frame] = Mailbox()
        self._error: SourceError | None = None
        self._thread = threading.Thread(target=self._run, name=f"reader {source.name}", daemon=True)

    @property
    def dropped(self) -> int:
        """Frames read but replaced by a newer one before :meth:`get` took them."""
        return self._box.dropped

    @property
    def read_count(self) -> int:
        """Frames read from the source so far."""
        return self._box.puts

    def start(self) -> LatestFrameReader:
        self._thread.start()
        return self

    def get(self, timeout: float | None = None) -> Frame | None:
        """The newest frame not yet returned; None after ``timeout`` s without one; raises the
        source's error once it failed."""
        frame = self._box.wait(timeout)
        if frame is None and self._error is not None:
            raise self._error
        return frame

    def stop(self, timeout: float = 2.0) -> bool:
        """Ask the thread to stop and wait up to ``timeout`` s; False if it is still in a read."""
        self._box.close()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        return not self._thread.is_alive()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        box = self._box
        while True:
            if not self.source.live:
                box.wait_taken()  # an on-request source makes the next frame once this one is taken
            if box.closed:
                return
            try:
                frame = self.source.read()
            except SourceError as exc:
                error: SourceError = exc
            except Exception as exc:  # a driver's own exception: report it like a source failure
                error = SourceError(f"{self.source.description}: {type(exc).__name__}: {exc}")
            else:
                box.put(frame)  # discarded once stopped
                continue
            self._error = error  # before the box closes: a get() woken by close() raises it
            box.close()
            return
