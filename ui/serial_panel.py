"""The serial panel: stream each measured pose to the gripper controller as $QRF lines and answer its
$QRC commands (PING, HELLO, STREAM, RATE, MEAS, TOOL, HANDEYE) on the same port (protocol 2,
docs/serial.md).

The panel owns at most one :class:`~qrfield.serial.controller.GripperLink` (the link's own thread
opens, writes, reads and reconnects the port, and answers the commands). The frame loop hands every
result to :class:`LinkPublisher` on the worker thread (OK for an unambiguous pose from a live camera,
AMBIG for an ambiguous one, else SIM; NOSRC while the source is down); publishing returns at once
(the link keeps only the newest pose), so neither the worker nor the GUI ever waits for the port.
The panel shows the link's line rate, its lag (the last pose's age when its last byte left) and the
controller's last command with its answer. The GUI reads ``link.status()`` on its redraw timer
(:meth:`SerialPanel.refresh`): nothing from the link's thread touches a widget. Disconnecting closes
the link as a :class:`ui.background.BackgroundJob`, since ``close`` joins the link's thread (up to a
write timeout).

The hand-eye box holds the ``handeye`` settings (the frame of the link's poses, the hand-eye file,
the set-up HANDEYE solves for; applied at Connect like the link's) and shows the pairs the
controller's ``$QRC,TOOL`` commands recorded and the last ``$QRC,HANDEYE`` result (residuals,
pairs, where it was saved), read from :meth:`qrfield.serial.handeye.HandEyeCommands.status` on the
redraw timer. The frame applies to the serial link only: the app's pose panel, plots and sessions
stay in the camera frame (docs/app.md).
"""

from __future__ import annotations

import dataclasses
import math
import threading
from typing import Any

from PySide6 import QtCore, QtWidgets

from qrfield.handeye import HandEyeError, HandEyeSettings, PoseFrame
from qrfield.serial.controller import GripperLink
from qrfield.serial.handeye import HandEyeCommands, HandEyeStatus
from qrfield.serial.link import CLOSED, CONNECTED, LinkStatus, SerialLinkSettings
from qrfield.serial.port import LOOP_URL, list_ports
from qrfield.settings import SettingError, specs, validated
from ui.background import BackgroundJob
from ui.settings_form import SettingsForm, set_widget_value, widget_for, widget_value

#: Colour of the state label: connected green, trying amber, closed grey.
STATE_COLOURS = {CONNECTED: "#1e8c1e", "connecting": "#c78400", "disconnected": "#c78400", CLOSED: "#808080"}
#: The link's counters shown (LinkStatus field, label).
COUNTERS = (
    ("frames_sent", "frames sent"),
    ("answers_sent", "answers to commands"),
    ("frames_dropped", "superseded / dropped"),
    ("errors", "errors"),
    ("reconnects", "reconnects"),
)


class LinkPublisher:
    """Thread-safe holder of the current link: the frame loop's sink (any thread).

    ``on_result`` returns True when the result was handed to an open link, False when no link is
    connected. The source's state is kept, so a link connected while the source is down starts
    with NOSRC.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._link: GripperLink | None = None
        self._down = False
        self.published = 0

    def set_link(self, link: GripperLink | None) -> None:
        with self._lock:
            self._link = link
            down = self._down
        if link is not None and down:
            link.on_source_down("no source")

    def on_result(self, result: Any, simulated: bool) -> bool:
        with self._lock:
            link = self._link
        if link is None:
            return False
        ok = link.on_result(result, simulated)
        if ok:
            self.published += 1
        return ok

    def on_source_down(self, reason: str = "") -> None:
        with self._lock:
            self._down = True
            link = self._link
        if link is not None:
            link.on_source_down(reason)

    def on_source_up(self) -> None:
        with self._lock:
            self._down = False
            link = self._link
        if link is not None:
            link.on_source_up()


class SerialPanel(QtWidgets.QWidget):
    """Port chooser, link settings, Connect/Disconnect and live counters of the serial link; the
    hand-eye settings, pairs and result.

    ``opener`` is passed to :class:`SerialLink` (tests may pass a fake port factory);
    ``handeye``: the saved :class:`~qrfield.handeye.HandEyeSettings`; ``config_dir``: the folder
    of the app's settings (the default hand-eye file's folder).
    """

    def __init__(
        self,
        settings: SerialLinkSettings | None = None,
        *,
        handeye: HandEyeSettings | None = None,
        config_dir: Any = None,
        opener: Any = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self._opener = opener
        self._config_dir = config_dir
        self._context: tuple[float, str] | None = None  # (side_mm, camera model) for HELLO
        self._live_source = False  # the app measures from a live camera (a simulated file is refused)
        self._handeye_shown: HandEyeStatus | None = None
        self.link: GripperLink | None = None
        self.publisher = LinkPublisher()
        self._closers: list[BackgroundJob] = []  # one job per link being closed
        self._shown: tuple[str, LinkStatus] | None = None
        self._specs = {s.name: s for s in specs(SerialLinkSettings)}
        settings = validated(settings or SerialLinkSettings())
        outer = QtWidgets.QVBoxLayout(self)
        outer.addLayout(self._build_settings_form())
        outer.addWidget(self._build_link_box())
        outer.addWidget(self._build_handeye_box(handeye))
        self.note = QtWidgets.QLabel("")
        self.note.setWordWrap(True)
        outer.addWidget(self.note)
        outer.addStretch(1)
        self.refresh_ports()
        self.set_settings(settings)
        self._show_state(CLOSED, "")
        self.refresh_button.clicked.connect(self.refresh_ports)
        self.connect_button.clicked.connect(self.toggle)
        self.clear_pairs_button.clicked.connect(self.clear_pairs)

    # ---------------------------------------------------------------- builders
    def _build_settings_form(self) -> QtWidgets.QFormLayout:
        """The port (chooser and Refresh), one widget per other link setting, and Connect."""
        form = QtWidgets.QFormLayout()
        self.port = QtWidgets.QComboBox()
        self.port.setEditable(True)
        self.port.setObjectName("port")
        self.port.setToolTip(self._specs["port"].describe())
        self.port.setInsertPolicy(QtWidgets.QComboBox.InsertPolicy.NoInsert)
        self.refresh_button = QtWidgets.QPushButton("Refresh")
        self.refresh_button.setObjectName("refresh_ports")
        self.refresh_button.setToolTip("list the machine's serial ports again (an adapter plugged in)")
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.port, 1)
        row.addWidget(self.refresh_button)
        form.addRow(self._specs["port"].label, row)
        self.fields: dict[str, QtWidgets.QWidget] = {}
        for name, spec in self._specs.items():
            if name != "port":
                self.fields[name] = widget_for(spec)
                form.addRow(spec.label, self.fields[name])
        self.connect_button = QtWidgets.QPushButton("Connect")
        self.connect_button.setObjectName("connect")
        form.addRow(self.connect_button)
        return form

    def _build_link_box(self) -> QtWidgets.QGroupBox:
        """The link's state, its counters, the last error and the last line sent."""
        box = QtWidgets.QGroupBox("link")
        grid = QtWidgets.QFormLayout(box)
        self.state_label = QtWidgets.QLabel()
        self.state_label.setObjectName("state")
        grid.addRow("state", self.state_label)
        self.counter_labels: dict[str, QtWidgets.QLabel] = {}
        for key, text in COUNTERS:
            label = QtWidgets.QLabel("0")
            label.setObjectName(key)
            self.counter_labels[key] = label
            grid.addRow(text, label)
        self.last_error = QtWidgets.QLabel("")
        self.last_error.setObjectName("last_error")
        self.last_error.setWordWrap(True)
        grid.addRow("last error", self.last_error)
        self.last_sent = QtWidgets.QLineEdit("")
        self.last_sent.setObjectName("last_sent")
        self.last_sent.setReadOnly(True)
        self.last_sent.setToolTip("the last $QRF line written to the port (without CR LF)")
        grid.addRow("last line sent", self.last_sent)
        self.line_rate = QtWidgets.QLabel("")
        self.line_rate.setObjectName("line_rate")
        self.line_rate.setToolTip("$QRF lines written per second (paced to the baud rate and the rate limit)")
        grid.addRow("line rate", self.line_rate)
        self.lag = QtWidgets.QLabel("")
        self.lag.setObjectName("lag")
        self.lag.setToolTip(
            "the last pose's age when its last byte left: its age_ms plus the line's time on the wire"
        )
        grid.addRow("lag", self.lag)
        self.last_command = QtWidgets.QLineEdit("")
        self.last_command.setObjectName("last_command")
        self.last_command.setReadOnly(True)
        self.last_command.setToolTip("the controller's last command and the answer it got")
        grid.addRow("last command", self.last_command)
        return box

    def _build_handeye_box(self, settings: HandEyeSettings | None) -> QtWidgets.QGroupBox:
        """The hand-eye settings, the pairs recorded over the link and the last calibration."""
        box = QtWidgets.QGroupBox("hand-eye over the link ($QRC,TOOL and $QRC,HANDEYE)")
        layout = QtWidgets.QVBoxLayout(box)
        self.handeye_form = SettingsForm(HandEyeSettings, settings or HandEyeSettings())
        self.handeye_form.setObjectName("handeye_settings")
        layout.addWidget(self.handeye_form)
        frame_note = QtWidgets.QLabel(
            "The pose frame applies to this serial link ($QRF, $QRM, HELLO) and to qrfield run: the app's "
            "pose panel, plots and sessions stay in the camera frame."
        )
        frame_note.setObjectName("frame_note")
        frame_note.setWordWrap(True)
        layout.addWidget(frame_note)
        self.pairs_label = QtWidgets.QLabel("pairs recorded: 0")
        self.pairs_label.setObjectName("handeye_pairs_count")
        layout.addWidget(self.pairs_label)
        self.pairs_list = QtWidgets.QListWidget()
        self.pairs_list.setObjectName("handeye_pairs")
        self.pairs_list.setToolTip(
            "each pair: the tool's position in the base frame (from $QRC,TOOL) and the code's position in "
            "the camera frame (the frame measured after it), mm"
        )
        self.pairs_list.setMinimumHeight(60)
        self.pairs_list.setMaximumHeight(120)
        layout.addWidget(self.pairs_list)
        self.handeye_result = QtWidgets.QLabel("no calibration made over the link yet")
        self.handeye_result.setObjectName("handeye_result")
        self.handeye_result.setWordWrap(True)
        self.handeye_result.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        layout.addWidget(self.handeye_result)
        self.clear_pairs_button = QtWidgets.QPushButton("Clear pairs")
        self.clear_pairs_button.setObjectName("clear_pairs")
        self.clear_pairs_button.setToolTip(
            "forget the pairs recorded so far: the next $QRC,TOOL starts a new set"
        )
        layout.addWidget(self.clear_pairs_button)
        return box

    # ---------------------------------------------------------------- settings
    def refresh_ports(self) -> None:
        """Offer pyserial's ports and loop:// again (keeps what is typed in the box)."""
        current = self.port.currentText()
        blocker = QtCore.QSignalBlocker(self.port)
        self.port.clear()
        for info in list_ports():
            if info.device:
                self.port.addItem(info.device)
                self.port.setItemData(
                    self.port.count() - 1, info.description, QtCore.Qt.ItemDataRole.ToolTipRole
                )
        self.port.setCurrentText(current or LOOP_URL)
        del blocker

    def set_settings(self, settings: SerialLinkSettings) -> None:
        """Show ``settings`` (used at the next Connect)."""
        settings = validated(settings)
        self.port.setCurrentText(settings.port)
        for name, widget in self.fields.items():
            set_widget_value(widget, self._specs[name], getattr(settings, name))

    def settings(self) -> SerialLinkSettings:
        """The settings the widgets show; SettingError (ValueError) names a bad field."""
        values = {name: widget_value(widget) for name, widget in self.fields.items()}
        return validated(SerialLinkSettings(port=self.port.currentText().strip(), **values))

    def saved_settings(self) -> SerialLinkSettings:
        """The settings to persist: those shown, or for a bad field the defaults for that field."""
        try:
            return self.settings()
        except (SettingError, ValueError):
            base = SerialLinkSettings()
            port = self.port.currentText().strip() or base.port
            return dataclasses.replace(base, port=port)

    def handeye_settings(self) -> HandEyeSettings:
        """The hand-eye settings shown (to persist; used at the next Connect)."""
        return self.handeye_form.value()

    def set_context(self, side_mm: float, camera: str, source: str = "") -> None:
        """The QR side (mm) and camera model the measurements use: what HELLO reports; ``source``:
        the app's source (a live camera's poses never go through a simulated calibration)."""
        from qrfield.sources import may_be_live_camera

        self._context = (float(side_mm), str(camera))
        self._live_source = bool(source) and may_be_live_camera(source)
        if self.link is not None:
            self.link.set_context(side_mm=self._context[0], camera=self._context[1])

    # ---------------------------------------------------------------- connect / disconnect
    @property
    def connected(self) -> bool:
        """True while a link exists (whatever its port's state)."""
        return self.link is not None

    def toggle(self) -> None:
        if self.link is None:
            self.connect_link()
        else:
            self.disconnect_link()

    def connect_link(self) -> bool:
        """Start a link with the shown settings; the port is opened on the link's thread."""
        if self.link is not None:
            return True
        try:
            settings = self.settings()
            if not settings.port:
                raise ValueError("no port given: choose one or type a device path or loop://")
            handeye_settings = self.handeye_settings()
            pose_frame = PoseFrame.from_settings(handeye_settings, self._config_dir)
            pose_frame.check_source(self._live_source)
            info: dict[str, Any] = {}
            if self._context is not None:
                info = {"side_mm": self._context[0], "camera": self._context[1]}
            handeye = HandEyeCommands.from_settings(handeye_settings, self._config_dir, info=info)
            link = GripperLink(settings, opener=self._opener, pose_frame=pose_frame)
        except (ValueError, HandEyeError) as exc:
            self.note.setText(f"⚠ cannot connect: {exc}")
            return False
        link.add_handeye(handeye)
        self.note.setText("" if pose_frame.identity else f"serial link: {pose_frame.describe()}")
        if self._context is not None:
            link.set_context(side_mm=self._context[0], camera=self._context[1])
        self.link = link.start()
        self.publisher.set_link(self.link)
        self._set_editable(False)
        self.connect_button.setText("Disconnect")
        self.refresh()
        return True

    def disconnect_link(self, wait: bool = False) -> None:
        """Stop sending; the link is closed on a plain thread (``wait``: join it, e.g. at exit)."""
        link, self.link = self.link, None
        self.publisher.set_link(None)
        self._set_editable(True)
        self.connect_button.setText("Connect")
        if link is None:
            return
        closer = BackgroundJob("serial-link close")  # no signal wanted: kept only while it runs
        closer.start(link.close)
        self._closers = [job for job in self._closers if job.busy] + [closer]
        self._last_link = link
        if wait:
            self.join_closers()
        self.refresh()

    def join_closers(self, timeout: float = 3.0) -> None:
        for job in self._closers:
            job.join(timeout)
        self._closers = []

    def shutdown(self) -> None:
        """Close the link and wait for it (the app is quitting)."""
        self.disconnect_link(wait=True)

    def _set_editable(self, editable: bool) -> None:
        self.port.setEnabled(editable)
        self.refresh_button.setEnabled(editable)
        for widget in self.fields.values():
            widget.setEnabled(editable)
        self.handeye_form.setEnabled(editable)

    def clear_pairs(self) -> None:
        """Forget the pairs recorded over the current link."""
        if self.link is not None and self.link.handeye is not None:
            self.link.handeye.clear()
            self.refresh()

    # ---------------------------------------------------------------- live counters
    def status(self) -> LinkStatus | None:
        """The current (or the last closed) link's status, None before the first Connect."""
        link = self.link or getattr(self, "_last_link", None)
        return None if link is None else link.status()

    def refresh(self) -> None:
        """Show the link's counters and the hand-eye pairs and result (called on the GUI's redraw
        timer; cheap when nothing changed)."""
        link = self.link or getattr(self, "_last_link", None)
        if link is not None and link.handeye is not None:
            self._show_handeye(link.handeye.status())
        status = self.status()
        if status is None:
            return
        state = status.state if self.link is not None else CLOSED
        if (state, status) == self._shown:
            return
        self._shown = (state, status)
        self._show_state(state, status.port)
        for key, label in self.counter_labels.items():
            label.setText(str(getattr(status, key)))
        self.last_error.setText(status.last_error)
        self.last_sent.setText(status.last_sent)
        self.last_sent.setCursorPosition(0)
        limit = f" (limit {status.max_rate_hz:g}/s)" if status.max_rate_hz > 0 else " (no limit)"
        self.line_rate.setText(f"{status.line_rate_hz:.1f} lines/s{limit}")
        self.lag.setText(f"{status.lag_ms:.0f} ms" if math.isfinite(status.lag_ms) else "—")
        self.last_command.setText(status.last_command)
        self.last_command.setCursorPosition(0)

    def _show_handeye(self, status: HandEyeStatus) -> None:
        if status == self._handeye_shown:
            return
        self._handeye_shown = status
        sim = " from a simulated source (SIM)" if status.simulated else ""
        busy = {"TOOL": "; waiting for a frame ($QRC,TOOL)", "HANDEYE": "; solving ($QRC,HANDEYE)"}
        self.pairs_label.setText(f"pairs recorded: {len(status.pairs)}{sim}{busy.get(status.busy, '')}")
        self.pairs_list.clear()
        for k, pair in enumerate(status.pairs, start=1):
            tool = ", ".join(f"{v:.1f}" for v in pair.tool_mm)
            code = ", ".join(f"{v:.1f}" for v in pair.code_mm)
            self.pairs_list.addItem(f"{k}: tool ({tool}) mm in the base; code ({code}) mm in the camera")
        self.pairs_list.scrollToBottom()
        lines = []
        done = status.done
        if done is not None:
            c = done.calibration
            kind = " from simulated frames" if done.simulated else ""
            kept = f" (the one before kept as {done.previous.name})" if done.previous else ""
            lines.append(
                f"last calibration: {c.setup}{kind} from {c.n_pairs} pairs, residuals "
                f"{c.residual_mm:.3f} mm, {c.residual_deg:.3f} deg; saved to {done.path}{kept}"
            )
        elif status.setup is None:
            lines.append(
                "HANDEYE has no set-up to solve for: choose the hand-eye set-up (or a tool/base frame)"
            )
        else:
            lines.append(f"HANDEYE solves {status.setup} and saves {status.save_to}")
        if status.last:
            lines.append(f"last: {status.last}")
        self.handeye_result.setText("\n".join(lines))

    def _show_state(self, state: str, port: str) -> None:
        colour = STATE_COLOURS.get(state, "#808080")
        self.state_label.setText(f"{state}" + (f" ({port})" if port and state != CLOSED else ""))
        self.state_label.setStyleSheet(
            f"color: white; background: {colour}; padding: 2px 6px; font-weight: bold;"
        )
        self.state_label.setProperty("state", state)

    def shown_state(self) -> str:
        """The state the panel displays: connected, connecting, disconnected or closed."""
        return str(self.state_label.property("state"))
