"""The serial panel: stream each measured pose to the gripper controller as $QRF lines and answer its
$QRC commands (PING, HELLO, STREAM, RATE, MEAS) on the same port (protocol 2, docs/serial.md).

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
"""

from __future__ import annotations

import dataclasses
import math
import threading
from typing import Any

from PySide6 import QtCore, QtWidgets

from qrfield.serial.controller import GripperLink
from qrfield.serial.link import CLOSED, CONNECTED, LinkStatus, SerialLinkSettings
from qrfield.serial.port import LOOP_URL, list_ports
from qrfield.settings import SettingError, specs, validated
from ui.background import BackgroundJob
from ui.settings_form import set_widget_value, widget_for, widget_value

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
    """Port chooser, link settings, Connect/Disconnect and live counters of the serial link.

    ``opener`` is passed to :class:`SerialLink` (tests may pass a fake port factory).
    """

    def __init__(
        self,
        settings: SerialLinkSettings | None = None,
        *,
        opener: Any = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self._opener = opener
        self._context: tuple[float, str] | None = None  # (side_mm, camera model) for HELLO
        self.link: GripperLink | None = None
        self.publisher = LinkPublisher()
        self._closers: list[BackgroundJob] = []  # one job per link being closed
        self._shown: tuple[str, LinkStatus] | None = None
        self._specs = {s.name: s for s in specs(SerialLinkSettings)}
        settings = validated(settings or SerialLinkSettings())
        outer = QtWidgets.QVBoxLayout(self)
        outer.addLayout(self._build_settings_form())
        outer.addWidget(self._build_link_box())
        self.note = QtWidgets.QLabel("")
        self.note.setWordWrap(True)
        outer.addWidget(self.note)
        outer.addStretch(1)
        self.refresh_ports()
        self.set_settings(settings)
        self._show_state(CLOSED, "")
        self.refresh_button.clicked.connect(self.refresh_ports)
        self.connect_button.clicked.connect(self.toggle)

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

    def set_context(self, side_mm: float, camera: str) -> None:
        """The QR side (mm) and camera model the measurements use: what HELLO reports."""
        self._context = (float(side_mm), str(camera))
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
            link = GripperLink(settings, opener=self._opener)
        except ValueError as exc:
            self.note.setText(f"⚠ cannot connect: {exc}")
            return False
        self.note.setText("")
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

    # ---------------------------------------------------------------- live counters
    def status(self) -> LinkStatus | None:
        """The current (or the last closed) link's status, None before the first Connect."""
        link = self.link or getattr(self, "_last_link", None)
        return None if link is None else link.status()

    def refresh(self) -> None:
        """Show the link's counters (called on the GUI's redraw timer; cheap when nothing changed)."""
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
