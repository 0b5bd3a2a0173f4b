"""The pose panel shows the engine's states in the serial link's words (docs/conventions.md): SIM,
never OK, with a badge that cannot be missed, for the virtual bench; OK only from a live camera;
NOSRC when no frames come and nothing was measured; STALE over the last real values (their +- kept)
when a camera stalls. Results of a replaced source are never drawn (by the worker's generation
number, not by timestamps). Driven through the real window and worker, offscreen."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest
from PySide6 import QtCore
from test_app_layout import clipped_by_parents, cut_labels, label_problem, settle

from qrfield.camera import resolve_camera
from qrfield.geometry import Pose
from qrfield.render import render_view
from qrfield.sources import Frame, FrameSource, is_live_camera

pytestmark = [pytest.mark.gui, pytest.mark.slow]
WAIT_MS = 20000
CAMERA = "picam-v2@640x480"
BADGE = "SIMULATED — virtual bench, not a camera"


class FakeUsbCamera(FrameSource):
    """A live USB camera as the frame loop sees one (``usb:N``, live, not a stand-in), showing a
    rendered code; ``stalled`` set: read blocks, as a camera that stops delivering."""

    live = True

    def __init__(self, image: np.ndarray, index: int = 5) -> None:
        super().__init__()
        self.name = f"usb:{index}"
        self.image = image
        self.stalled = threading.Event()
        self._closing = threading.Event()

    def _open_impl(self) -> None:
        pass

    def _read_impl(self, index: int) -> Frame:
        while self.stalled.is_set() and not self._closing.is_set():
            time.sleep(0.01)
        time.sleep(0.02)
        return Frame(self.image, time.monotonic(), index)

    def _close_impl(self) -> None:
        self._closing.set()


@pytest.fixture
def code_image() -> np.ndarray:
    pose = Pose([0.0, 0.0, 300.0], [10.0, 10.0, 0.0])
    return render_view(resolve_camera(CAMERA), 50.0, pose, noise_sigma=1.0, seed=3).image


def usb_factory(image: np.ndarray, made: list[FakeUsbCamera], stall_later: bool = False):
    """Opens a FakeUsbCamera per open; with ``stall_later`` every camera after the first is stalled."""

    def factory(spec: str, **kwargs) -> FrameSource:
        camera = FakeUsbCamera(image)
        if stall_later and made:
            camera.stalled.set()
        camera.open()
        made.append(camera)
        return camera

    return factory


def test_the_virtual_bench_shows_sim_and_an_unmistakable_badge_at_800x480(make_window, qtbot) -> None:
    window = make_window({"source": "virtual", "camera": CAMERA, "method": "both"})
    window.resize(800, 480)
    qtbot.waitUntil(lambda: window.last is not None and window.last.result.status == "OK", timeout=WAIT_MS)
    panel = window.pose_panel
    assert window.last.simulated  # the worker says so per result (qrfield.sources.is_live_camera)
    assert panel.state == "SIM" and panel.headline.text().startswith("SIM")
    assert "OK" not in panel.headline.text().split()  # a made-up pose never reads as measured
    assert panel.badge.isVisible() and panel.badge.text() == BADGE
    assert window.preview.info.toPlainText().startswith("SIM ")  # the preview's line says it too
    assert np.all(np.isfinite(panel.displayed("numerical")))  # the values are shown beside it
    settle(qtbot)
    assert (window.width(), window.height()) == (800, 480)
    assert label_problem(panel.badge) == "" and not clipped_by_parents(panel.badge)
    inside = window.rect()
    where = QtCore.QRect(panel.badge.mapTo(window, QtCore.QPoint(0, 0)), panel.badge.size())
    assert inside.contains(where), (where, inside)
    assert not cut_labels(window), cut_labels(window)


def test_a_live_camera_shows_ok_and_no_badge(make_window, qtbot, code_image) -> None:
    made: list[FakeUsbCamera] = []
    window = make_window({"source": "usb:5", "camera": CAMERA}, source_factory=usb_factory(code_image, made))
    qtbot.waitUntil(lambda: window.last is not None and window.last.result.status == "OK", timeout=WAIT_MS)
    assert is_live_camera(made[0]) and not window.last.simulated
    panel = window.pose_panel
    assert panel.state == "OK" and panel.headline.text().startswith("OK")
    assert not panel.badge.isVisible()


def test_a_source_that_fails_to_open_shows_nosrc_and_dashes(make_window, qtbot, tmp_path) -> None:
    window = make_window({"source": str(tmp_path / "unplugged.avi")})
    qtbot.waitUntil(window.banner_row.isVisible, timeout=WAIT_MS)
    panel = window.pose_panel
    assert panel.state == "NOSRC" and panel.headline.text().startswith("NOSRC")
    assert "STALE" not in panel.headline.text()  # nothing was ever measured
    assert not panel.badge.isVisible()
    assert np.all(np.isnan(panel.displayed("numerical")))


def test_a_stalled_camera_turns_the_last_values_stale_and_frames_bring_it_back(
    make_window, qtbot, code_image
) -> None:
    made: list[FakeUsbCamera] = []
    overrides = {"source": "usb:5", "camera": CAMERA, "method": "numerical"}
    window = make_window(overrides, source_factory=usb_factory(code_image, made))
    panel = window.pose_panel
    qtbot.waitUntil(lambda: panel.state == "OK", timeout=WAIT_MS)
    shown = panel.displayed("numerical")
    stds = panel.displayed_std("numerical")
    assert np.all(np.isfinite(shown)) and np.all(np.isfinite(stds))  # values with their +-
    made[0].stalled.set()  # the camera hangs: no banner (nothing failed), only no frames
    qtbot.waitUntil(lambda: panel.state == "STALE", timeout=WAIT_MS)
    assert panel.headline.text().startswith("STALE") and "no frame for" in panel.headline.text()
    assert not window.banner_row.isVisible()
    np.testing.assert_allclose(panel.displayed("numerical"), shown, atol=0.2)  # the last values stay
    assert np.all(np.isfinite(panel.displayed_std("numerical")))  # with their +-
    made[0].stalled.clear()
    qtbot.waitUntil(lambda: panel.state == "OK", timeout=WAIT_MS)


def test_a_result_of_a_replaced_source_is_never_drawn(make_window, qtbot, code_image) -> None:
    made: list[FakeUsbCamera] = []
    factory = usb_factory(code_image, made, stall_later=True)
    window = make_window({"source": "usb:5", "camera": CAMERA}, source_factory=factory)
    qtbot.waitUntil(lambda: window.frames_shown >= 2, timeout=WAIT_MS)
    old = window.last
    assert old is not None and old.generation == 0
    window.timer.stop()  # the test redraws by hand
    window.set_source("usb:6")  # the operator picks another camera
    qtbot.waitUntil(lambda: len(made) == 2, timeout=WAIT_MS)  # stalled: delivers nothing
    window.worker.latest.clear()  # only the results put below are drawn
    assert window._generation > old.generation
    # A frame of the old camera captured after the request (the loop had not applied it yet): a
    # timestamp test would draw it; its generation says it is the old source's.
    late = dataclasses.replace(old, frame=dataclasses.replace(old.frame, t_capture=time.monotonic()))
    shown = window.frames_shown
    window.worker.latest.put(late)
    window._redraw()
    assert window.frames_shown == shown and window.last is old
    window.worker.latest.put(dataclasses.replace(late, generation=window._generation))  # the new one's
    window._redraw()
    assert window.frames_shown == shown + 1
