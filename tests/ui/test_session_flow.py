"""The Session tab's flow on the virtual bench, offscreen with pytest-qt: "Log row" waits for live
frames (with the reason), a row whose frames stop is given up with a message, a label that
disagrees with the angles asks first, a failing row is not reported in green, and Export writes
the rows in force."""

from __future__ import annotations

import csv
import dataclasses
import threading
import time
from pathlib import Path

import pytest
from PySide6 import QtCore
from session_steps import FRAMES, bench, create_session, log_by_enter, rows_csv, type_truth

from qrfield.sources import Frame, FrameSource, SourceError, open_source
from ui.sessions_panel import STATUS_STYLES

pytestmark = [pytest.mark.gui, pytest.mark.slow]
WAIT_MS = 15000
LEFT = QtCore.Qt.MouseButton.LeftButton


@pytest.fixture
def sessions(tmp_path: Path, monkeypatch) -> Path:
    root = tmp_path / "sessions"
    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(root))
    return root


class StallingSource(FrameSource):
    """The virtual bench, whose frames stop while ``stalled`` is set (a camera that hangs)."""

    name = "stalling"

    def __init__(self, inner: FrameSource) -> None:
        super().__init__()
        self.inner = inner
        self.stalled = threading.Event()
        self._closing = threading.Event()

    def _open_impl(self) -> None:
        self.inner.open()

    def _read_impl(self, index: int) -> Frame:
        while self.stalled.is_set() and not self._closing.is_set():
            time.sleep(0.02)
        if self._closing.is_set():
            raise SourceError("closed")
        return self.inner.read()

    def _close_impl(self) -> None:
        self._closing.set()
        self.inner.close()


def test_log_row_is_disabled_without_a_source(make_window, qtbot, sessions, tmp_path) -> None:
    window = make_window({"source": str(tmp_path / "no-such-video.avi"), "method": "both"})
    qtbot.waitUntil(lambda: window.banner_row.isVisible(), timeout=WAIT_MS)
    # One clear empty state in the preview; nothing was measured, so nothing is "STALE".
    assert window.preview_pane.is_empty and "No picture" in window.preview_pane.empty.text()
    assert "no-such-video.avi" in window.banner.text()  # why, once, in the banner
    assert window.pose_panel.headline.text().startswith("NOSRC")
    panel = window.session_panel
    qtbot.mouseClick(panel.new_button, LEFT)
    panel.name_edit.setText("no source")
    qtbot.mouseClick(panel.create_button, LEFT)
    assert panel.session is not None
    panel.form.set_fields({"x": "0", "y": "0", "z": "300", "alpha": "0", "beta": "40", "gamma": "0"})
    assert panel.form.valid and panel.form.combo.currentText() == "beta"
    assert not panel.log_button.isEnabled() and panel.why.text().startswith("no frames:")
    qtbot.keyClick(panel.form.edits["z"], QtCore.Qt.Key.Key_Return)
    assert not panel.collecting and panel.status.text().startswith("cannot log: no frames")
    # A source that works: "Log row" comes alive with its frames, and the empty state goes.
    window.set_source("virtual")
    qtbot.waitUntil(lambda: panel.log_button.isEnabled(), timeout=WAIT_MS)
    assert not window.preview_pane.is_empty and panel.why.text() == ""


def test_a_row_whose_frames_stop_is_given_up_with_a_message(make_window, qtbot, sessions) -> None:
    made: list[StallingSource] = []

    def factory(spec: str, **kwargs) -> FrameSource:
        source = StallingSource(open_source("virtual", **kwargs))
        source.open()
        made.append(source)
        return source

    window = make_window({"source": "virtual", "method": "both"}, source_factory=factory)
    panel = create_session(qtbot, window)
    # Long enough for a frame of a loaded machine to come before the stall, short for the test.
    panel.row_settings.widgets["frame_timeout_s"].setValue(3.0)
    type_truth(qtbot, panel, {k: f"{v:g}" for k, v in bench(window).items()})
    panel.session.info = dataclasses.replace(panel.session.info, frames_per_row=1000)  # a row never done
    qtbot.mouseClick(panel.log_button, LEFT)
    qtbot.waitUntil(lambda: panel.progress.value() >= 1, timeout=WAIT_MS)
    made[-1].stalled.set()  # the camera hangs mid-row
    qtbot.waitUntil(lambda: not panel.collecting, timeout=WAIT_MS)
    assert "not logged: no frame for" in panel.status.text() and panel.status.property("kind") == "error"
    assert rows_csv(panel.session.path)[1] == []  # nothing half-logged
    qtbot.waitUntil(lambda: panel.why.text().startswith("no frame for"), timeout=WAIT_MS)
    assert not panel.log_button.isEnabled()
    made[-1].stalled.clear()  # frames again: the row can be logged
    qtbot.waitUntil(lambda: panel.log_button.isEnabled(), timeout=WAIT_MS)


def test_a_source_failing_while_collecting_ends_the_row(make_window, qtbot, sessions) -> None:
    window = make_window({"source": "virtual", "method": "both"})
    panel = create_session(qtbot, window)
    type_truth(qtbot, panel, {k: f"{v:g}" for k, v in bench(window).items()})
    panel.session.info = dataclasses.replace(panel.session.info, frames_per_row=1000)  # a row never done
    qtbot.mouseClick(panel.log_button, LEFT)
    qtbot.waitUntil(lambda: panel.progress.value() >= 1, timeout=WAIT_MS)
    window._on_source_failed("source failed: camera unplugged")  # as the worker signals it
    assert not panel.collecting and "the source failed while collecting" in panel.status.text()
    assert "camera unplugged" in panel.status.text() and rows_csv(panel.session.path)[1] == []
    assert window.pose_panel.headline.text().startswith("STALE")  # real poses were shown: stale


def test_a_label_that_disagrees_with_the_angles_asks_first(make_window, qtbot, sessions) -> None:
    window = make_window({"source": "virtual", "method": "both"})
    panel = create_session(qtbot, window)
    texts = {k: f"{v:g}" for k, v in bench(window).items()}
    # The row: the pose (0, 40, 0) with the label of the pose before, picked by hand.
    type_truth(qtbot, panel, {**texts, "alpha": "0", "beta": "40", "gamma": "0"}, combo="alpha+beta-gamma+")
    asked: list[tuple[str, str | None]] = []
    answers = iter(["cancel", "use", "keep"])

    def answer(message: str, suggestion: str | None) -> str:
        asked.append((message, suggestion))
        return next(answers)

    panel.ask_combo_choice = answer
    qtbot.keyClick(panel.form.edits["x"], QtCore.Qt.Key.Key_Return)  # cancel: nothing logged
    assert asked[-1][1] == "beta" and "'alpha+beta-gamma+' means α+ β− γ+" in asked[-1][0]
    assert not panel.collecting and panel.status.text().startswith("not logged")
    log_by_enter(qtbot, panel, 1)  # "use": relabelled with the combination the signs fit
    panel.form.combo.setCurrentText("alpha+beta-gamma+")
    log_by_enter(qtbot, panel, 2)  # "keep": logged as labelled, after asking
    assert len(asked) == 3
    _header, rows = rows_csv(panel.session.path)
    assert [r["combo"] for r in rows] == ["beta", "alpha+beta-gamma+"]
    # The bench is at (15, -20, 10): against the typed (0, 40, 0) the rows fail, and say so in
    # the fail colour, not the pass green.
    assert [r["pass"] for r in rows] == ["0", "0"]
    assert panel.status.text().startswith("logged row 2: fail") and panel.status.property("kind") == "fail"
    assert panel.status.styleSheet() == STATUS_STYLES["fail"] != STATUS_STYLES["ok"]


def test_export_writes_the_rows_in_force(make_window, qtbot, sessions, tmp_path, monkeypatch) -> None:
    window = make_window({"source": "virtual", "method": "both"})
    panel = window.session_panel
    assert not panel.export_button.isEnabled()  # no session yet
    panel = create_session(qtbot, window)
    texts = {k: f"{v:g}" for k, v in bench(window).items()}
    type_truth(qtbot, panel, texts)
    log_by_enter(qtbot, panel, 1)
    type_truth(qtbot, panel, {**texts, "z": f"{float(texts['z']) + 10:g}"})
    log_by_enter(qtbot, panel, 2)
    monkeypatch.setattr(panel, "ask_confirm", lambda title, text: True)
    qtbot.mouseClick(panel.undo_button, LEFT)  # row 2 withdrawn
    offered: list[Path] = []
    target = tmp_path / "clean.csv"

    def ask(default: Path) -> str:
        offered.append(default)
        return str(target)

    monkeypatch.setattr(panel, "ask_export_path", ask)
    qtbot.mouseClick(panel.export_button, LEFT)
    assert offered == [panel.session.path / "rows-clean.csv"]  # offered inside the session folder
    assert panel.status.text().startswith("exported 1 rows") and "1 withdrawn left out" in panel.status.text()
    with open(target, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["row"] for r in rows] == ["1"] and rows[0]["n_frames"] == str(FRAMES)
    assert float(rows[0]["gt_z_mm"]) == float(texts["z"]) and float(rows[0]["gt_beta_deg"]) == float(
        texts["beta"]
    )
    _header, raw = rows_csv(panel.session.path)
    assert rows[0]["err_pos_mm"] == raw[0]["err_pos"] and rows[0]["x_mm"] == raw[0]["x"]
    assert len(raw) == 3  # rows.csv keeps both rows and the withdrawal record


def test_a_row_averages_the_frames_the_loop_processed_and_its_note_is_not_kept(
    make_window, qtbot, sessions
) -> None:
    """The row recorder is a sink of the frame loop: with the window drawing nothing (its redraw
    timer stopped) a row is still collected and logged, from frames no one drew. The note belongs
    to its row: the next row starts without it."""
    window = make_window({"source": "virtual", "method": "both"})
    panel = create_session(qtbot, window)
    type_truth(qtbot, panel, {k: f"{v:g}" for k, v in bench(window).items()})
    qtbot.keyClicks(panel.form.note, "card re-taped")
    window.timer.stop()  # nothing more is drawn
    drawn, processed = window.frames_shown, window.worker.frames_processed
    with qtbot.waitSignal(panel.rowLogged, timeout=WAIT_MS):
        qtbot.mouseClick(panel.log_button, LEFT)
    assert window.frames_shown == drawn and window.worker.frames_processed >= processed + FRAMES
    assert panel.form.note.text() == "" and panel.form.valid  # the pose and combination stay
    window.timer.start()
    log_by_enter(qtbot, panel, 2)
    _header, rows = rows_csv(panel.session.path)
    assert [(r["row"], r["note"], r["n_frames"]) for r in rows] == [
        ("1", "card re-taped", str(FRAMES)),
        ("2", "", str(FRAMES)),
    ]


@pytest.mark.slow
@pytest.mark.parametrize("change", ["side", "method", "source", "plot window"])
def test_a_setting_changed_while_collecting_ends_the_row(make_window, qtbot, sessions, change) -> None:
    """(audit-ui) The row recorder takes every frame the loop processes: a QR side, solver or
    source changed in Setup while a row was being collected mixed the frames measured before
    and after the change into one row (at 50 mm, then 60 mm: positions of two scales averaged).
    The row ends at once with a message saying why, and nothing is written; a setting that
    changes no measurement (the plots' time window) leaves the row collecting."""
    from qrfield.sessions.criteria import MAX_FRAMES_PER_ROW

    window = make_window({"source": "virtual", "method": "both", "side_mm": 50.0})
    panel = window.session_panel
    panel.row_settings.widgets["frames_per_row"].setValue(MAX_FRAMES_PER_ROW)  # never done in the test
    panel.name_edit.setText("mid-row")
    session = panel.create_from_form()
    assert session is not None and session.info.frames_per_row == MAX_FRAMES_PER_ROW
    qtbot.waitUntil(lambda: panel.form.follow_box.isEnabled() and not panel.blocked_reason(), timeout=WAIT_MS)
    qtbot.mouseClick(panel.log_button, QtCore.Qt.MouseButton.LeftButton)
    assert panel.collecting
    if change == "side":
        window.camera_controls.side_mm.setValue(60.0)  # as the operator types it in Setup › Camera
    elif change == "method":
        window.set_method("ippe")
    elif change == "source":
        window.set_source("virtual")  # Open again in Setup › Source
    else:
        window.camera_controls.plot_window_s.setValue(30.0)
        assert panel.collecting and panel.status.text().startswith("collecting")
        panel.cancel_row()
        return
    assert not panel.collecting
    assert "not logged" in panel.status.text() and "changed while collecting" in panel.status.text()
    assert panel.session.next_row == 1 and not panel.session.rows
    _header, rows = rows_csv(panel.session.path)
    assert rows == []


@pytest.mark.slow
@pytest.mark.parametrize("model", ["wrong distortion", "right"])
def test_a_row_of_misfit_frames_says_so_when_logged(make_window, qtbot, sessions, tmp_path, model) -> None:
    """(audit-ui) Photos of the card rendered with picam-v2@640x480 (no distortion), measured
    with a model of strong barrel distortion: every frame's fit misfits its corners
    (PoseResult.misfit; chi2 in the thousands, checked with `qrfield solve --json`), which the
    pose panel's status line says, but a row of them was logged as a plain "pass" or "fail".
    The row's message now says how many of its frames misfit; with the right model it does not."""
    import json

    import cv2

    from qrfield.camera import resolve_camera
    from qrfield.geometry import Pose
    from qrfield.render import render_view
    from qrfield.runconfig import ConfigStore, RunSettings

    camera = "picam-v2@640x480"
    folder = tmp_path / "photos"
    folder.mkdir()
    pose = Pose([-20.0, 15.0, 350.0], [15.0, -20.0, 10.0])
    for i in range(3):
        image = render_view(resolve_camera(camera), 50.0, pose, noise_sigma=2.0, seed=i).image
        cv2.imwrite(str(folder / f"img{i}.png"), image)
    if model != "right":
        spec = json.loads((Path(__file__).parents[2] / "calib" / "picam-v2.json").read_text())
        spec.update(name="picam-v2-barrel", dist=[-0.6, 0.4, 0.0, 0.0, 0.0])
        (tmp_path / "barrel.json").write_text(json.dumps(spec))
        camera = f"{tmp_path / 'barrel.json'}@640x480"
    store = ConfigStore(tmp_path / "config")  # the folder plays in a loop (the window's own store)
    run = RunSettings(source=str(folder), camera=camera, side_mm=50.0, method="numerical", loop=True)
    store.set_group("run", run)
    store.save()
    window = make_window()
    panel = window.session_panel
    panel.row_settings.widgets["frames_per_row"].setValue(FRAMES)
    panel.name_edit.setText("misfit")
    assert panel.create_from_form() is not None
    truth = {"x": "-20", "y": "15", "z": "350", "alpha": "15", "beta": "-20", "gamma": "10"}
    panel.form.set_fields({**truth, "combo": "alpha+beta-gamma+"})
    qtbot.waitUntil(lambda: not panel.blocked_reason(), timeout=WAIT_MS)
    qtbot.waitUntil(panel.log_button.isEnabled, timeout=WAIT_MS)
    with qtbot.waitSignal(panel.rowLogged, timeout=WAIT_MS):
        qtbot.mouseClick(panel.log_button, LEFT)
    status = panel.status.text()
    assert status.startswith("logged row 1")
    if model == "right":
        assert "misfit" not in status and status == "logged row 1: pass"
    else:
        assert f"{FRAMES} of its {FRAMES} frames misfit" in status
