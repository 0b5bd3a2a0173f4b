"""The calibration dialog, offscreen with pytest-qt, driven by clicks: eight views of the virtual
chessboard give back the camera model they were rendered through (the independent truth); the
coverage grid follows the rendered corners; Save writes a file CameraModel.load reads and does not
overwrite unasked; Use changes the app's camera; the live preview finds a board in the app's own
frames; a screenshot."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore

from qrfield.camera import CameraModel, resolve_camera
from qrfield.chessboard import Board, render_chessboard
from qrfield.geometry import Pose
from qrfield.runconfig import ConfigStore
from qrfield.sources import Frame, FrameSource
from qrfield.sources.base import Pacer
from ui.main_window import MainWindow

pytestmark = [pytest.mark.gui, pytest.mark.slow]
WAIT_MS = 20000
CAMERA = "picam-v2@640x480"


@pytest.fixture(autouse=True)
def _in_tmp_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # nothing may land in ./calib (the checkout's shipped presets)
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path / "user-config"))  # Save writes its calib/


def click(qtbot, widget) -> None:
    qtbot.mouseClick(widget, QtCore.Qt.MouseButton.LeftButton)


def cells_hit(corners_px: np.ndarray, width: int, height: int) -> np.ndarray:
    """(3, 3) bool: image thirds (rows top to bottom) holding at least one of the corners."""
    hit = np.zeros((3, 3), dtype=bool)
    for u, v in corners_px:
        if 0 <= u < width and 0 <= v < height:
            hit[int(v * 3 // height), int(u * 3 // width)] = True
    return hit


def capture_virtual_views(qtbot, dialog, count: int) -> list[np.ndarray]:
    """Click Capture ``count`` times, each when the next rendered board has been found."""
    grids = []
    before = len(dialog.captured)
    for i in range(count):
        qtbot.waitUntil(dialog.capture_button.isEnabled, timeout=WAIT_MS)
        click(qtbot, dialog.capture_button)
        assert len(dialog.captured) == before + i + 1 and dialog.views.count() == before + i + 1
        grids.append(dialog.coverage().copy())
    return grids


def test_virtual_chessboard_views_calibrate_back_to_the_camera(make_window, qtbot, tmp_path: Path) -> None:
    window = make_window({"source": "virtual", "camera": CAMERA})
    truth = resolve_camera(CAMERA)  # what the views are rendered through
    click(qtbot, window.calibrate_button)
    dialog = window.calibration_dialog
    assert dialog is not None and dialog.isVisible()
    click(qtbot, dialog.virtual_check)
    assert dialog.virtual_check.isChecked() and not dialog.compute_button.isEnabled()

    grids = capture_virtual_views(qtbot, dialog, 2)
    assert not dialog.compute_button.isEnabled()  # fewer than 3 views
    grids += capture_virtual_views(qtbot, dialog, 6)
    assert len(dialog.captured) == 8 and dialog.compute_button.isEnabled()

    # Coverage: counted against the exact rendered corners, cell by cell, as views come in.
    expected = np.zeros((3, 3), dtype=int)
    for k, rendered in enumerate(dialog.captured_truth):
        assert rendered is not None
        expected += cells_hit(rendered, truth.width, truth.height)
        np.testing.assert_array_equal(grids[k], expected)
    shown = np.array([[int(dialog.cells[r][c].text()) for c in range(3)] for r in range(3)])
    np.testing.assert_array_equal(shown, expected)
    assert (dialog.hint.text() == "every cell covered") == bool(np.all(expected > 0))
    assert grids[0].sum() < expected.sum()

    click(qtbot, dialog.compute_button)
    qtbot.waitUntil(lambda: dialog.result is not None, timeout=WAIT_MS)
    cam = dialog.result.camera
    # Measured over seeds 0..3 with 8 views: fx, fy within 0.4 %, cx, cy within 1.2 px, RMS ~0.07 px.
    assert cam.fx == pytest.approx(truth.fx, rel=0.006)
    assert cam.fy == pytest.approx(truth.fy, rel=0.006)
    assert abs(cam.cx - truth.cx) < 2.0 and abs(cam.cy - truth.cy) < 2.0
    assert 0 < dialog.result.rms_px < 0.2
    text = dialog.results.toPlainText()
    assert "RMS reprojection error" in text and f"fx = {cam.fx:.2f} ±" in text and "advice:" in text
    assert all("px RMS" in dialog.views.item(i).text() for i in range(8))

    # Save: NAME.json in the user's calib folder (the name given, made file-safe), read back by
    # the core and found by that name; no overwrite unless confirmed.
    dialog.form.widgets["name"].setText("bench cam")
    dialog.form.widgets["name"].editingFinished.emit()
    click(qtbot, dialog.save_button)
    path = tmp_path / "user-config" / "calib" / "bench-cam.json"
    assert not (tmp_path / "calib").exists()
    assert resolve_camera("bench-cam").fx == pytest.approx(cam.fx)
    loaded = CameraModel.load(path)
    assert resolve_camera("bench-cam").fx == pytest.approx(cam.fx)  # --camera bench-cam finds it
    assert (loaded.fx, loaded.fy, loaded.cx, loaded.cy) == pytest.approx((cam.fx, cam.fy, cam.cx, cam.cy))
    assert loaded.size == truth.size
    path.write_text("sentinel")
    dialog.confirm_overwrite = lambda p: False
    click(qtbot, dialog.save_button)
    assert path.read_text() == "sentinel" and "not saved" in dialog.note.text()
    dialog.confirm_overwrite = lambda p: True
    click(qtbot, dialog.save_button)
    assert CameraModel.load(path).fx == pytest.approx(cam.fx)

    # Use: the app's camera model becomes the calibrated one.
    click(qtbot, dialog.use_button)
    assert window.app_settings.camera == str(path)
    assert window.camera_model.fx == pytest.approx(cam.fx)
    # ... and reaches the worker: the frames are solved with it from now on.
    qtbot.waitUntil(
        lambda: (
            window.worker._config is not None and window.worker._config.camera.fx == pytest.approx(cam.fx)
        ),
        timeout=WAIT_MS,
    )

    screenshot = tmp_path / "calibration_dialog.png"
    assert dialog.grab().save(str(screenshot)) and screenshot.stat().st_size > 5000
    out = os.environ.get("QRFIELD_SCREENSHOT_DIR")
    if out:
        dialog.grab().save(str(Path(out) / "calibration_dialog.png"))


class ChessboardSource(FrameSource):
    """A live camera looking at a still chessboard (one rendered view, repeated at 20 fps)."""

    name = "chessboard"

    def __init__(self, image: np.ndarray) -> None:
        super().__init__()
        self.image = image
        self.pacer = Pacer(20.0)

    def _open_impl(self) -> None:
        pass

    def _read_impl(self, index: int) -> Frame:
        self.pacer.wait()
        return Frame(self.image, time.monotonic(), index, label="chessboard")

    def _close_impl(self) -> None:
        pass


def test_live_preview_finds_the_board_in_the_apps_frames(make_window, qtbot) -> None:
    camera = resolve_camera(CAMERA)
    board = Board(9, 6, 25.0)
    pose = Pose(np.array([20.0, -10.0, 600.0]), np.array([20.0, -15.0, 5.0]))
    view = render_chessboard(camera, board, pose, noise_sigma=1.0, seed=3)

    def factory(spec: str, **kwargs) -> FrameSource:
        source = ChessboardSource(view.image)
        source.open()
        return source

    window = make_window({"source": "usb:9", "camera": CAMERA}, source_factory=factory)
    click(qtbot, window.calibrate_button)
    dialog = window.calibration_dialog
    qtbot.waitUntil(dialog.capture_button.isEnabled, timeout=WAIT_MS)
    found = dialog.current.detection.corners_px
    gap = min(np.abs(c - view.corners_px).max() for c in (found, found[::-1]))
    assert gap < 0.3  # the rendered corners, to sub-pixel accuracy
    click(qtbot, dialog.capture_button)
    assert len(dialog.captured) == 1
    np.testing.assert_array_equal(dialog.coverage() > 0, cells_hit(view.corners_px, 640, 480))
    assert "not yet covered" in dialog.hint.text()
    # A board of another size is not found in these frames: Capture stays off.
    dialog.form.widgets["board"].setText("7x5")
    dialog.form.widgets["board"].editingFinished.emit()
    assert not dialog.captured  # views of the old board were cleared
    qtbot.waitUntil(
        lambda: dialog.current is not None and dialog.current.board.label == "7x5", timeout=WAIT_MS
    )
    assert not dialog.capture_button.isEnabled() and "not found" in dialog.found_label.text()


def test_dialog_settings_persist_with_the_app_config(qtbot, tmp_path: Path) -> None:
    store_dir = tmp_path / "config"
    window = MainWindow(ConfigStore(store_dir), {"source": "virtual"})
    qtbot.addWidget(window)
    dialog = window.open_calibration()
    for name, text in (("board", "7x5"), ("name", "left-cam")):
        dialog.form.widgets[name].setText(text)
        dialog.form.widgets[name].editingFinished.emit()
    dialog.form.widgets["square_mm"].setValue(30.0)
    window.shutdown()
    again = MainWindow(ConfigStore(store_dir), {"source": "virtual"})
    qtbot.addWidget(again)
    try:
        settings = again.open_calibration().settings()
        assert (settings.board, settings.square_mm, settings.name) == ("7x5", 30.0, "left-cam")
        assert again.calibration_dialog.board() == Board(7, 5, 30.0)
    finally:
        again.shutdown()


def test_a_failed_save_leaves_the_existing_model_intact(qtbot, tmp_path: Path, monkeypatch) -> None:
    from types import SimpleNamespace

    from ui.calibration_dialog import CalibrationDialog

    monkeypatch.chdir(tmp_path)
    dialog = CalibrationDialog(lambda: resolve_camera(CAMERA))
    qtbot.addWidget(dialog)
    try:
        path = dialog.save_path()
        path.parent.mkdir(parents=True)
        path.write_text('{"the model in use": 1}\n')

        import qrfield.files

        def disk_full(fd: int) -> None:  # the data is written, then the disk is full
            raise OSError(28, "No space left on device")

        monkeypatch.setattr(qrfield.files.os, "fsync", disk_full)
        dialog.result = SimpleNamespace(camera=resolve_camera(CAMERA))
        dialog.confirm_overwrite = lambda p: True
        assert dialog.save() is None and "not saved" in dialog.note.text()
        assert path.read_text() == '{"the model in use": 1}\n'
        assert sorted(p.name for p in path.parent.iterdir()) == [path.name]  # no temporary left
    finally:
        dialog.shutdown()
