"""The Analysis tab: choose a session, run :func:`qrfield.sessions.analysis.analyze` in the
background (it solves one pose per row for the resemblance to the simulation), then show the
report, the per-combination table and the two plots.

Results belong to their session: each analysis writes ``<session>/analysis/`` (``report.txt``,
``analysis.json``, ``errors_vs_tilt.png``, ``measured_vs_truth.png``; a new analysis replaces the
last one, each file written whole). "Save as…" copies them to a folder the operator chooses.
Only when the session folder cannot be written (a read-only medium) do they go to a temporary
folder, and the tab says so.

"Open report" writes the session's ``report.html`` (:func:`qrfield.sessions.report.write_report`,
in the background: it runs the simulation for the session's poses) and opens it in the system's
browser (:meth:`AnalysisTab.open_url`; a temporary file when the session folder is read-only).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.sessions import read_session, session_folders
from qrfield.sessions.files import atomic_write
from ui.background import BackgroundJob
from ui.groundtruth_form import WrappedLabel
from ui.session_dialogs import touch_button
from ui.text import fixed, short_path

#: The folder, inside a session, that its analysis is written to.
ANALYSIS_FOLDER = "analysis"
REPORT_FILE = "report.txt"
JSON_FILE = "analysis.json"
#: Per-combination table: (header, key in a per_combination item, how to show it).
TABLE_COLUMNS = (
    ("combination", "combo", str),
    ("rows", "rows", str),
    ("passed", "passed", str),
    ("pass rate", "pass_rate", lambda v: "-" if v is None else f"{fixed(100 * v, 1)} %"),
    ("no pose", "no_pose", str),
)
ERROR_COLUMNS = (
    ("pos mm", "pos_mm"),
    ("α deg", "alpha_deg"),
    ("β deg", "beta_deg"),
    ("γ deg", "gamma_deg"),
)


def _num(value: float | None) -> str:
    return fixed(value, 2, missing="-")


def analyse_into_session(session_dir: str) -> dict[str, Any]:
    """Analyse ``session_dir`` and write the results into its ``analysis/`` folder (a temporary
    folder when that cannot be written: ``result["out_note"]`` says why). Runs off the GUI thread."""
    from qrfield.sessions.analysis import analyze, format_report

    read_session(session_dir)  # SessionError for a folder that is no session: nothing written into it
    out = Path(session_dir) / ANALYSIS_FOLDER
    note = ""
    try:
        out.mkdir(exist_ok=True)
        probe = out / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        note = (
            f"the session folder cannot be written ({exc.strerror or exc}): "
            "results kept in a temporary folder"
        )
        out = Path(tempfile.mkdtemp(prefix="qrfield-analysis-"))
    result = analyze(session_dir, out_dir=out, compare=True)
    result["report"] = format_report(result)
    atomic_write(out / REPORT_FILE, (result["report"] + "\n").encode("utf-8"))
    data = {k: v for k, v in result.items() if k != "report"}
    atomic_write(out / JSON_FILE, (json.dumps(data, indent=2) + "\n").encode("utf-8"))
    result["out_dir"] = str(out)
    result["out_note"] = note
    return result


def report_into_session(session_dir: str) -> dict[str, Any]:
    """Write ``session_dir``'s report.html (a temporary file when the folder cannot be written:
    ``note`` says why); {"path", "note", "summary"}. Runs off the GUI thread."""
    from qrfield.sessions.report import REPORT_FILE, write_report

    read_session(session_dir)  # SessionError for a folder that is no session: nothing written into it
    try:
        summary = write_report(session_dir)
        note = ""
    except OSError as exc:
        note = f"the session folder cannot be written ({exc.strerror or exc}): report in a temporary folder"
        out = Path(tempfile.mkdtemp(prefix="qrfield-report-")) / REPORT_FILE
        summary = write_report(session_dir, out)
    return {"path": str(summary.path), "note": note, "summary": summary}


def result_files(result: dict[str, Any]) -> list[Path]:
    """The files an analysis wrote (report, JSON, plots)."""
    out = Path(result["out_dir"])
    return [out / REPORT_FILE, out / JSON_FILE, *(Path(p) for p in result["plots"])]


class ScaledImage(QtWidgets.QLabel):
    """Shows a picture scaled to the label's width (aspect kept); ``image`` is the full-size one."""

    def __init__(self, text: str = "") -> None:
        super().__init__(text)
        self.image: QtGui.QPixmap | None = None
        self.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self.setWordWrap(True)
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


class AnalysisTab(QtWidgets.QWidget):
    """Analysis of a session (the current one by default). ``root()`` gives the sessions folder."""

    analysisDone = QtCore.Signal(object)  # the result dict (with "report" and "out_dir")

    def __init__(self, root: Any, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.root = root
        self.current: str | None = None
        self.result: dict[str, Any] | None = None
        self.job = BackgroundJob("qrfield-analysis", self)
        self.job.finished.connect(self._done)
        self.job.failed.connect(self._failed)
        self.report_job = BackgroundJob("qrfield-report", self)
        self.report_job.finished.connect(self._report_done)
        self.report_job.failed.connect(self._report_failed)
        self.report_path: str | None = None
        self._build_controls()
        self._build_results()
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(6, 6, 6, 6)
        layout.addLayout(self.controls)
        layout.addWidget(self.state)
        layout.addWidget(self.pass_rate)
        layout.addWidget(self.pages, 1)
        self.refresh_sessions()

    # ---------------------------------------------------------------- builders
    def _build_controls(self) -> None:
        self.choice = QtWidgets.QComboBox()
        self.choice.setObjectName("analysis_session")
        self.choice.setEditable(True)
        self.choice.setToolTip("a session folder (the open session is first)")
        self.choice.setMinimumContentsLength(12)
        self.choice.setSizeAdjustPolicy(
            QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon
        )
        refresh = touch_button("↻")
        refresh.setFixedWidth(44)
        refresh.setToolTip("list the sessions folder again")
        refresh.clicked.connect(self.refresh_sessions)
        browse = touch_button("Folder…")
        browse.clicked.connect(self._browse)
        self.run_button = touch_button("Analyze", "analyze")
        self.run_button.clicked.connect(self.run)
        self.save_button = touch_button("Save as…", "save_analysis")
        self.save_button.setToolTip("copy the report, its JSON and the plots to a folder you choose")
        self.save_button.setEnabled(False)
        self.save_button.clicked.connect(self.save_as)
        self.report_button = touch_button("Open report", "open_report")
        self.report_button.setToolTip(
            "write the session's report.html (settings, pass rates, figures, rows, the simulation's "
            "prediction; one file that opens offline) and open it in the browser"
        )
        self.report_button.clicked.connect(self.open_report)
        first, second = QtWidgets.QHBoxLayout(), QtWidgets.QHBoxLayout()
        first.addWidget(self.choice, 1)
        first.addWidget(refresh)
        first.addWidget(browse)
        second.addWidget(self.run_button)
        second.addWidget(self.save_button)
        second.addWidget(self.report_button)
        second.addStretch(1)
        self.controls = QtWidgets.QVBoxLayout()  # two lines: the session's name needs the width
        self.controls.addLayout(first)
        self.controls.addLayout(second)
        self.state = WrappedLabel("choose a session and press Analyze")
        self.state.setObjectName("analysis_state")
        self.pass_rate = WrappedLabel("")
        self.pass_rate.setObjectName("analysis_pass_rate")
        self.pass_rate.setStyleSheet("font-size: 13pt; font-weight: bold;")

    def _build_results(self) -> None:
        self.report = QtWidgets.QPlainTextEdit()
        self.report.setObjectName("analysis_report")
        self.report.setReadOnly(True)
        self.report.setLineWrapMode(QtWidgets.QPlainTextEdit.LineWrapMode.NoWrap)
        self.report.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        self.table = QtWidgets.QTableWidget(0, len(TABLE_COLUMNS) + len(ERROR_COLUMNS))
        self.table.setObjectName("analysis_table")
        self.table.setHorizontalHeaderLabels(
            [h for h, _, _ in TABLE_COLUMNS] + [f"{h}\nmean / max" for h, _ in ERROR_COLUMNS]
        )
        self.table.verticalHeader().hide()
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.plots: list[ScaledImage] = []
        plots_page = QtWidgets.QWidget()
        plots_layout = QtWidgets.QVBoxLayout(plots_page)
        for name in ("errors against tilt", "measured against truth"):
            label = ScaledImage(f"({name}: not drawn yet)")
            label.setObjectName(name.replace(" ", "_"))
            self.plots.append(label)
            plots_layout.addWidget(label)
        plots_layout.addStretch(1)
        plots_area = QtWidgets.QScrollArea()
        plots_area.setWidget(plots_page)
        plots_area.setWidgetResizable(True)
        self.pages = QtWidgets.QTabWidget()
        self.pages.setObjectName("analysis_pages")
        self.pages.addTab(self.report, "Report")
        self.pages.addTab(self.table, "Per combination")
        self.pages.addTab(plots_area, "Plots")

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
        return self.job.busy

    def run(self) -> bool:
        """Start the analysis of the chosen session in the background; False if it cannot start."""
        return self._start(
            self.job, analyse_into_session, self.run_button, "an analysis is running", "analysing"
        )

    def _start(
        self, job: BackgroundJob, work: Any, button: QtWidgets.QPushButton, busy: str, doing: str
    ) -> bool:
        """Run ``work(chosen session)`` on ``job``, its button off meanwhile; False if it cannot start."""
        session_dir = self.chosen()
        if not session_dir:
            self._set_state("choose a session first", error=True)
            return False
        if not job.start(work, session_dir):
            self._set_state(busy, error=False)
            return False
        button.setEnabled(False)
        self._set_state(f"{doing} {short_path(session_dir)} …", error=False)
        return True

    def _set_state(self, text: str, error: bool) -> None:
        self.state.setText(text)
        self.state.setStyleSheet("color: #c0392b;" if error else "")

    def _failed(self, message: str) -> None:
        self.run_button.setEnabled(True)
        self._set_state(f"analysis of {self.chosen()} failed: {message}", error=True)

    def _done(self, result: dict[str, Any]) -> None:
        self.run_button.setEnabled(True)
        self.save_button.setEnabled(True)
        self.result = result
        where = short_path(result["out_dir"])
        self._set_state(
            f"analysed {Path(result['session']).name}; results in {where}"
            + (f"\n⚠ {result['out_note']}" if result["out_note"] else ""),
            error=bool(result["out_note"]),
        )
        rate = result["pass_rate"]
        self.pass_rate.setText(
            "pass rate: -"
            if rate is None
            else f"pass rate {fixed(100 * rate, 2)} %  ({result['passed']} of {result['rows']} rows)"
        )
        self.report.setPlainText(result["report"])
        self._fill_table(result)
        for label, path in zip(self.plots, result["plots"], strict=False):
            pixmap = QtGui.QPixmap(path)
            if pixmap.isNull():
                label.setText(f"cannot show {path}")
            else:
                label.set_image(pixmap)
            label.setToolTip(path)
        self.analysisDone.emit(result)

    def _fill_table(self, result: dict[str, Any]) -> None:
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

    # ---------------------------------------------------------------- saving
    def ask_save_folder(self) -> str:
        """The folder to copy the results to ("" = cancelled); tests replace this."""
        return QtWidgets.QFileDialog.getExistingDirectory(self, "Save the analysis in", str(Path.home()))

    def save_as(self) -> list[Path]:
        """Copy the last analysis' files to a folder the operator chooses; the copies' paths."""
        if self.result is None:
            return []
        folder = self.ask_save_folder()
        if not folder:
            return []
        prefix = Path(self.result["session"]).name
        copies = []
        try:
            for path in result_files(self.result):
                target = Path(folder) / f"{prefix}-{path.name}"
                shutil.copyfile(path, target)
                copies.append(target)
        except OSError as exc:
            self._set_state(f"not saved to {folder}: {exc}", error=True)
            return copies
        self._set_state(f"saved {len(copies)} files to {short_path(folder)}", error=False)
        return copies

    # ---------------------------------------------------------------- the report
    def open_url(self, path: str) -> bool:
        """Open a file in the system's browser; tests replace this."""
        return QtGui.QDesktopServices.openUrl(QtCore.QUrl.fromLocalFile(path))

    def open_report(self) -> bool:
        """Write the chosen session's report.html in the background, then open it."""
        return self._start(
            self.report_job,
            report_into_session,
            self.report_button,
            "a report is being written",
            "writing the report of",
        )

    def _report_done(self, result: dict[str, Any]) -> None:
        self.report_button.setEnabled(True)
        self.report_path = result["path"]
        opened = self.open_url(result["path"])
        text = f"report: {short_path(result['path'])}" + ("" if opened else " (no browser to open it)")
        if result["note"]:
            text += f"\n⚠ {result['note']}"
        self._set_state(text, error=bool(result["note"]) or not opened)

    def _report_failed(self, message: str) -> None:
        self.report_button.setEnabled(True)
        self._set_state(f"report of {self.chosen()} not written: {message}", error=True)

    def shutdown(self) -> None:
        """Wait briefly for a running analysis or report (the window is closing)."""
        self.job.join(5.0)
        self.report_job.join(5.0)
