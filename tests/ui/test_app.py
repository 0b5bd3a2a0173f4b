"""The bench app, offscreen with pytest-qt: live pose on the virtual bench against its true pose,
switching solver and source, a source failing mid-stream, a screenshot, settings persistence."""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from qrfield.geometry import Pose, angle_difference
from qrfield.render import render_view
from qrfield.sources import Frame, FrameSource, SourceError, VirtualBenchSettings, open_source

pytestmark = [pytest.mark.gui, pytest.mark.slow]
WAIT_MS = 15000


def meets_seed_criteria(values: np.ndarray, truth: Pose) -> bool:
    """Displayed x, y, z (mm), alpha, beta, gamma (deg) within 5 mm and 2 degrees of the truth."""
    if not np.all(np.isfinite(values)):
        return False
    position_ok = np.linalg.norm(values[:3] - truth.position_mm) < 5.0
    return bool(position_ok and np.all(np.abs(angle_difference(values[3:], truth.angles_deg)) <= 2.0))


def test_app_shows_the_virtual_bench_true_pose(make_window, qtbot, camera_vga) -> None:
    window = make_window(
        {"source": "virtual", "method": "both", "camera": "picam-v2@640x480", "side_mm": 50.0}
    )
    truth = window.virtual_form.value().pose  # the pose the bench was told to render

    def panel_shows_truth() -> None:
        for method in ("numerical", "ippe"):
            assert meets_seed_criteria(window.pose_panel.displayed(method), truth), method
        assert np.allclose(
            window.pose_panel.displayed("true"), np.r_[truth.position_mm, truth.angles_deg], atol=0.01
        )

    qtbot.waitUntil(panel_shows_truth, timeout=WAIT_MS)
    # The preview marks V1..V4 where the renderer put them.
    xs, ys = window.preview.vertices.getData()
    assert np.allclose(np.c_[xs, ys], truth.corners_px(camera_vga, 50.0), atol=2.0)
    assert [label.toPlainText() for label in window.preview.labels] == ["V1", "V2", "V3", "V4"]
    assert window.thread.isRunning() and window.worker.source is not None


def test_switching_solver_changes_what_is_solved(make_window, qtbot) -> None:
    window = make_window({"source": "virtual", "method": "both"})
    qtbot.waitUntil(
        lambda: window.last is not None and set(window.last.result.poses) == {"numerical", "ippe"},
        timeout=WAIT_MS,
    )
    for choice in ("ippe", "numerical"):
        window.set_method(choice)
        qtbot.waitUntil(
            lambda c=choice: window.last is not None and tuple(window.last.result.poses) == (c,),
            timeout=WAIT_MS,
        )
        truth = window.virtual_form.value().pose
        qtbot.waitUntil(
            lambda c=choice, t=truth: meets_seed_criteria(window.pose_panel.displayed(c), t), timeout=WAIT_MS
        )
    assert window.app_settings.method == "numerical"


def test_switching_source_to_a_folder(make_window, qtbot, tmp_path: Path, camera_vga) -> None:
    pose = Pose([-20.0, 15.0, 350.0], [-10.0, 25.0, -30.0])
    folder = tmp_path / "photos"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(
            str(folder / f"img{i}.png"), render_view(camera_vga, 50.0, pose, noise_sigma=2.0, seed=i).image
        )
    window = make_window({"source": "virtual", "method": "ippe"})
    qtbot.waitUntil(lambda: window.last is not None and window.last.result.truth is not None, timeout=WAIT_MS)
    window.set_source(str(folder))
    qtbot.waitUntil(
        lambda: window.last is not None and window.last.result.label.startswith("img"), timeout=WAIT_MS
    )
    # The status line is set by the queued sourceOpened signal, which may land after the redraw
    # timer has already drawn the folder's first frame: wait for it rather than race it.
    qtbot.waitUntil(lambda: "folder" in window.status_source.toolTip(), timeout=WAIT_MS)
    assert window.status_source.text() == "source: photos"  # short in the status bar, in full beside
    assert "folder" in window.source_controls.state.text()
    qtbot.waitUntil(lambda: meets_seed_criteria(window.pose_panel.displayed("ippe"), pose), timeout=WAIT_MS)
    assert np.all(np.isnan(window.pose_panel.displayed("true")))  # no truth column for real sources


class FlakySource(FrameSource):
    """The virtual bench for a few frames, then it fails like an unplugged camera."""

    name = "flaky"

    def __init__(self, inner: FrameSource, frames_before_failure: int, error: Exception) -> None:
        super().__init__()
        self.inner, self.left, self.error = inner, frames_before_failure, error

    def _open_impl(self) -> None:
        self.inner.open()

    def _read_impl(self, index: int) -> Frame:
        if self.left <= 0:
            raise self.error
        self.left -= 1
        return self.inner.read()

    def _close_impl(self) -> None:
        self.inner.close()


@pytest.mark.parametrize("error", [SourceError("camera unplugged"), RuntimeError("driver crashed")])
def test_a_source_failing_midstream_is_reported_and_can_be_reopened(make_window, qtbot, error) -> None:
    opened: list[FlakySource] = []

    def factory(spec: str, **kwargs) -> FrameSource:
        source = FlakySource(open_source("virtual", **kwargs), 5, error)
        opened.append(source)
        source.open()
        return source

    window = make_window({"source": "virtual"}, source_factory=factory)
    qtbot.waitUntil(lambda: window.banner_row.isVisible(), timeout=WAIT_MS)
    assert str(error) in window.banner.text()
    assert window.pose_panel.headline.text().startswith("STALE")
    shown = window.frames_shown
    assert shown >= 1 and window.timer.isActive() and window.thread.isRunning()
    qtbot.mouseClick(window.banner_button, qtbot_button_left())
    qtbot.waitUntil(lambda: len(opened) == 2 and window.frames_shown > shown, timeout=WAIT_MS)
    assert not opened[0].is_open  # the failed source was closed
    qtbot.waitUntil(lambda: window.banner_row.isVisible(), timeout=WAIT_MS)  # and the new one fails too


def test_a_source_that_cannot_open_is_reported(make_window, qtbot, tmp_path: Path) -> None:
    window = make_window({"source": str(tmp_path / "no-such-video.avi")})
    qtbot.waitUntil(lambda: window.banner_row.isVisible(), timeout=WAIT_MS)
    assert "no such file" in window.banner.text() or "not one of" in window.banner.text()
    window.set_source("virtual")
    qtbot.waitUntil(lambda: not window.banner_row.isVisible() and window.last is not None, timeout=WAIT_MS)


def test_window_screenshot_is_not_blank(make_window, qtbot, tmp_path: Path) -> None:
    window = make_window({"source": "virtual", "method": "both"})
    qtbot.waitUntil(lambda: window.frames_shown >= 5, timeout=WAIT_MS)
    path = tmp_path / "window.png"
    assert window.grab().save(str(path))
    image = cv2.imread(str(path))
    assert image is not None and image.shape[:2] == (window.height(), window.width())
    assert image.std() > 20  # text, preview and plots, not an empty grey
    # The preview area shows the camera image: its pixels vary like the rendered card's.
    preview = window.preview.grab().toImage()
    assert (
        preview.width() > 100
        and len({preview.pixel(x, preview.height() // 2) for x in range(0, preview.width(), 7)}) > 5
    )


def test_settings_persist_across_two_app_instances(make_window, qtbot, tmp_path: Path) -> None:
    first = make_window({"source": "virtual"})
    first.camera_controls.side_mm.setValue(42.0)
    first.set_method("ippe")
    first.virtual_form.widgets["z_mm"].setValue(420.0)
    numerical = first.solver_controls.forms["numerical"]
    int_spec = next(spec for spec in numerical.specs if spec.type is int)  # e.g. n_max
    new_int = int(int_spec.default) + 1
    numerical.widgets[int_spec.name].setValue(new_int)
    # The change reaches the worker's pipeline, not only the form.
    qtbot.waitUntil(
        lambda: getattr(first.worker._config.solver_settings["numerical"], int_spec.name) == new_int,
        timeout=WAIT_MS,
    )
    first.shutdown()
    saved = (tmp_path / "config" / "app.json").read_text()
    assert '"side_mm": 42.0' in saved
    second = make_window()
    assert second.app_settings.side_mm == 42.0 and second.app_settings.method == "ippe"
    assert second.app_settings.source == "virtual"
    assert second.virtual_form.value().z_mm == 420.0
    assert second.camera_controls.side_mm.value() == 42.0
    assert getattr(second.solver_controls.settings()["numerical"], int_spec.name) == new_int
    qtbot.waitUntil(lambda: second.last is not None and second.last.result.truth is not None, timeout=WAIT_MS)
    assert second.last.result.truth.position_mm[2] == pytest.approx(420.0)


def test_only_a_source_and_camera_that_worked_are_saved(make_window, qtbot, tmp_path: Path) -> None:
    """A source that failed to open (the issue's `gui --source usb:0`) and a camera profile that does
    not exist are not written to app.json, which `qrfield run` reads: the last ones that worked are."""
    import json

    from qrfield.runconfig import ConfigStore, RunSettings

    def saved_run() -> RunSettings:
        return ConfigStore(tmp_path / "config").group("run", RunSettings)

    first = make_window({"source": "virtual", "camera": "picam-v2@640x480"})
    qtbot.waitUntil(lambda: first.last is not None, timeout=WAIT_MS)
    first.shutdown()
    assert (saved_run().source, saved_run().camera) == ("virtual", "picam-v2@640x480")
    missing = str(tmp_path / "no-such-video.avi")
    second = make_window({"source": missing, "camera": "no-such-camera"})
    qtbot.waitUntil(lambda: second.banner_row.isVisible(), timeout=WAIT_MS)
    second.camera_controls.side_mm.setValue(41.0)  # a setting that works is saved as ever
    second.shutdown()
    run = json.loads((tmp_path / "config" / "app.json").read_text(encoding="utf-8"))
    assert missing not in json.dumps(run) and "no-such-camera" not in json.dumps(run)
    assert (saved_run().source, saved_run().camera, saved_run().side_mm) == (
        "virtual",
        "picam-v2@640x480",
        41.0,
    )
    # A source that failed and then one that opened: the one that opened is saved.
    folder = tmp_path / "frames"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), np.full((480, 640), 128, np.uint8))
    third = make_window({"source": missing})
    qtbot.waitUntil(lambda: third.banner_row.isVisible(), timeout=WAIT_MS)
    third.set_source(str(folder))
    qtbot.waitUntil(lambda: not third.banner_row.isVisible() and third.last is not None, timeout=WAIT_MS)
    third.shutdown()
    assert saved_run().source == str(folder)


def test_close_stops_the_worker_and_closes_the_source(make_window, qtbot) -> None:
    window = make_window({"source": "virtual"})
    qtbot.waitUntil(lambda: window.worker.source is not None, timeout=WAIT_MS)
    source = window.worker.source
    window.close()
    assert window.thread.isFinished() and not source.is_open and window.worker.source is None


def test_the_worker_and_its_thread_are_deleted_with_the_window_on_the_gui_thread(qtbot, tmp_path) -> None:
    from PySide6 import QtCore

    from qrfield.runconfig import ConfigStore
    from ui.main_window import MainWindow

    window = MainWindow(ConfigStore(tmp_path / "config"), {"source": "virtual"})
    deleted: list[threading.Thread] = []
    for qobject in (window.worker, window.thread):
        qobject.destroyed.connect(
            lambda *_: deleted.append(threading.current_thread()), QtCore.Qt.ConnectionType.DirectConnection
        )
    try:
        window.show()
        qtbot.waitUntil(lambda: window.frames_shown >= 1, timeout=WAIT_MS)
    finally:
        window.close()
        window.deleteLater()
    qtbot.waitUntil(lambda: len(deleted) == 2, timeout=WAIT_MS)
    assert all(thread is threading.main_thread() for thread in deleted)


class StuckOnClose(FrameSource):
    """The virtual bench whose close hangs until ``release`` is set, as a camera driver stuck in
    its close would."""

    name = "stuck"

    def __init__(self, inner: FrameSource, release: threading.Event) -> None:
        super().__init__()
        self.inner, self.release = inner, release

    def _open_impl(self) -> None:
        self.inner.open()

    def _read_impl(self, index: int) -> Frame:
        return self.inner.read()

    def _close_impl(self) -> None:
        self.release.wait(60.0)
        self.inner.close()


def test_a_worker_that_does_not_end_in_time_is_said_and_kept_alive_until_it_ends(
    make_window, qtbot, capsys
) -> None:
    from PySide6 import QtWidgets

    from ui.worker import unjoined_workers

    release = threading.Event()

    def factory(spec: str, **kwargs) -> FrameSource:
        source = StuckOnClose(open_source("virtual", **kwargs), release)
        source.open()
        return source

    window = make_window({"source": "virtual"}, source_factory=factory)
    window.WORKER_STOP_MS = 300
    qtbot.waitUntil(lambda: window.frames_shown >= 1, timeout=WAIT_MS)
    worker, thread = window.worker, window.thread
    try:
        window.close()  # the bounded wait runs out: the window closes anyway, and says why
        assert window.worker_stopped is False and thread.isRunning()
        assert "frame loop did not end within 0.3 s" in capsys.readouterr().err
        assert "did not end" in window.notes[-1]
        # Kept referenced while it runs: nothing deletes the worker or its QThread meanwhile.
        assert any(w is worker and t is thread for w, t in unjoined_workers())
    finally:
        release.set()
    qtbot.waitUntil(thread.isFinished, timeout=WAIT_MS)
    # Its loop ended: the worker is back on the GUI thread, where it will be deleted.
    assert worker.thread() is QtWidgets.QApplication.instance().thread()
    assert not any(w is worker for w, _ in unjoined_workers())


def test_virtual_bench_controls_move_the_true_pose(make_window, qtbot) -> None:
    window = make_window({"source": "virtual", "method": "ippe"})
    window.virtual_form.widgets["gamma_deg"].setValue(-60.0)
    target = VirtualBenchSettings().with_pose(Pose([10.0, -5.0, 300.0], [15.0, -20.0, -60.0])).pose
    qtbot.waitUntil(lambda: meets_seed_criteria(window.pose_panel.displayed("ippe"), target), timeout=WAIT_MS)
    assert window.pose_panel.displayed("true")[5] == pytest.approx(-60.0)


def qtbot_button_left():
    from PySide6 import QtCore

    return QtCore.Qt.MouseButton.LeftButton


def test_every_tab_title_is_visible_without_scrolling(make_window, qtbot) -> None:
    window = make_window({"source": "virtual"})
    qtbot.waitExposed(window)
    titles = [window.work_tabs.tabText(i) for i in range(window.work_tabs.count())]
    assert titles == ["Session", "Live plots", "Analysis", "Simulation", "Setup"]
    window.work_tabs.setCurrentIndex(titles.index("Setup"))
    for tabs in (window.tabs, window.work_tabs):
        bar = tabs.tabBar()
        assert bar.sizeHint().width() <= tabs.width(), [tabs.tabText(i) for i in range(tabs.count())]
    setup = [window.tabs.tabText(i) for i in range(window.tabs.count())]
    assert setup == ["Source", "Detect && solve", "Camera", "Virtual bench", "Serial"]


def test_choosing_a_new_source_opens_it_once(make_window, qtbot, tmp_path: Path) -> None:
    opened: list[str] = []

    def factory(spec: str, **kwargs) -> FrameSource:
        opened.append(spec)
        return open_source(spec, **kwargs)

    window = make_window({"source": str(tmp_path / "no-such-video.avi")}, source_factory=factory)
    qtbot.waitUntil(lambda: window.banner_row.isVisible(), timeout=WAIT_MS)
    window.set_source("virtual")  # a new source (new settings) and "open it": one open, not two
    qtbot.waitUntil(lambda: window.frames_shown >= 3, timeout=WAIT_MS)
    processed = window.worker.frames_processed
    qtbot.waitUntil(lambda: window.worker.frames_processed >= processed + 5, timeout=WAIT_MS)
    assert opened == [str(tmp_path / "no-such-video.avi"), "virtual"]
    qtbot.mouseClick(window.source_controls.open_button, qtbot_button_left())  # same settings: reopen
    qtbot.waitUntil(lambda: len(opened) == 3, timeout=WAIT_MS)
    processed = window.worker.frames_processed
    qtbot.waitUntil(lambda: window.worker.frames_processed >= processed + 5, timeout=WAIT_MS)
    assert opened[2:] == ["virtual"]


def test_ctrl_c_or_sigterm_closes_the_window_and_saves_its_settings(
    make_window, qtbot, tmp_path: Path
) -> None:
    import os
    import signal

    from ui.app import close_on_signals

    window = make_window({"source": "virtual", "side_mm": 37.0})
    qtbot.waitUntil(lambda: window.frames_shown >= 1, timeout=WAIT_MS)
    previous = close_on_signals(window)
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        qtbot.waitUntil(lambda: not window.isVisible(), timeout=WAIT_MS)
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    assert window.thread.isFinished() and window.worker.source is None
    assert '"side_mm": 37.0' in (tmp_path / "config" / "app.json").read_text()


def test_a_bad_command_line_value_is_named_and_no_window_opens(qtbot, tmp_path: Path, capsys) -> None:
    import argparse

    from PySide6 import QtWidgets

    from ui.app import main

    before = len(QtWidgets.QApplication.topLevelWidgets())
    args = argparse.Namespace(source="virtual", side_mm=-5.0, config_dir=str(tmp_path / "config"))
    assert main(args) == 2
    error = capsys.readouterr().err
    assert "side_mm" in error and "-5" in error and "minimum" in error
    assert len(QtWidgets.QApplication.topLevelWidgets()) == before and not (tmp_path / "config").exists()


def test_the_frequent_actions_have_keys_named_in_their_tooltips(
    make_window, qtbot, tmp_path, monkeypatch
) -> None:
    from PySide6 import QtCore

    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "sessions"))
    window = make_window({"source": "virtual", "method": "both"})
    window.activateWindow()
    qtbot.waitUntil(lambda: window.isActiveWindow(), timeout=WAIT_MS)
    panel = window.session_panel
    ctrl = QtCore.Qt.KeyboardModifier.ControlModifier
    for button, key in (
        (panel.log_button, "Ctrl+L"),
        (panel.undo_button, "Ctrl+Z"),
        (panel.new_button, "Ctrl+N"),
        (panel.resume_button, "Ctrl+O"),
        (panel.export_button, "Ctrl+E"),
        (panel.cancel_button, "Esc"),
    ):
        assert f"({key}" in button.toolTip(), (button.objectName(), button.toolTip())
    tabs = window.work_tabs
    assert all("Ctrl+Tab: next tab" in tabs.tabToolTip(k) for k in range(tabs.count()))
    qtbot.keyClick(window, QtCore.Qt.Key.Key_Tab, ctrl)  # next tab
    assert tabs.currentIndex() == 1
    qtbot.keyClick(window, QtCore.Qt.Key.Key_Backtab, ctrl | QtCore.Qt.KeyboardModifier.ShiftModifier)
    assert tabs.currentIndex() == 0
    qtbot.keyClick(window, QtCore.Qt.Key.Key_N, ctrl)  # New session…
    assert panel.new_dialog.isVisible()
    panel.name_edit.setText("keys")
    qtbot.mouseClick(panel.create_button, QtCore.Qt.MouseButton.LeftButton)
    assert panel.session is not None
    window.activateWindow()
    qtbot.waitUntil(lambda: panel.log_button.isEnabled(), timeout=WAIT_MS)  # follows the bench: valid
    tabs.setCurrentIndex(1)  # Ctrl+L logs from any tab
    with qtbot.waitSignal(panel.rowLogged, timeout=WAIT_MS):
        qtbot.keyClick(window, QtCore.Qt.Key.Key_L, ctrl)
    asked = []
    monkeypatch.setattr(panel, "ask_confirm", lambda title, text: asked.append(text) or False)
    qtbot.keyClick(window, QtCore.Qt.Key.Key_Z, ctrl)
    assert asked and "row 1" in asked[0]
    panel.session.info = dataclasses.replace(panel.session.info, frames_per_row=1000)
    qtbot.keyClick(window, QtCore.Qt.Key.Key_L, ctrl)
    assert panel.collecting
    qtbot.keyClick(window, QtCore.Qt.Key.Key_Escape)
    assert not panel.collecting and "nothing logged" in panel.status.text()


def test_the_window_fits_a_newly_chosen_screen_size(make_window, qtbot, tmp_path) -> None:
    """At 1024x600 the window kept the size it had at 800x480: it now takes the new screen's free
    area (up to the desktop size), when the screen changes size and when the app starts on a screen
    of another size than the one its size was saved on."""
    from PySide6 import QtCore

    from qrfield.runconfig import ConfigStore
    from ui.main_window import DESKTOP_SIZE, SCREEN_KEY

    window = make_window({"source": "virtual"})
    window.fit_new_screen(QtCore.QRect(0, 0, 800, 480))
    assert (window.width(), window.height()) == (800, 480)
    window.fit_new_screen(QtCore.QRect(0, 0, 1024, 600))  # the display was set to 1024x600
    assert (window.width(), window.height()) == (1024, 600)
    window.fit_new_screen(QtCore.QRect(0, 0, 1920, 1080))
    assert (window.width(), window.height()) == DESKTOP_SIZE
    window.resize(800, 480)
    window.shutdown()
    free = window.screen().availableGeometry()
    store = ConfigStore(tmp_path / "config")
    assert store.value(SCREEN_KEY) == [free.width(), free.height()]  # saved with the window's size
    store.set_value(SCREEN_KEY, [800, 480])  # as if the size was saved on an 800x480 screen
    store.save()
    second = make_window()
    expected = (min(DESKTOP_SIZE[0], free.width()), min(DESKTOP_SIZE[1], free.height()))
    assert (second.width(), second.height()) == expected != (800, 480)
