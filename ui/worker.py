"""The worker: the core's frame loop (:class:`qrfield.engine.FrameLoop`) on its own QThread.

The loop owns the camera source (opened, read and closed on the worker's thread only), reads only
the newest frame, measures and hands every result to the sinks (the serial panel's publisher).
Each result also goes, as a :class:`Processed`, into a :class:`qrfield.mailbox.Mailbox` (a newer
result replaces an unread one: the GUI drops frames, it never queues them), which the GUI takes on
its redraw timer. The GUI hands over new settings with :meth:`PipelineWorker.configure`
(thread-safe, applied before the next frame) and never touches the camera. A source that fails is
reported by ``sourceFailed`` and stays closed until :meth:`PipelineWorker.reopen` (or, with a retry
interval set, until the loop reopens it); ``sourceDown(reason)`` says that no frames come (opening
hangs, a live camera stalls, or the source failed: the serial link's NOSRC), until the next result.

This long-lived QThread is the app's one exception to :class:`ui.background.BackgroundJob`, the
app's way of running other work off the GUI thread: the frame loop is not a job that ends with a
result but the engine itself, running for the window's whole life.

Shutdown (:func:`stop_worker`, docs/architecture.md "Shutdown"): stop the loop, then join the thread
with a bounded wait. When its loop ends, the worker moves itself back to the application's thread,
so that the QObject is never deleted on, or after the end of, the worker thread (the window then
makes the worker and its QThread its children). A worker whose
thread does not end in time stays referenced here (:func:`unjoined_workers`) until it does: neither
it nor its QThread is destroyed while running, whatever Qt does to the window meanwhile.
"""

from __future__ import annotations

import threading
import time
import weakref
from dataclasses import dataclass
from typing import Any

from PySide6 import QtCore

from qrfield.engine import FrameLoop
from qrfield.mailbox import Mailbox
from qrfield.pipeline import FrameResult
from qrfield.runconfig import RunConfig
from qrfield.sources import Frame

__all__ = [
    "PipelineWorker",
    "Processed",
    "RunConfig",
    "start_worker",
    "stop_worker",
    "unjoined_workers",
    "wait_for_workers",
]

#: How long :func:`stop_worker` waits for the thread by default, ms: the current frame, closing the
#: reader (up to 2 s, qrfield.sources.LatestFrameReader.stop) and the source.
STOP_WAIT_MS = 5000


@dataclass(frozen=True)
class Processed:
    """One frame and what the pipeline made of it (what the GUI draws)."""

    frame: Frame
    result: FrameResult
    t_done: float
    #: frames the source delivered after this one by the time its result was ready (0 = it is the
    #: newest frame; a live camera's preview lags by this many frames)
    frames_behind: int = 0
    #: the source is not a live camera (qrfield.sources.is_live_camera): its poses are SIM, never OK
    simulated: bool = True
    #: the request number (:meth:`PipelineWorker.configure` / ``reopen``) its source was opened for
    generation: int = 0


class PipelineWorker(QtCore.QObject):
    """The frame loop on a QThread, its events as signals. Start with :func:`start_worker`."""

    sourceOpened = QtCore.Signal(str)  # description
    sourceFailed = QtCore.Signal(str)  # why; the source is closed until reopen()
    sourceNote = QtCore.Signal(str)
    sourceDown = QtCore.Signal(str)  # why no frames come (the serial link says NOSRC meanwhile)
    finished = QtCore.Signal()

    def __init__(self, config: RunConfig, *, source_factory: Any = None) -> None:
        super().__init__()
        #: The newest result not yet drawn (the GUI takes it on its redraw timer).
        self.latest: Mailbox[Processed] = Mailbox()
        # A proxy: no worker <-> loop cycle, so the worker is freed where its last reference goes
        # (the GUI thread), never by a garbage collection that happens to run on another thread.
        self.loop = FrameLoop(config, events=weakref.proxy(self), opener=source_factory, hold_when_down=True)

    # ---------------------------------------------------------------- called from the GUI thread
    def configure(self, config: RunConfig, *, reopen: bool = False) -> int:
        """Use ``config`` from the next frame on; the request's number (see FrameLoop.configure:
        results of a source opened for it or later have a ``generation`` at least this)."""
        return self.loop.configure(config, reopen=reopen)

    def reopen(self) -> int:
        return self.loop.reopen()

    def stop(self) -> None:
        self.loop.stop()

    @property
    def result_sinks(self) -> tuple[Any, ...]:
        """Called on the worker thread with every result (``on_result(result, simulated)``, and
        ``on_source_down`` / ``on_source_up``); each must return at once and never touch widgets."""
        return self.loop.sinks

    @result_sinks.setter
    def result_sinks(self, sinks: tuple[Any, ...]) -> None:
        self.loop.sinks = tuple(sinks)

    @property
    def frames_processed(self) -> int:
        return self.loop.frames_processed

    @property
    def source(self) -> Any:
        return self.loop.source

    @property
    def source_camera(self) -> Any:
        """The open source's own camera model (a picamera2 stream's), None when the named applies."""
        return self.loop.source_camera

    @property
    def stream_report(self) -> list[str]:
        """What the open stream delivers and the model it is measured with (the Camera tab)."""
        return self.loop.stream_report

    @property
    def _reader(self) -> Any:
        return self.loop.reader

    @property
    def _config(self) -> RunConfig | None:
        return self.loop.config

    # ---------------------------------------------------------------- the worker thread
    @QtCore.Slot()
    def run(self) -> None:
        try:
            self.loop.run()
        finally:
            # Back to the application's thread before the thread ends: the QObject is then deleted
            # there (a push from the object's own thread is the one move Qt allows here).
            app = QtCore.QCoreApplication.instance()
            if app is not None:
                self.moveToThread(app.thread())
            self.finished.emit()

    # The frame loop's events (on the worker thread): signals to the GUI.
    def opened(self, description: str, again: bool) -> None:
        self.sourceOpened.emit(description)

    def failed(self, message: str, ended: bool) -> None:
        self.sourceFailed.emit(message)

    def note(self, message: str) -> None:
        self.sourceNote.emit(message)

    def source_down(self, reason: str) -> None:
        self.sourceDown.emit(reason)

    def source_up(self) -> None:
        """Frames come again: the next processed result says so (nothing else to tell the GUI)."""

    def processed(self, frame: Frame, result: FrameResult, behind: int) -> None:
        loop = self.loop  # read on the loop's thread: the source this frame came from
        item = Processed(frame, result, time.monotonic(), behind, loop.simulated, loop.source_generation)
        self.latest.put(item)


#: Every started worker with its thread until its thread is seen to end: this reference keeps
#: both alive while the thread runs. Those whose owner gave up waiting (stop_worker False) are
#: deleted here, on the GUI thread, once their thread has ended.
_started: dict[int, tuple[PipelineWorker, QtCore.QThread]] = {}
_abandoned: set[int] = set()
_started_lock = threading.Lock()


def start_worker(worker: PipelineWorker) -> QtCore.QThread:
    """Move ``worker`` to a new QThread and start its loop; returns the thread."""
    thread = QtCore.QThread()
    thread.setObjectName("qrfield-worker")
    worker.moveToThread(thread)
    thread.started.connect(worker.run)
    # Direct: quit() is thread-safe, and the GUI thread may be blocked in thread.wait() meanwhile.
    worker.finished.connect(thread.quit, QtCore.Qt.ConnectionType.DirectConnection)
    with _started_lock:
        _started[id(worker)] = (worker, thread)
    thread.start()
    return thread


def stop_worker(worker: PipelineWorker, thread: QtCore.QThread, timeout_ms: int = STOP_WAIT_MS) -> bool:
    """Stop the loop, close the source, join the thread (GUI thread); True when it has ended.

    False: the thread still runs after ``timeout_ms`` (a source stuck in a read or close); the
    worker and thread stay referenced here (:func:`unjoined_workers`) until it ends, and are then
    deleted on the GUI thread."""
    worker.stop()
    thread.quit()
    if thread.wait(timeout_ms):
        _ended(id(worker))
        return True
    with _started_lock:
        _abandoned.add(id(worker))
    return False


def unjoined_workers() -> list[tuple[PipelineWorker, QtCore.QThread]]:
    """Started workers whose thread has not ended (still running in a window, or stopped and
    not ended in time); call on the GUI thread (those seen ended are let go here)."""
    with _started_lock:
        ended = [key for key, (_w, thread) in _started.items() if thread.isFinished()]
    for key in ended:
        _ended(key)
    with _started_lock:
        return list(_started.values())


def wait_for_workers(timeout_ms: int = STOP_WAIT_MS) -> bool:
    """Stop every started worker and wait up to ``timeout_ms`` in all; True when none still runs."""
    deadline = time.monotonic() + timeout_ms / 1000
    for worker, thread in unjoined_workers():
        left_ms = max(0, int((deadline - time.monotonic()) * 1000))
        stop_worker(worker, thread, left_ms)
    return not unjoined_workers()


def _ended(key: int) -> None:
    """The thread of worker ``key`` has ended: forget it; delete an abandoned one (GUI thread)."""
    with _started_lock:
        pair = _started.pop(key, None)
        abandoned = key in _abandoned
        _abandoned.discard(key)
    if pair is not None and abandoned:
        for qobject in pair:
            qobject.deleteLater()
