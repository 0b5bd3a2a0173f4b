"""The Camera tab's report: what the open camera delivers (sensor mode, crop, focus, the camera
model of its frames and where each number came from), and the cameras of this machine.

The same lines as ``qrfield camera check`` and ``qrfield camera list``. The report of the open
stream comes from the worker (``PipelineWorker.stream_report``); listing the cameras opens each
one briefly, so it runs as a :class:`ui.background.BackgroundJob`, never on the GUI thread.
"""

from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

from ui.background import BackgroundJob


def camera_listing() -> str:
    """The cameras of this machine and their modes, as text (each camera is opened briefly: slow)."""
    try:
        from qrfield.sources.discovery import list_cameras

        found, reasons = list_cameras(include_simulated=True)
        lines = []
        if not any(not c.simulated for c in found):
            lines.append("no cameras found: " + "; ".join(reasons))
        for camera in found:
            lines += [f"{camera.title}  [source {camera.source}]", *(f"  {x}" for x in camera.lines)]
        return "\n".join(lines)
    except Exception as exc:  # the listing must never take the app down
        return f"listing the cameras failed: {type(exc).__name__}: {exc}"


class CameraReport(QtWidgets.QWidget):
    """A read-only text of the stream's report, and a button that lists the cameras."""

    listed = QtCore.Signal(str)  # the listing's text, once shown

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self._stream = ""
        self._listing = ""  # the last listing, kept when the stream's report changes
        self.job = BackgroundJob("list-cameras", self)
        self._build()
        self.list_button.clicked.connect(self.list_cameras)
        self.job.finished.connect(self._show_listing)
        self.job.failed.connect(lambda message: self._show_listing(f"listing the cameras failed: {message}"))

    def _build(self) -> None:
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("stream"), 1)
        self.list_button = QtWidgets.QPushButton("List cameras")
        self.list_button.setObjectName("list_cameras")
        self.list_button.setToolTip(
            "the cameras of this machine and their sensor modes (qrfield camera list)"
        )
        row.addWidget(self.list_button)
        layout.addLayout(row)
        self.text = QtWidgets.QPlainTextEdit()
        self.text.setObjectName("camera_report")
        self.text.setReadOnly(True)
        self.text.setLineWrapMode(QtWidgets.QPlainTextEdit.LineWrapMode.NoWrap)
        self.text.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        self.text.setPlaceholderText("the open camera's sensor mode, crop and camera model appear here")
        layout.addWidget(self.text, 1)

    def show_stream(self, lines: list[str]) -> None:
        """Show the open stream's report (``PipelineWorker.stream_report``), above the last listing
        (a stream that opens after the listing came back must not wipe it)."""
        self._stream = "\n".join(lines)
        self._render()

    def _render(self) -> None:
        head = self._stream + "\n\n" if self._stream and self._listing else self._stream
        self.text.setPlainText(head + self._listing)

    def list_cameras(self) -> None:
        """List the cameras in the background (each is opened briefly); the text follows the stream's."""
        if not self.job.start(camera_listing):
            return  # a listing is on its way
        self.list_button.setEnabled(False)
        self.text.setPlainText(self._stream + ("\n\n" if self._stream else "") + "listing cameras…")

    def _show_listing(self, text: str) -> None:
        self.list_button.setEnabled(True)
        self._listing = f"cameras of this machine (the camera in use may show as busy):\n{text}"
        self._render()
        self.listed.emit(text)

    def shutdown(self, timeout_s: float = 5.0) -> None:
        """Wait briefly for a listing in progress (the window is closing)."""
        self.job.join(timeout_s)
