"""The worker thread alone: a fast live camera never makes the results lag (frames are dropped,
not queued), and stopping joins the thread and closes the source."""

from __future__ import annotations

import time

import numpy as np
import pytest
from PySide6 import QtWidgets

from qrfield.camera import resolve_camera
from qrfield.geometry import Pose
from qrfield.render import render_view
from qrfield.runconfig import RunConfig
from qrfield.sources import Frame, FrameSource
from ui.worker import PipelineWorker, start_worker, stop_worker

pytestmark = pytest.mark.gui


class FastLiveCamera(FrameSource):
    """A live camera delivering the same rendered view about every millisecond (faster than any
    processing), as a driver hands out frames whether or not anyone keeps up."""

    name = "fast"
    live = True

    def __init__(self, image: np.ndarray) -> None:
        super().__init__()
        self.image = image

    def _open_impl(self) -> None:
        pass

    def _read_impl(self, index: int) -> Frame:
        time.sleep(0.001)
        return Frame(self.image, time.monotonic(), index)

    def _close_impl(self) -> None:
        pass


@pytest.mark.slow
def test_a_fast_live_camera_is_drained_and_results_stay_current(qtbot, camera_vga) -> None:
    image = render_view(camera_vga, 50.0, Pose([0, 0, 300], [10, 10, 0]), noise_sigma=2.0, seed=1).image
    sources: list[FastLiveCamera] = []

    def factory(spec: str, **kwargs) -> FrameSource:
        sources.append(FastLiveCamera(image))
        sources[-1].open()
        return sources[-1]

    config = RunConfig("fast", resolve_camera("picam-v2@640x480"), 50.0, ("numerical", "ippe"))
    worker = PipelineWorker(config, source_factory=factory)
    thread = start_worker(worker)
    try:
        qtbot.waitUntil(lambda: worker.frames_processed >= 15, timeout=20000)
        reader = worker._reader
        assert reader is not None
        # The camera delivered far more frames than were processed: the extra ones were dropped
        # by the reader (never queued), so each processed frame was the newest one at the time.
        assert reader.read_count > worker.frames_processed and reader.dropped > 0
        taken: list = []
        qtbot.waitUntil(lambda: taken.append(worker.latest.take()) or taken[-1] is not None, timeout=20000)
        assert taken[-1].result.status == "OK", taken[-1].result.reason
    finally:
        assert stop_worker(worker, thread)
    assert not sources[0].is_open and worker.source is None
    # Back on the GUI thread once its loop ended: the QObject is never deleted on a worker thread.
    assert worker.thread() is QtWidgets.QApplication.instance().thread()
