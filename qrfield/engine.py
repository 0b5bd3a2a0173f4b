"""The frame loop: open the source, take its newest frame, measure, hand the result on; reopen.

One :class:`FrameLoop` runs ``qrfield run``, ``qrfield session log`` and the bench app's worker
thread (``ui/worker.py`` is a thin QThread around it). Per frame:

1. read: a :class:`~qrfield.sources.LatestFrameReader` reads the source on its own thread; from a
   live camera only the newest frame is taken (the rest are dropped and counted, so the
   measurement never trails the scene); a file, a folder or the virtual bench delivers every frame
   in turn (the reader makes one frame ahead and waits until it is taken);
2. process: :meth:`qrfield.pipeline.Pipeline.process` (never raises);
3. hand on: every sink's ``on_result(result, simulated)`` (``simulated``: the source is not a live
   camera, :func:`qrfield.sources.is_live_camera`; the serial link then says SIM, never OK), and the
   owner's ``processed`` event.

While no frames come (the source cannot be opened, failed, or a live camera delivers nothing for
:attr:`FrameLoop.NO_FRAMES_S`), every sink's ``on_source_down(reason)`` is called once, and
``on_source_up()`` with the next frame: the serial link sends NOSRC meanwhile. A source that fails
is closed and, with ``retry_s`` > 0, reopened every ``retry_s`` seconds; else the loop ends
(``hold_when_down`` False: the commands) or waits for :meth:`FrameLoop.reopen` or a new
configuration (``hold_when_down`` True: the app). New settings (:meth:`FrameLoop.configure`, any
thread) apply before the next frame and reopen the source only when they must.

Events for the owner (the methods of :class:`qrfield.seams.LoopEvents`, called on the loop's thread,
except ``source_down`` which also comes from the opening timer's thread; sinks implement
:class:`qrfield.seams.Sink`, both checked when the loop is made): ``opened(description, again)``,
``failed(message, ended)``, ``note(message)`` (each source note once, pipeline problems),
``processed(frame, result, frames_behind)``, and ``source_down(reason)`` / ``source_up()`` with the
sinks' calls of the same names.

Every :meth:`FrameLoop.configure` and :meth:`FrameLoop.reopen` returns a request number; the
source the loop opens records the number of the newest request applied before it opened
(:attr:`FrameLoop.source_generation`), so an owner that asked for a new source can drop, strictly,
every result of the sources before it (the app's preview).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from qrfield.runconfig import RunConfig
from qrfield.seams import LoopEvents, LoopEventsBase, Sink

#: How the loop ended (:meth:`FrameLoop.run`).
STOPPED, DONE, ENDED, FAILED = "stopped", "done", "ended", "failed"


class FrameLoop:
    """See the module docstring. Run :meth:`run` on the thread that owns the loop."""

    #: How long a wait for a frame lasts before the loop looks at stop requests and settings, s.
    POLL_S = 0.05
    #: A source that delivers no frame for this long counts as down (the serial link says NOSRC), s.
    NO_FRAMES_S = 1.0

    def __init__(
        self,
        config: RunConfig,
        *,
        events: LoopEvents | None = None,
        sinks: Sequence[Sink] = (),
        opener: Callable[..., Any] | None = None,
        hold_when_down: bool = False,
        max_frames: int = 0,
    ) -> None:
        if max_frames < 0:
            raise ValueError(f"max_frames must be >= 0, got {max_frames}")
        self.events: LoopEvents = LoopEventsBase() if events is None else events
        #: Frame sinks (qrfield.seams.Sink); replace the tuple, never mutate it.
        self.sinks: tuple[Sink, ...] = tuple(sinks)
        missing = _missing_methods(self.events, LoopEvents)
        if missing:
            raise TypeError(
                f"events {type(self.events).__name__} lacks {', '.join(missing)} of qrfield.seams.LoopEvents "
                "(subclass qrfield.seams.LoopEventsBase)"
            )
        for sink in self.sinks:
            missing = _missing_methods(sink, Sink)
            if missing:
                raise TypeError(
                    f"sink {type(sink).__name__} lacks {', '.join(missing)} of qrfield.seams.Sink "
                    "(subclass qrfield.seams.BaseSink)"
                )
        self.hold_when_down = hold_when_down
        self.max_frames = int(max_frames)
        self._opener = opener
        self._lock = threading.Lock()
        self._pending: RunConfig | None = config
        self._reopen_requested = False
        self._requests = 0  # configure() and reopen() calls so far (each returns its number)
        self._applied_request = 0
        self._stop = False
        self._wake = threading.Event()
        self.config: RunConfig | None = None
        self.source: Any = None
        self.reader: Any = None
        self.pipeline: Any = None
        #: The open source's own camera model (a picamera2 stream's, through its sensor crop), None
        #: when the named model applies; and the stream's report (the app's Camera tab).
        self.source_camera: Any = None
        self.stream_report: list[str] = []
        self.simulated = True
        #: The request number (configure / reopen) the open source was opened for.
        self.source_generation = 0
        self.frames_processed = 0
        self._dropped_before = 0
        self._notes_seen = 0
        self._failed = False  # the last open failed or the source failed: the next success is "again"
        self._retry_at: float | None = None
        self._ending = ""
        self._last_frame_at = 0.0
        self._down_lock = threading.Lock()
        self._down = False

    # ---------------------------------------------------------------- any thread
    def configure(self, config: RunConfig, *, reopen: bool = False) -> int:
        """Use ``config`` from the next frame on (the source is reopened only if it must be, or
        when ``reopen``: then once, with ``config``). Returns the request's number: a source
        opened after it has a :attr:`source_generation` at least this."""
        with self._lock:
            self._pending = config
            self._reopen_requested = self._reopen_requested or reopen
            self._requests += 1
            number = self._requests
        self._wake.set()
        return number

    def reopen(self) -> int:
        """Close and open the source again (after a failure, or to restart a file); returns the
        request's number (see :meth:`configure`)."""
        with self._lock:
            self._reopen_requested = True
            self._requests += 1
            number = self._requests
        self._wake.set()
        return number

    def stop(self) -> None:
        """End the loop after the current frame (thread-safe; not from a signal handler)."""
        self._stop = True
        self._wake.set()

    def stop_from_signal(self) -> None:
        """End the loop within POLL_S: safe in a signal handler (it takes no lock)."""
        self._stop = True

    @property
    def stopping(self) -> bool:
        return self._stop

    @property
    def dropped(self) -> int:
        """Camera frames that arrived while one was processed and were dropped, over every reopen."""
        reader = self.reader
        return self._dropped_before + (reader.dropped if reader is not None else 0)

    @property
    def latest_only(self) -> bool:
        """The open source is live: only its newest frame is taken."""
        return bool(getattr(self.source, "live", False))

    # ---------------------------------------------------------------- the loop's thread
    def run(self) -> str:
        """Run until stopped, ``max_frames`` processed, or (without ``hold_when_down``) the source
        ends or fails for good; returns STOPPED, DONE, ENDED or FAILED. Closes the source."""
        try:
            while not self._stop:
                self._apply_pending()
                if self.max_frames and self.frames_processed >= self.max_frames:
                    return DONE
                if self.reader is not None:
                    self._step()
                    continue
                if self._ending and not self.hold_when_down:
                    return self._ending
                if self._retry_at is not None and time.monotonic() >= self._retry_at:
                    self._retry_at = None
                    self._open()
                    continue
                self._wake.wait(self.POLL_S)
                self._wake.clear()
            return STOPPED
        finally:
            self._close_source()

    def _apply_pending(self) -> None:
        """New settings and a reopen request, taken together: a source that must be opened anyway
        is opened once."""
        with self._lock:
            config, self._pending = self._pending, None
            reopen, self._reopen_requested = self._reopen_requested, False
            self._applied_request = self._requests
        opened = False
        if config is not None:
            old, self.config = self.config, config
            if old is None or old.source_key() != config.source_key():
                self._close_source()
                self._retry_at = None
                self._open()
                opened = True
            elif old.virtual != config.virtual and hasattr(self.source, "set_settings"):
                self.source.set_settings(config.virtual)  # the virtual bench, live
            if old is None or self.pipeline is None or old.pipeline_key() != config.pipeline_key():
                self._make_pipeline(config)
        if reopen and not opened and self.config is not None:
            self._close_source()
            self._retry_at = None
            self._open()

    def _make_pipeline(self, config: RunConfig) -> None:
        t0 = getattr(self.pipeline, "t0", None)
        try:
            self.pipeline = config.make_pipeline(self.source_camera)
        except Exception as exc:  # bad settings are said, not a crash of the loop
            self.pipeline = None
            self.events.note(f"cannot set up the pipeline: {exc}")
            return
        self.pipeline.t0 = t0  # one stream clock (t_ms) for the whole run

    def _open(self) -> None:
        from qrfield.sources import LatestFrameReader, is_live_camera, stream_camera
        from qrfield.sources.discovery import stream_report

        config = self.config
        assert config is not None
        self._ending = ""
        # Opening may take seconds (picamera2) or hang (a USB camera): the sinks learn that no
        # frames come from a timer, since this thread is busy opening.
        timer = threading.Timer(self.NO_FRAMES_S, self._mark_down, ("opening the source",))
        timer.daemon = True
        timer.start()
        try:
            source = config.open_source(self._opener)
        except Exception as exc:  # SourceError, or a driver's own error: said, never a crash
            timer.cancel()
            again = "still " if self._failed else ""
            self._failed = True
            self._mark_down(f"cannot open source: {exc}")
            self.events.failed(f"{again}cannot open source {config.source!r}: {exc}", False)
            self._after_failure()
            return
        finally:
            timer.cancel()
        self.source = source
        self.source_generation = self._applied_request
        self.simulated = not is_live_camera(source)
        own = stream_camera(source, config.camera)
        self.source_camera = own if own is not config.camera else None
        self.stream_report = stream_report(source, own)
        if self.pipeline is not None and self.pipeline.camera != own:
            self._make_pipeline(config)  # the stream's model differs from the one in use
        self._notes_seen = 0
        self.reader = LatestFrameReader(source).start()
        self._last_frame_at = time.monotonic()
        self.events.opened(source.description, self._failed)
        self._failed = False
        self._forward_notes()
        if self.pipeline is not None:
            self.pipeline.reset(self.pipeline.t0)  # the tracker forgets; the clock runs on

    def _after_failure(self) -> None:
        retry_s = self.config.retry_s if self.config is not None else 0.0
        if retry_s > 0:
            self._retry_at = time.monotonic() + retry_s
        else:
            self._ending = FAILED

    def _step(self) -> None:
        from qrfield.sources import EndOfStream, SourceError

        reader = self.reader
        try:
            frame = reader.get(timeout=self.POLL_S)
        except EndOfStream as exc:
            self._forward_notes()
            self._close_source()
            self._mark_down(f"end of stream: {exc}")
            self.events.failed(f"end of stream: {exc}", True)
            self._ending = ENDED
            return
        except SourceError as exc:
            self._forward_notes()
            self._close_source()
            self._failed = True
            self._mark_down(f"source failed: {exc}")
            self.events.failed(f"source failed: {exc}", False)
            self._after_failure()
            return
        self._forward_notes()
        now = time.monotonic()
        if frame is None:
            if now - self._last_frame_at >= self.NO_FRAMES_S:
                self._mark_down(f"no frame for {now - self._last_frame_at:.1f} s")
            return
        self._last_frame_at = now
        self._mark_up()
        if self.pipeline is None:
            return
        result = self.pipeline.process(frame)
        self.frames_processed += 1
        for sink in self.sinks:
            try:
                sink.on_result(result, self.simulated)
            except Exception as exc:  # a faulty sink must not stop the measurements
                self.events.note(f"result sink failed: {exc!r}")
        behind = max(0, reader.read_count - 1 - frame.index)
        self.events.processed(frame, result, behind)

    def _mark_down(self, reason: str) -> None:
        with self._down_lock:
            if self._down:
                return
            self._down = True
        self._to_sinks(lambda sink: sink.on_source_down(reason))
        self.events.source_down(reason)

    def _mark_up(self) -> None:
        with self._down_lock:
            if not self._down:
                return
            self._down = False
        self._to_sinks(lambda sink: sink.on_source_up())
        self.events.source_up()

    def _to_sinks(self, call: Callable[[Sink], object]) -> None:
        for sink in self.sinks:
            try:
                call(sink)
            except Exception as exc:  # a faulty sink must not stop the loop
                self.events.note(f"sink failed: {exc!r}")

    def _forward_notes(self) -> None:
        source = self.source
        if source is None:
            return
        notes = list(source.notes)
        for note in notes[self._notes_seen :]:
            self.events.note(note)
        self._notes_seen = len(notes)

    def _close_source(self) -> None:
        reader, self.reader = self.reader, None
        if reader is not None:
            reader.stop()
            self._dropped_before += reader.dropped
        source, self.source = self.source, None
        self.source_camera = None
        if source is not None:
            try:
                source.close()
            except Exception as exc:  # closing a broken device must not take the loop down
                self.events.note(f"closing the source failed: {exc}")


def _missing_methods(obj: object, protocol: type) -> list[str]:
    """The methods of ``protocol`` that ``obj`` does not have (a clear error at construction beats a
    missing method found mid-stream)."""
    names = [n for n, v in vars(protocol).items() if callable(v) and not n.startswith("_")]
    return [n for n in names if not callable(getattr(obj, n, None))]
