"""The Analysis tab: choose a session, run :func:`qrfield.sessions.analysis.analyze` on a worker
thread (it solves one pose per row for the resemblance to the simulation), then show the report
text, the per-combination table and the two PNG plots it wrote to a temporary folder."""

from __future__ import annotations

import os
import tempfile
import threading
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.sessions import session_folders

#: Per-combination table: (header, key in a per_combination item, how to show it).
TABLE_COLUMNS = (
    ("combination", "combo", str),
    ("rows", "rows", str),
    ("passed", "passed", str),
    ("pass rate", "pass_rate", lambda v: "-" if v is None else f"{100 * v:.1f} %"),
    ("no pose", "no_pose", str),
)
ERROR_COLUMNS = (
    ("pos mm", "pos_mm"),
    ("α deg", "alpha_deg"),
    ("β deg", "beta_deg"),
    ("γ deg", "gamma_deg"),
)


def _num(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


class ScaledImage(QtWidgets.QLabel):
    """Shows a picture scaled to the label's width (aspect kept); ``image`` is the full-size one."""

    def __init__(self, text: str = "") -> None:
        super().__init__(text)
        self.image: QtGui.QPixmap | None = None
        self.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored, QtWidgets.QSizePolicy.Policy.Fixed)
        self.setMinimumHeight(60)

    def set_image(self, pixmap: QtGui.QPixmap) -> None:
        self.image = pixmap
        self._fit()

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:
        super().resizeEvent(event)
        self._fit()

    def _fit(self) -> None:
        if self.image is None or self.image.isNull():
            return
        width = max(100, min(self.width(), self.image.width()))
        scaled = self.image.scaledToWidth(width, QtCore.Qt.TransformationMode.SmoothTransformation)
        self.setPixmap(scaled)
        self.setFixedHeight(scaled.height())


class _Runner(QtCore.QObject):
    """Runs analyze() on a plain thread; reports by signal (queued into the GUI thread)."""

    finished = QtCore.Signal(object)  # the result dict
    failed = QtCore.Signal(str)

    def start(self, session_dir: str, out_dir: str) -> threading.Thread:
        thread = threading.Thread(target=self._run, args=(session_dir, out_dir), name="qrfield-analysis")
        thread.daemon = True
        thread.start()
        return thread

    def _run(self, session_dir: str, out_dir: str) -> None:
        try:
            from qrfield.sessions.analysis import analyze, format_report

            result = analyze(session_dir, out_dir=out_dir, compare=True)
            result["report"] = format_report(result)
        except Exception as exc:  # a damaged session or an unwritable folder: show it, keep the app
            self.failed.emit(f"analysis of {session_dir} failed: {exc}")
            return
        self.finished.emit(result)


class AnalysisTab(QtWidgets.QWidget):
    """Analysis of a session (the current one by default). ``root()`` gives the sessions folder."""

    analysisDone = QtCore.Signal(object)  # the result dict (with "report")

    def __init__(self, root: Any, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.root = root
        self.current: str | None = None
        self.result: dict[str, Any] | None = None
        self._thread: threading.Thread | None = None
        self._out = tempfile.TemporaryDirectory(prefix="qrfield-analysis-")
        self._runs = 0
        self._runner = _Runner()
        self._runner.finished.connect(self._done)
        self._runner.failed.connect(self._failed)

        self.choice = QtWidgets.QComboBox()
        self.choice.setObjectName("analysis_session")
        self.choice.setEditable(True)
        self.choice.setToolTip("a session folder (the open session is first)")
        browse = QtWidgets.QPushButton("Folder…")
        browse.clicked.connect(self._browse)
        refresh = QtWidgets.QPushButton("↻")
        refresh.setToolTip("list the sessions folder again")
        refresh.clicked.connect(self.refresh_sessions)
        self.run_button = QtWidgets.QPushButton("Analyze")
        self.run_button.setObjectName("analyze")
        self.run_button.clicked.connect(self.run)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(self.choice, 1)
        top.addWidget(refresh)
        top.addWidget(browse)
        top.addWidget(self.run_button)
        self.state = QtWidgets.QLabel("choose a session and press Analyze")
        self.state.setObjectName("analysis_state")
        self.state.setWordWrap(True)
        self.pass_rate = QtWidgets.QLabel("")
        self.pass_rate.setObjectName("analysis_pass_rate")
        self.pass_rate.setStyleSheet("font-size: 15pt; font-weight: bold;")
        self.report = QtWidgets.QPlainTextEdit()
        self.report.setObjectName("analysis_report")
        self.report.setReadOnly(True)
        self.report.setLineWrapMode(QtWidgets.QPlainTextEdit.LineWrapMode.NoWrap)
        self.report.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        self.report.setMinimumHeight(140)
        self.table = QtWidgets.QTableWidget(0, len(TABLE_COLUMNS) + len(ERROR_COLUMNS))
        self.table.setObjectName("analysis_table")
        self.table.setHorizontalHeaderLabels(
            [h for h, _, _ in TABLE_COLUMNS] + [f"{h} mean/max" for h, _ in ERROR_COLUMNS]
        )
        self.table.verticalHeader().hide()
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setMaximumHeight(160)
        self.plots: list[ScaledImage] = []
        plots = QtWidgets.QVBoxLayout()
        for name in ("errors against tilt", "measured against truth"):
            label = ScaledImage(f"({name}: not drawn yet)")
            label.setObjectName(name.replace(" ", "_"))
            self.plots.append(label)
            plots.addWidget(label)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.state)
        layout.addWidget(self.pass_rate)
        layout.addWidget(self.report)
        layout.addWidget(self.table)
        layout.addLayout(plots)
        self.refresh_sessions()

    # ---------------------------------------------------------------- choosing
    def set_current(self, path: str | os.PathLike[str] | None) -> None:
        """The open session (first in the list, chosen by default)."""
        self.current = None if path is None else str(path)
        self.refresh_sessions()
        if self.current:
            self.choice.setCurrentIndex(self.choice.findData(self.current))

    def refresh_sessions(self) -> None:
        chosen = self.choice.currentData() or self.choice.currentText()
        self.choice.clear()
        paths = [str(p) for p in reversed(session_folders(self.root()))]
        if self.current and self.current not in paths:
            paths.insert(0, self.current)
        for path in paths:
            label = Path(path).name + ("  (open)" if path == self.current else "")
            self.choice.addItem(label, path)
        index = self.choice.findData(chosen) if chosen else -1
        if index >= 0:
            self.choice.setCurrentIndex(index)
        elif self.current:
            self.choice.setCurrentIndex(self.choice.findData(self.current))

    def _browse(self) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Session folder", str(self.root()))
        if path:
            self.choice.addItem(Path(path).name, path)
            self.choice.setCurrentIndex(self.choice.count() - 1)

    def chosen(self) -> str:
        index = self.choice.currentIndex()
        data = self.choice.itemData(index) if index >= 0 else None
        if data and self.choice.itemText(index) == self.choice.currentText():
            return str(data)
        return self.choice.currentText().strip()  # a path typed in

    # ---------------------------------------------------------------- running
    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def run(self) -> bool:
        """Start the analysis of the chosen session on a worker thread; False if it cannot start."""
        session_dir = self.chosen()
        if not session_dir:
            self.state.setText("choose a session first")
            return False
        if self.busy:
            self.state.setText("an analysis is running")
            return False
        self._runs += 1
        out = Path(self._out.name) / f"run{self._runs}"
        self.run_button.setEnabled(False)
        self.state.setText(f"analysing {session_dir} …")
        self._thread = self._runner.start(session_dir, str(out))
        return True

    def _failed(self, message: str) -> None:
        self.run_button.setEnabled(True)
        self.state.setText(message)
        self.state.setStyleSheet("color: #c0392b;")

    def _done(self, result: dict[str, Any]) -> None:
        self.run_button.setEnabled(True)
        self.state.setStyleSheet("")
        self.result = result
        self.state.setText(f"analysed {result['session']}; plots in {Path(self._out.name)}")
        rate = result["pass_rate"]
        self.pass_rate.setText(
            "pass rate: -"
            if rate is None
            else f"pass rate {100 * rate:.2f} %  ({result['passed']} of {result['rows']} rows)"
        )
        self.report.setPlainText(result["report"])
        items = [*result["per_combination"], {"combo": "all", **result}]
        self.table.setRowCount(len(items))
        for r, item in enumerate(items):
            cells = [fmt(item[key]) for _, key, fmt in TABLE_COLUMNS]
            cells += [
                f"{_num(item['mean_abs_error'][key])} / {_num(item['max_abs_error'][key])}"
                for _, key in ERROR_COLUMNS
            ]
            for c, text in enumerate(cells):
                self.table.setItem(r, c, QtWidgets.QTableWidgetItem(text))
        self.table.resizeColumnsToContents()
        for label, path in zip(self.plots, result["plots"], strict=False):
            pixmap = QtGui.QPixmap(path)
            if pixmap.isNull():
                label.setText(f"cannot show {path}")
            else:
                label.set_image(pixmap)
            label.setToolTip(path)
        self.analysisDone.emit(result)

    def shutdown(self) -> None:
        """Wait briefly for a running analysis, then remove the temporary plots."""
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if not self.busy:
            self._out.cleanup()
