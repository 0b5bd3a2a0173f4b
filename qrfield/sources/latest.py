"""Read a source on its own thread and keep only the newest frame (so processing never lags).

A live camera delivers frames whether or not anyone is ready for them; if each frame were
processed in turn, a slow step would let frames pile up in the driver's buffer and the result
would trail the scene. :class:`LatestFrameReader` reads continuously and hands out only the newest
frame, counting the ones it dropped.
"""

from __future__ import annotations

import threading

from qrfield.sources.base import Frame, FrameSource, SourceError


class LatestFrameReader:
    """Reads an opened source on a daemon thread; :meth:`get` returns the newest unread frame.

    For a source that is not ``live`` (the virtual bench) the reader renders ahead by one frame
    only: it waits until its frame is taken before reading the next, so no work is thrown away.
    When the source raises (SourceError, EndOfStream or anything else), the reader stops and
    :meth:`get` raises that error (as SourceError) once the frames before it are consumed.
    The reader does not close the source: its owner does, after :meth:`stop`.
    """

    def __init__(self, source: FrameSource) -> None:
        self.source = source
        self.dropped = 0
        self.read_count = 0
        self._cond = threading.Condition()
        self._frame: Frame | None = None
        self._error: SourceError | None = None
        self._stop = False
        self._thread = threading.Thread(target=self._run, name=f"reader {source.name}", daemon=True)

    def start(self) -> LatestFrameReader:
        self._thread.start()
        return self

    def get(self, timeout: float | None = None) -> Frame | None:
        """The newest frame not yet returned; None after ``timeout`` s without one; raises the
        source's error once it failed."""
        with self._cond:
            if self._frame is None and self._error is None:
                self._cond.wait(timeout)
            frame, self._frame = self._frame, None
            if frame is not None:
                self._cond.notify_all()  # an on-request source may make the next frame now
            if frame is None and self._error is not None:
                raise self._error
            return frame

    def stop(self, timeout: float = 2.0) -> bool:
        """Ask the thread to stop and wait up to ``timeout`` s; False if it is still in a read."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        return not self._thread.is_alive()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        while True:
            with self._cond:
                if not self.source.live:
                    while self._frame is not None and not self._stop:
                        self._cond.wait()
                if self._stop:
                    return
            try:
                frame = self.source.read()
            except SourceError as exc:
                error: SourceError = exc
            except Exception as exc:  # a driver's own exception: report it like a source failure
                error = SourceError(f"{self.source.description}: {type(exc).__name__}: {exc}")
            else:
                with self._cond:
                    if self._frame is not None:
                        self.dropped += 1
                    self._frame = frame
                    self.read_count += 1
                    self._cond.notify_all()
                continue
            with self._cond:
                self._error = error
                self._cond.notify_all()
            return
