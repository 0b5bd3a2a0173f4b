"""The control tabs: source, solver, camera and QR side, virtual bench. Each emits ``changed``
when the user edits it; the main window turns the values into a worker configuration."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from PySide6 import QtCore, QtWidgets

from qrfield.camera import preset_names
from qrfield.runconfig import RunSettings
from qrfield.settings import setting, specs
from qrfield.sources import SOURCE_CHOICES, Picamera2Settings
from ui.camera_report import CameraReport
from ui.settings_form import SettingsForm, set_widget_value, widget_for, widget_value

PRESET_SIZES = ("640x480", "1280x960", "1280x720", "1920x1080")


@dataclass(frozen=True)
class ViewSettings:
    """How the app shows what it measures (the app's own; the run configuration is the core's)."""

    plot_window_s: float = setting(
        20.0, label="plot window", unit="s", minimum=2.0, maximum=600.0, decimals=0
    )


def _spec(name: str, cls: type = RunSettings) -> Any:
    return next(s for s in specs(cls) if s.name == name)


class SourceControls(QtWidgets.QWidget):
    """Source chooser (list, file, folder), loop option and the open/reopen button."""

    changed = QtCore.Signal()
    openRequested = QtCore.Signal()

    def __init__(self, picamera: Any = None, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        outer = QtWidgets.QVBoxLayout(self)
        outer.addLayout(self._build_source_form())
        box = QtWidgets.QGroupBox("Raspberry Pi camera (picamera2)")
        self.picamera = SettingsForm(Picamera2Settings, picamera)
        QtWidgets.QVBoxLayout(box).addWidget(self.picamera)
        outer.addWidget(box)
        outer.addStretch(1)
        self.picamera.changed.connect(lambda *_: self.changed.emit())
        self.open_button.clicked.connect(self.openRequested)
        self.combo.activated.connect(lambda *_: self.openRequested.emit())
        self.loop.toggled.connect(lambda *_: self.changed.emit())

    def _build_source_form(self) -> QtWidgets.QFormLayout:
        """The source chooser with its Video file… and Folder… buttons, loop, Open and the state line."""
        layout = QtWidgets.QFormLayout()
        self.combo = QtWidgets.QComboBox()
        self.combo.setEditable(True)
        self.combo.addItems(list(SOURCE_CHOICES))
        self.combo.setToolTip(_spec("source").describe())
        self.combo.setObjectName("source")
        file_button = QtWidgets.QPushButton("Video file…")
        folder_button = QtWidgets.QPushButton("Folder…")
        file_button.clicked.connect(self._choose_file)
        folder_button.clicked.connect(self._choose_folder)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.combo, 1)
        row.addWidget(file_button)
        row.addWidget(folder_button)
        layout.addRow("source", row)
        self.loop = widget_for(_spec("loop"))
        layout.addRow(_spec("loop").label, self.loop)
        self.open_button = QtWidgets.QPushButton("Open / reopen source")
        self.open_button.setObjectName("open_source")
        layout.addRow(self.open_button)
        self.state = QtWidgets.QLabel("")
        self.state.setObjectName("source_state")
        self.state.setWordWrap(True)
        layout.addRow(self.state)
        return layout

    def source(self) -> str:
        return self.combo.currentText().strip() or "auto"

    def show_state(self, text: str, error: bool = False) -> None:
        """What the source is doing: its description when open, why when it failed."""
        self.state.setText(text)
        self.state.setStyleSheet("color: #c0392b;" if error else "color: #1d6b1d;")

    def set_source(self, spec: str) -> None:
        with QtCore.QSignalBlocker(self.combo):
            self.combo.setCurrentText(spec)

    def _choose_file(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Video file", "", "Video (*.avi *.mp4 *.mkv *.mov);;All (*)"
        )
        if path:
            self.set_source(path)
            self.openRequested.emit()

    def _choose_folder(self) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Folder of images")
        if path:
            self.set_source(path)
            self.openRequested.emit()


class SolverControls(QtWidgets.QWidget):
    """Method choice, the live stream's settings (flips from history, the filter), the detector's
    and each method's settings (forms generated from their declarations)."""

    changed = QtCore.Signal()

    def __init__(
        self,
        settings_classes: dict[str, type],
        values: dict[str, Any],
        detector: tuple[type, Any] | None = None,
        stream: tuple[type, Any] | None = None,
        parent=None,
    ) -> None:
        super().__init__(parent)
        layout = QtWidgets.QVBoxLayout(self)
        form = QtWidgets.QFormLayout()
        self.method = widget_for(_spec("method"))
        form.addRow(_spec("method").label, self.method)
        layout.addLayout(form)
        self.stream = None if stream is None else self._add_form(layout, "live stream", *stream)
        self.detector = None if detector is None else self._add_form(layout, "detector", *detector)
        self.forms: dict[str, SettingsForm] = {}
        for name, cls in settings_classes.items():
            self.forms[name] = self._add_form(layout, name, cls, values.get(name))
        layout.addStretch(1)
        self.method.currentTextChanged.connect(lambda *_: self.changed.emit())

    def _add_form(self, layout: QtWidgets.QVBoxLayout, name: str, cls: type, value: Any) -> SettingsForm:
        """A "NAME settings" box holding the form of ``cls``; its changes are this tab's."""
        box = QtWidgets.QGroupBox(f"{name} settings")
        form = SettingsForm(cls, value)
        QtWidgets.QVBoxLayout(box).addWidget(form)
        layout.addWidget(box)
        form.changed.connect(lambda *_: self.changed.emit())
        return form

    def settings(self) -> dict[str, Any]:
        return {name: form.value() for name, form in self.forms.items()}


class CameraControls(QtWidgets.QWidget):
    """Camera model (preset[@size] or a JSON file), QR side and the plot window."""

    changed = QtCore.Signal()

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        layout = QtWidgets.QFormLayout(self)
        self.camera = QtWidgets.QComboBox()
        self.camera.setEditable(True)
        self.camera.setObjectName("camera")
        for name in preset_names():
            self.camera.addItems([f"{name}@{size}" for size in PRESET_SIZES])
        self.camera.setToolTip(_spec("camera").describe())
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.camera, 1)
        browse = QtWidgets.QPushButton("File…")
        row.addWidget(browse)
        layout.addRow(_spec("camera").label, row)
        self.camera_info = QtWidgets.QLabel("")
        self.camera_info.setWordWrap(True)
        layout.addRow(self.camera_info)
        self.side_mm = widget_for(_spec("side_mm"))
        layout.addRow(_spec("side_mm").label, self.side_mm)
        self.plot_window_s = widget_for(_spec("plot_window_s", ViewSettings))
        layout.addRow(_spec("plot_window_s", ViewSettings).label, self.plot_window_s)
        self.report = CameraReport()  # the open stream's mode, crop and model (qrfield camera check)
        layout.addRow(self.report)
        browse.clicked.connect(self._choose_file)
        self.camera.activated.connect(lambda *_: self.changed.emit())
        self.camera.lineEdit().editingFinished.connect(self.changed.emit)
        self.side_mm.valueChanged.connect(lambda *_: self.changed.emit())
        self.plot_window_s.valueChanged.connect(lambda *_: self.changed.emit())

    def _choose_file(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Camera model", "", "Camera JSON (*.json);;All (*)"
        )
        if path:
            with QtCore.QSignalBlocker(self.camera):
                self.camera.setCurrentText(path)
            self.changed.emit()


def app_settings_from(
    base: RunSettings, source: SourceControls, solver: SolverControls, camera: CameraControls
) -> RunSettings:
    """The run settings the controls show."""
    return dataclasses.replace(
        base,
        source=source.source(),
        loop=widget_value(source.loop),
        method=widget_value(solver.method),
        camera=camera.camera.currentText().strip(),
        side_mm=widget_value(camera.side_mm),
    )


def show_app_settings(
    app: RunSettings, source: SourceControls, solver: SolverControls, camera: CameraControls
) -> None:
    """Put ``app`` into the controls without emitting their change signals."""
    source.set_source(app.source)
    set_widget_value(source.loop, _spec("loop"), app.loop)
    set_widget_value(solver.method, _spec("method"), app.method)
    with QtCore.QSignalBlocker(camera.camera):
        camera.camera.setCurrentText(app.camera)
    set_widget_value(camera.side_mm, _spec("side_mm"), app.side_mm)


def view_settings_from(camera: CameraControls) -> ViewSettings:
    return ViewSettings(plot_window_s=widget_value(camera.plot_window_s))


def show_view_settings(view: ViewSettings, camera: CameraControls) -> None:
    set_widget_value(camera.plot_window_s, _spec("plot_window_s", ViewSettings), view.plot_window_s)
