"""The app's serial panel, offscreen with pytest-qt, driven by clicks and typing: the virtual bench's
true pose arrives over a pty pair (read at the other end here) and over loop://, checked with
tests/serial_truth.py (a parser that shares no code with the link); Disconnect stops the frames; a
pty that vanishes shows "disconnected" while the app keeps measuring; settings persist; a screenshot."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets
from serial_truth import command_line, frames_and_answers, parse_frame_line, split_lines

from qrfield.geometry import Pose, angle_difference
from qrfield.runconfig import ConfigStore
from qrfield.serial.link import CLOSED, CONNECTED, DISCONNECTED, SerialLinkSettings
from ui.main_window import MainWindow
from ui.serial_panel import STATE_COLOURS, SerialPanel

pytestmark = pytest.mark.gui
WAIT_MS = 15000


class Pty:
    """A pty pair; the link opens ``path`` (a symlink to the slave), the test reads the master."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.master, self.slave = os.openpty()
        os.set_blocking(self.master, False)
        self.tty = os.ttyname(self.slave)
        tmp = path.with_suffix(".new")
        os.symlink(self.tty, tmp)
        os.replace(tmp, path)
        self.data = bytearray()

    def drain(self) -> bytes:
        """Everything written to the slave so far (non-blocking)."""
        while self.master >= 0:
            try:
                chunk = os.read(self.master, 65536)
            except (BlockingIOError, OSError):
                break
            if not chunk:
                break
            self.data += chunk
        return bytes(self.data)

    def frames(self) -> list[dict]:
        """The $QRF frames so far (answers to commands left out)."""
        return frames_and_answers(self.drain())[0]

    def vanish(self) -> None:
        """The USB adapter is pulled: both ends closed and its device path gone.

        The path must go too: the kernel soon hands the freed /dev/pts/N number to the next pty
        opened on the machine (another test, another program), and a link reconnecting through a
        stale symlink would then "connect" to that stranger's terminal.
        """
        for fd in (self.master, self.slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        # Once only: a second close of these numbers would close whatever file reused them since
        # (the next pty's ends, the link's port, a Qt event fd).
        self.master = self.slave = -1
        with contextlib.suppress(OSError):
            if os.readlink(self.path) == self.tty:  # not a newer Pty's link at the same path
                os.unlink(self.path)


def meets_seed_criteria(values: list[float], truth: Pose) -> bool:
    """x, y, z (mm) within 5 mm and alpha, beta, gamma within 2 degrees of the truth."""
    v = np.asarray(values, dtype=float)
    position_ok = np.linalg.norm(v[:3] - truth.position_mm) < 5.0
    return bool(position_ok and np.all(np.abs(angle_difference(v[3:], truth.angles_deg)) <= 2.0))


def type_port(qtbot, panel: SerialPanel, port: str) -> None:
    edit = panel.port.lineEdit()
    edit.selectAll()
    qtbot.keyClick(edit, QtCore.Qt.Key.Key_Delete)
    qtbot.keyClicks(edit, port)


def click(qtbot, button) -> None:
    qtbot.mouseClick(button, QtCore.Qt.MouseButton.LeftButton)


def test_bench_pose_streams_over_a_pty_and_disconnect_stops_it(make_window, qtbot, tmp_path: Path) -> None:
    window = make_window({"source": "virtual", "method": "both"})
    panel = window.serial_panel
    window.tabs.setCurrentIndex(window.tabs.count() - 1)
    truth = window.virtual_form.value().pose
    pty = Pty(tmp_path / "ttyQRF")
    try:
        type_port(qtbot, panel, str(pty.path))
        click(qtbot, panel.connect_button)
        assert panel.connect_button.text() == "Disconnect" and not panel.port.isEnabled()
        qtbot.waitUntil(lambda: panel.shown_state() == CONNECTED, timeout=WAIT_MS)
        # The virtual bench's poses are made up: SIM, never OK (docs/conventions.md).
        qtbot.waitUntil(lambda: sum(f["status"] == "SIM" for f in pty.frames()) >= 8, timeout=WAIT_MS)
        frames = pty.frames()
        ok = [f for f in frames if f["status"] == "SIM"]
        assert all(meets_seed_criteria(f["pose"], truth) for f in ok), ok[:3]
        seqs = [f["seq"] for f in frames]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # in order, none lost on the wire
        assert all(f["status"] in ("SIM", "NOQR", "NOCONV", "STALE", "NOSRC") for f in frames)
        # The counters shown are the link's, and the last line shown is one that went out.
        qtbot.waitUntil(
            lambda: int(panel.counter_labels["frames_sent"].text()) >= len(frames), timeout=WAIT_MS
        )
        qtbot.waitUntil(
            lambda: (
                panel.last_sent.text() != "" and (panel.last_sent.text() + "\r\n") in pty.drain().decode()
            ),
            timeout=WAIT_MS,
        )
        assert panel.state_label.text().startswith("connected")
        assert STATE_COLOURS[CONNECTED] in panel.state_label.styleSheet()

        click(qtbot, panel.connect_button)  # Disconnect
        assert panel.connect_button.text() == "Connect" and panel.port.isEnabled()
        assert panel.shown_state() == CLOSED and STATE_COLOURS[CLOSED] in panel.state_label.styleSheet()
        panel.join_closers()
        assert panel.status().state == CLOSED
        count = len(split_lines(pty.drain()))
        processed = window.worker.frames_processed
        qtbot.waitUntil(lambda: window.worker.frames_processed >= processed + 10, timeout=WAIT_MS)
        assert len(split_lines(pty.drain())) == count, "frames kept coming after Disconnect"
    finally:
        pty.vanish()


def test_vanished_port_shows_disconnected_app_goes_on_and_resumes(make_window, qtbot, tmp_path: Path) -> None:
    window = make_window({"source": "virtual", "method": "numerical"})
    panel = window.serial_panel
    path = tmp_path / "ttyQRF"
    first = Pty(path)
    second = None
    try:
        type_port(qtbot, panel, str(path))
        reconnect = panel.fields["reconnect_interval_s"]
        reconnect.lineEdit().selectAll()
        qtbot.keyClicks(reconnect.lineEdit(), "0.05")
        qtbot.keyClick(reconnect.lineEdit(), QtCore.Qt.Key.Key_Return)
        assert panel.settings().reconnect_interval_s == pytest.approx(0.05)
        click(qtbot, panel.connect_button)
        qtbot.waitUntil(lambda: len(first.frames()) >= 3, timeout=WAIT_MS)
        first.vanish()  # unplugged mid-stream
        qtbot.waitUntil(lambda: panel.shown_state() == DISCONNECTED, timeout=WAIT_MS)
        assert STATE_COLOURS[DISCONNECTED] in panel.state_label.styleSheet()
        assert "ttyQRF" in panel.last_error.text() and int(panel.counter_labels["errors"].text()) >= 1
        # The app keeps measuring and drawing meanwhile.
        processed, shown = window.worker.frames_processed, window.frames_shown
        qtbot.waitUntil(
            lambda: window.worker.frames_processed > processed + 5 and window.frames_shown > shown,
            timeout=WAIT_MS,
        )
        assert panel.shown_state() == DISCONNECTED
        second = Pty(path)  # plugged in again (another pty behind the same path)
        qtbot.waitUntil(lambda: panel.shown_state() == CONNECTED, timeout=WAIT_MS)
        qtbot.waitUntil(lambda: any(f["status"] == "SIM" for f in second.frames()), timeout=WAIT_MS)
        assert panel.counter_labels["reconnects"].text() == "1"
    finally:
        first.vanish()
        if second is not None:
            second.vanish()


def test_the_controllers_commands_are_answered_in_the_serial_tab(make_window, qtbot, tmp_path: Path) -> None:
    window = make_window({"source": "virtual", "method": "numerical"})
    panel = window.serial_panel
    truth = window.virtual_form.value().pose
    pty = Pty(tmp_path / "ttyQRF")
    try:
        type_port(qtbot, panel, str(pty.path))
        click(qtbot, panel.connect_button)
        qtbot.waitUntil(lambda: len(pty.frames()) >= 3, timeout=WAIT_MS)
        os.write(pty.master, command_line("PING") + command_line("MEAS", "5"))
        qtbot.waitUntil(lambda: len(frames_and_answers(pty.drain())[1]) >= 2, timeout=WAIT_MS)
        ping, meas = frames_and_answers(pty.drain())[1][:2]
        assert (ping["command"], ping["result"]) == ("PING", "OK")
        assert meas["type"] == "QRM" and meas["status"] == "SIM" and meas["n_used"] == 5
        assert meets_seed_criteria(meas["pose"], truth)
        qtbot.waitUntil(lambda: panel.counter_labels["answers_sent"].text() == "2", timeout=WAIT_MS)
        # The tab shows the last command with its answer, the line rate and the lag.
        qtbot.waitUntil(lambda: panel.last_command.text().startswith("MEAS,5 -> QRM,"), timeout=WAIT_MS)
        assert panel.line_rate.text().endswith("lines/s (limit 30/s)") and panel.lag.text().endswith(" ms")
        # The source goes away: the controller hears NOSRC, not silence.
        window.set_source(str(tmp_path / "missing.avi"))
        qtbot.waitUntil(lambda: any(f["status"] == "NOSRC" for f in pty.frames()), timeout=WAIT_MS)
    finally:
        pty.vanish()


def test_bad_path_shows_disconnected(make_window, qtbot) -> None:
    window = make_window({"source": "virtual", "method": "numerical"})
    panel = window.serial_panel
    type_port(qtbot, panel, "/nonexistent/ttyQRF0")
    click(qtbot, panel.connect_button)
    qtbot.waitUntil(lambda: panel.shown_state() == DISCONNECTED, timeout=WAIT_MS)
    assert "cannot open /nonexistent/ttyQRF0" in panel.last_error.text()
    processed = window.worker.frames_processed
    qtbot.waitUntil(lambda: window.worker.frames_processed > processed + 3, timeout=WAIT_MS)


def test_loop_port_carries_the_bench_pose(make_window, qtbot) -> None:
    window = make_window({"source": "virtual", "method": "numerical"})
    panel = window.serial_panel
    truth = window.virtual_form.value().pose
    type_port(qtbot, panel, "loop://")
    click(qtbot, panel.connect_button)
    qtbot.waitUntil(lambda: panel.shown_state() == CONNECTED, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: ",SIM*" in panel.last_sent.text(), timeout=WAIT_MS)
    frame = parse_frame_line(panel.last_sent.text().encode() + b"\r\n")
    assert frame["status"] == "SIM" and meets_seed_criteria(frame["pose"], truth)
    # loop:// sends every byte back: the link decoded its own frames with good checksums.
    qtbot.waitUntil(lambda: panel.status().received.get("frames", 0) >= 3, timeout=WAIT_MS)
    assert panel.status().received["bad_checksum"] == 0


def test_settings_persist_with_the_app_config(qtbot, tmp_path: Path) -> None:
    store_dir = tmp_path / "config"
    window = MainWindow(ConfigStore(store_dir), {"source": "virtual"})
    qtbot.addWidget(window)
    panel = window.serial_panel
    type_port(qtbot, panel, "/dev/ttyACM7")
    baud = panel.fields["baud"]
    baud.lineEdit().selectAll()
    qtbot.keyClicks(baud.lineEdit(), "9600")
    qtbot.keyClick(baud.lineEdit(), QtCore.Qt.Key.Key_Return)
    panel.fields["max_rate_hz"].setValue(12.5)
    window.shutdown()
    again = MainWindow(ConfigStore(store_dir), {"source": "virtual"})
    qtbot.addWidget(again)
    try:
        assert again.serial_panel.settings() == SerialLinkSettings(
            port="/dev/ttyACM7", baud=9600, max_rate_hz=12.5
        )
        assert again.serial_panel.shown_state() == CLOSED  # never reconnects unasked
    finally:
        again.shutdown()


def test_panel_screenshot(make_window, qtbot, tmp_path: Path) -> None:
    window = make_window({"source": "virtual", "method": "numerical"})
    panel = window.serial_panel
    window.tabs.setCurrentIndex(window.tabs.count() - 1)
    type_port(qtbot, panel, "loop://")
    click(qtbot, panel.connect_button)
    qtbot.waitUntil(lambda: int(panel.counter_labels["frames_sent"].text()) >= 3, timeout=WAIT_MS)
    path = tmp_path / "serial_panel.png"
    assert panel.grab().save(str(path))
    assert path.stat().st_size > 2000
    out = os.environ.get("QRFIELD_SCREENSHOT_DIR")
    if out:
        window.grab().save(str(Path(out) / "serial_window.png"))
        panel.grab().save(str(Path(out) / "serial_panel.png"))


def choose(qtbot, panel: SerialPanel, name: str, value: str) -> None:
    """Pick ``value`` in the hand-eye form's chooser ``name`` (as a click on the list would)."""
    box = panel.handeye_form.widgets[name]
    box.setCurrentIndex(box.findText(value))
    assert box.currentText() == value


def test_the_serial_tab_records_pairs_and_shows_the_calibration_made_over_the_link(
    make_window, qtbot, tmp_path: Path
) -> None:
    # The controller moves a simulated robot (the app's virtual bench follows it), sends TOOL at
    # each pose and then HANDEYE: the tab lists the pairs and shows the result; the transform found
    # is the robot's, composed by hand here.
    import json

    from qrfield.handeye import SimulatedRobot
    from qrfield.handeye.rigid import difference, transform_from_pose
    from qrfield.serial.robot_demo import tool_arguments

    window = make_window({"source": "virtual", "method": "numerical"})
    panel = window.serial_panel
    assert "stay in the camera frame" in panel.findChild(QtWidgets.QLabel, "frame_note").text()
    choose(qtbot, panel, "handeye_setup", "eye-in-hand")
    robot = SimulatedRobot(
        "eye-in-hand",
        transform_from_pose([60.0, -15.0, 40.0], [2.0, -3.0, 90.0]),
        transform_from_pose([450.0, 30.0, 0.0], [180.0, 0.0, 0.0]),
    )
    camera = window._run_config().camera  # the model the bench renders with
    tools = robot.viewing_tool_poses(camera, 50.0, 7, seed=2)
    pty = Pty(tmp_path / "ttyQRF")
    try:
        type_port(qtbot, panel, str(pty.path))
        click(qtbot, panel.connect_button)
        assert not panel.handeye_form.isEnabled()  # applied at Connect, like the link's settings
        qtbot.waitUntil(lambda: len(pty.frames()) >= 3, timeout=WAIT_MS)
        for k, tool in enumerate(tools):
            window.virtual_form.set_value(window.virtual_form.value().with_pose(robot.code_pose(tool)))
            pose = window.virtual_form.value().pose  # as the form's widgets round it (0.1 mm, 0.01 deg)
            window.virtual_form.changed.emit(window.virtual_form.value())
            qtbot.waitUntil(  # the bench shows the robot's new pose
                lambda p=pose: (
                    window.last is not None
                    and window.last.result.truth is not None
                    and np.allclose(window.last.result.truth.position_mm, p.position_mm)
                ),
                timeout=WAIT_MS,
            )
            os.write(pty.master, command_line("TOOL", *tool_arguments(tool)))
            qtbot.waitUntil(lambda n=k + 1: len(frames_and_answers(pty.drain())[1]) >= n, timeout=WAIT_MS)
        answers = frames_and_answers(pty.drain())[1]
        ok = [a for a in answers if a["result"] == "OK"]
        assert len(ok) >= 5 and all(a["values"][-1] == "SIM" for a in ok), answers
        qtbot.waitUntil(lambda: panel.pairs_list.count() == len(ok), timeout=WAIT_MS)
        assert panel.pairs_label.text().startswith(f"pairs recorded: {len(ok)} from a simulated source")
        os.write(pty.master, command_line("HANDEYE"))
        qtbot.waitUntil(lambda: len(frames_and_answers(pty.drain())[1]) > len(tools), timeout=WAIT_MS)
        handeye = frames_and_answers(pty.drain())[1][-1]
        assert (handeye["command"], handeye["result"]) == ("HANDEYE", "OK"), handeye
        saved_path = tmp_path / "config" / "handeye-simulated.json"  # beside the app's settings
        qtbot.waitUntil(lambda: "last calibration" in panel.handeye_result.text(), timeout=WAIT_MS)
        text = panel.handeye_result.text()
        assert f"eye-in-hand from simulated frames from {len(ok)} pairs" in text
        assert f"residuals {handeye['values'][0]} mm, {handeye['values'][1]} deg" in text
        assert str(saved_path) in text and panel.pairs_list.count() == 0  # a new set begins
        saved = json.loads(saved_path.read_text())
        err = difference(np.array(saved["camera_to_tool"]), robot.transform)
        assert np.linalg.norm(err[:3]) < 2.0 and np.degrees(np.linalg.norm(err[3:])) < 0.3
        # Clear pairs: the next TOOL starts again at 1.
        os.write(pty.master, command_line("TOOL", *tool_arguments(tools[-1])))
        qtbot.waitUntil(lambda: panel.pairs_list.count() == 1, timeout=WAIT_MS)
        click(qtbot, panel.clear_pairs_button)
        assert panel.pairs_list.count() == 0 and panel.pairs_label.text().startswith("pairs recorded: 0")
    finally:
        pty.vanish()


def test_the_link_reports_poses_in_the_tool_frame_chosen_in_the_serial_tab(
    make_window, qtbot, tmp_path: Path
) -> None:
    from qrfield.geometry import angles_from_rotation, rotation_matrix
    from qrfield.handeye import HandEyeCalibration
    from qrfield.handeye.rigid import transform_from_pose

    x = transform_from_pose([60.0, -15.0, 40.0], [2.0, -3.0, 90.0])
    (tmp_path / "config").mkdir(exist_ok=True)
    HandEyeCalibration("eye-in-hand", x, 0.1, 0.02, 15, "test").save(tmp_path / "config" / "handeye.json")
    window = make_window({"source": "virtual", "method": "numerical"})
    panel = window.serial_panel
    truth = window.virtual_form.value().pose
    choose(qtbot, panel, "frame", "tool")
    pty = Pty(tmp_path / "ttyQRF")
    try:
        type_port(qtbot, panel, str(pty.path))
        click(qtbot, panel.connect_button)
        assert "poses in the tool frame through the eye-in-hand calibration" in panel.note.text()
        qtbot.waitUntil(lambda: sum(f["status"] == "SIM" for f in pty.frames()) >= 3, timeout=WAIT_MS)
        os.write(pty.master, command_line("HELLO"))
        qtbot.waitUntil(lambda: len(frames_and_answers(pty.drain())[1]) >= 1, timeout=WAIT_MS)
        frames, answers = frames_and_answers(pty.drain())
        assert answers[0]["values"][-1] == "tool"
        p = x[:3, :3] @ truth.position_mm + x[:3, 3]  # by hand: the bench's pose through X
        a = angles_from_rotation(x[:3, :3] @ rotation_matrix(truth.angles_deg))
        sim = [f for f in frames if f["status"] == "SIM"]
        assert all(meets_seed_criteria(f["pose"], Pose(p, a)) for f in sim), sim[:2]
        # The app itself stays in the camera frame.
        assert np.allclose(window.last.result.truth.position_mm, truth.position_mm)
    finally:
        pty.vanish()
    click(qtbot, panel.connect_button)  # Disconnect: the form is editable again
    assert panel.handeye_form.isEnabled()


def test_the_hand_eye_settings_persist_and_a_bad_file_refuses_the_connect(qtbot, tmp_path: Path) -> None:
    store_dir = tmp_path / "config"
    window = MainWindow(ConfigStore(store_dir), {"source": "virtual"})
    qtbot.addWidget(window)
    panel = window.serial_panel
    choose(qtbot, panel, "frame", "base")
    type_port(qtbot, panel, "loop://")
    click(qtbot, panel.connect_button)  # no hand-eye file in the config folder
    assert (
        not panel.connected and "cannot connect" in panel.note.text() and "handeye.json" in panel.note.text()
    )
    window.shutdown()
    again = MainWindow(ConfigStore(store_dir), {"source": "virtual"})
    qtbot.addWidget(again)
    try:
        assert again.serial_panel.handeye_settings().frame == "base"
    finally:
        again.shutdown()
