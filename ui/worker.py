"""The worker: captures, detects and solves on its own QThread; the GUI only reads its results.

:class:`PipelineWorker` is a QObject moved to a QThread. Its loop owns the camera source (opened,
read and closed on the worker's side only), a :class:`~qrfield.sources.LatestFrameReader` that
keeps only the newest frame, and a :class:`~qrfield.pipeline.Pipeline`. Each result goes into a
one-slot :class:`LatestBox` (a newer result replaces an unread one: the GUI drops frames, it never
queues them) and ``resultReady`` is emitted. The GUI hands over new settings with
:meth:`PipelineWorker.configure` (thread-safe, applied before the next frame) and never touches
the camera. A source that fails is reported by ``sourceFailed`` and stays closed until
:meth:`PipelineWorker.reopen`.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any

from PySide6 import QtCore

from qrfield.camera import CameraModel
from qrfield.pipeline import FrameResult, Pipeline
from qrfield.sources import (
    EndOfStream,
    Frame,
    FrameSource,
    LatestFrameReader,
    Picamera2Settings,
    SourceError,
    VirtualBenchSettings,
    VirtualBenchSource,
    open_source,
    stream_camera,
)
from qrfield.sources.discovery import stream_report


@dataclass(frozen=True)
class RunConfig:
    """Everything the worker needs; the GUI sends a new one whenever a setting changes."""

    source: str
    camera: CameraModel
    side_mm: float
    methods: tuple[str, ...]
    solver_settings: dict[str, Any] = field(default_factory=dict)
    detector_settings: Any = None
    virtual: VirtualBenchSettings = field(default_factory=VirtualBenchSettings)
    select_text: str = ""
    loop: bool = True
    picamera: Picamera2Settings | None = None

    def source_key(self) -> tuple[Any, ...]:
        """What requires reopening the source when it changes."""
        bench = (self.camera, self.side_mm) if self.source in ("virtual", "auto") else ()
        size = (self.camera.size,) if self.source.startswith("usb") else ()
        # picamera2 derives the stream's model from the profile at open: a new profile reopens it.
        pi = self.source.startswith("picamera2") or self.source == "auto"
        pi_key = (self.camera, self.picamera) if pi else ()
        sim = (self.virtual, self.side_mm) if self.source.startswith("picamera2-sim") else ()
        return (self.source, self.loop, *bench, *size, *pi_key, *sim)


class LatestBox:
    """Holds one item; ``put`` replaces an unread one (counted as dropped); ``take`` empties it."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._item: Any = None
        self.dropped = 0

    def put(self, item: Any) -> bool:
        """Store ``item``; True if the box was empty (the reader must be told), False if replaced."""
        with self._lock:
            was_empty = self._item is None
            if not was_empty:
                self.dropped += 1
            self._item = item
            return was_empty

    def take(self) -> Any:
        with self._lock:
            item, self._item = self._item, None
            return item


@dataclass(frozen=True)
class Processed:
    """One frame and what the pipeline made of it (what the GUI draws)."""

    frame: Frame
    result: FrameResult
    t_done: float
    #: frames the source delivered after this one by the time its result was ready (0 = it is the
    #: newest frame; a live camera's preview lags by this many frames)
    frames_behind: int = 0


class PipelineWorker(QtCore.QObject):
    """Runs source -> pipeline on its thread. Start with :func:`start_worker`."""

    resultReady = QtCore.Signal()
    sourceOpened = QtCore.Signal(str)  # description, then any notes
    sourceFailed = QtCore.Signal(str)  # why; the source is closed until reopen()
    sourceNote = QtCore.Signal(str)
    finished = QtCore.Signal()

    #: How long the loop waits for a frame before checking for new settings or a stop, s.
    POLL_S = 0.05

    def __init__(self, config: RunConfig, *, source_factory: Any = None) -> None:
        super().__init__()
        self.latest = LatestBox()
        self._lock = threading.Lock()
        self._pending: RunConfig | None = config
        self._config: RunConfig | None = None
        self._reopen = threading.Event()
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._open_source = source_factory or open_source
        self.source: FrameSource | None = None
        self._reader: LatestFrameReader | None = None
        self._pipeline: Pipeline | None = None
        self._notes_seen = 0
        self.frames_processed = 0
        #: The open source's own camera model (a picamera2 stream's, through its sensor crop; None
        #: when the named model applies) and its report (qrfield.sources.discovery.stream_report);
        #: both set before sourceOpened is emitted.
        self.source_camera: CameraModel | None = None
        self.stream_report: list[str] = []
        #: Called on the worker thread with every FrameResult (e.g. the serial panel's publisher);
        #: each must return at once and never touch widgets. Replace the tuple, never mutate it.
        self.result_sinks: tuple[Any, ...] = ()

    # ---------------------------------------------------------------- called from the GUI thread
    def configure(self, config: RunConfig, *, reopen: bool = False) -> None:
        """Use ``config`` from the next frame on (reopens the source only if it has to, or when
        ``reopen``: then it is opened once, with ``config``, even when its key changed too)."""
        with self._lock:
            self._pending = config
            if reopen:
                self._reopen.set()
        self._wake.set()

    def reopen(self) -> None:
        """Close and open the source again (after a failure, or to restart a file)."""
        with self._lock:
            self._reopen.set()
        self._wake.set()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()

    # ---------------------------------------------------------------- the worker thread
    @QtCore.Slot()
    def run(self) -> None:
        try:
            while not self._stop.is_set():
                self._apply_pending()
                if self._reader is None:
                    self._wake.wait(self.POLL_S)
                    self._wake.clear()
                    continue
                self._step()
        finally:
            self._close_source()
            self.finished.emit()

    def _apply_pending(self) -> None:
        """New settings and a reopen request, taken together: a new source that must be opened
        anyway is opened once, not once for the settings and again for the request."""
        with self._lock:
            config, self._pending = self._pending, None
            reopen = self._reopen.is_set()
            self._reopen.clear()
        opened = False
        if config is not None:
            old, self._config = self._config, config
            if old is None or old.source_key() != config.source_key():
                self._close_source()
                self._open()
                opened = True
            elif isinstance(self.source, VirtualBenchSource) and old.virtual != config.virtual:
                self.source.set_settings(config.virtual)
            if old is None or self._pipeline is None or _pipeline_key(old) != _pipeline_key(config):
                self._pipeline = self._make_pipeline(config)
        if reopen and not opened and self._config is not None:
            self._close_source()
            self._open()

    def _make_pipeline(self, config: RunConfig) -> Pipeline | None:
        try:
            return Pipeline(
                stream_camera(self.source, config.camera) if self.source is not None else config.camera,
                config.side_mm,
                config.methods,
                solver_settings=config.solver_settings,
                detector_settings=config.detector_settings,
                select_text=config.select_text,
            )
        except Exception as exc:  # bad settings must be shown, not crash the worker
            self.sourceNote.emit(f"cannot set up the pipeline: {exc}")
            return None

    def _open(self) -> None:
        config = self._config
        assert config is not None
        try:
            source = self._open_source(
                config.source,
                camera=config.camera,
                side_mm=config.side_mm,
                virtual=config.virtual,
                picamera=config.picamera,
                loop=config.loop,
                pace=True,
            )
        except Exception as exc:  # SourceError, or a driver's own error: the app keeps running
            self.sourceFailed.emit(f"cannot open source {config.source!r}: {exc}")
            return
        self.source = source
        self._notes_seen = 0
        camera = stream_camera(source, config.camera)
        self.source_camera = source.camera
        self.stream_report = stream_report(source, camera)
        if self._pipeline is not None and self._pipeline.camera != camera:
            self._pipeline = self._make_pipeline(config)  # the stream's model differs from the named
        self._reader = LatestFrameReader(source).start()
        self.sourceOpened.emit(source.description)
        if self._pipeline is not None:
            self._pipeline.reset()

    def _step(self) -> None:
        assert self._reader is not None
        try:
            frame = self._reader.get(timeout=self.POLL_S)
        except EndOfStream as exc:
            self.sourceFailed.emit(f"end of stream: {exc}")
            self._close_source()
            return
        except SourceError as exc:
            self.sourceFailed.emit(f"source failed: {exc}")
            self._close_source()
            return
        self._forward_notes()
        if frame is None or self._pipeline is None:
            return
        result = self._pipeline.process(frame)
        self.frames_processed += 1
        for sink in self.result_sinks:
            try:
                sink(result)
            except Exception as exc:  # a faulty sink must not stop the measurements
                self.sourceNote.emit(f"result sink failed: {exc!r}")
        behind = max(0, self._reader.read_count - 1 - frame.index)
        if self.latest.put(Processed(frame, result, time.monotonic(), behind)):
            self.resultReady.emit()

    def _forward_notes(self) -> None:
        source = self.source
        if source is None:
            return
        notes = list(source.notes)
        for note in notes[self._notes_seen :]:
            self.sourceNote.emit(note)
        self._notes_seen = len(notes)

    def _close_source(self) -> None:
        reader, self._reader = self._reader, None
        if reader is not None:
            reader.stop()
        source, self.source = self.source, None
        self.source_camera = None
        if source is not None:
            try:
                source.close()
            except Exception as exc:  # closing a broken device must not take the app down
                self.sourceNote.emit(f"closing the source failed: {exc}")


def _pipeline_key(config: RunConfig) -> tuple[Any, ...]:
    return (
        config.camera,
        config.side_mm,
        config.methods,
        tuple(sorted(config.solver_settings.items())),
        config.detector_settings,
        config.select_text,
    )


def start_worker(worker: PipelineWorker) -> QtCore.QThread:
    """Move ``worker`` to a new QThread and start its loop; returns the thread."""
    thread = QtCore.QThread()
    thread.setObjectName("qrfield-worker")
    worker.moveToThread(thread)
    thread.started.connect(worker.run)
    # Direct: quit() is thread-safe, and the GUI thread may be blocked in thread.wait() meanwhile.
    worker.finished.connect(thread.quit, QtCore.Qt.ConnectionType.DirectConnection)
    thread.start()
    return thread


def stop_worker(worker: PipelineWorker, thread: QtCore.QThread, timeout_ms: int = 5000) -> bool:
    """Stop the loop, close the source, join the thread; True when the thread has ended."""
    worker.stop()
    thread.quit()
    return bool(thread.wait(timeout_ms))
