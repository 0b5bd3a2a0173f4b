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
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from PySide6 import QtCore

from qrfield.engine import FrameLoop
from qrfield.mailbox import Mailbox
from qrfield.pipeline import FrameResult
from qrfield.runconfig import RunConfig
from qrfield.sources import Frame

__all__ = ["PipelineWorker", "Processed", "RunConfig", "start_worker", "stop_worker"]


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
        self.loop = FrameLoop(config, events=self, opener=source_factory, hold_when_down=True)

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
