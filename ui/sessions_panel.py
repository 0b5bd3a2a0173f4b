"""The Session tab: new / resume a session, the ground-truth form, "Log row", undo, the rows table.

A thin layer over :mod:`qrfield.sessions`. "Log row" collects the next N results the window draws
(:meth:`SessionPanel.on_processed`, fed from the main window's redraw: the same results the
preview shows, no second camera path; only frames captured after the press count), averages
them with a :class:`~qrfield.sessions.FrameCollector` for the session's solver and calls
:meth:`Session.log` on the GUI thread (one append and fsync per row). When the form follows the
virtual bench, the row's ground truth is the bench's mean true pose over the frames collected
(a wobbling bench moves while the row is measured). The status says "logged
row K" only when ``log`` returned "logged"; a row that could not be written stays in the
session's pending queue and a red banner offers Retry and "Save pending elsewhere…".

Dialogs go through small methods (:meth:`ask_confirm`, :meth:`ask_pending_choice`,
:meth:`ask_save_path`, :meth:`ask_folder`) so that tests can answer them.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

from qrfield.camera import CameraModel
from qrfield.methods import METHODS
from qrfield.sessions import (
    AcceptanceCriteria,
    FrameCollector,
    GroundTruth,
    LogOutcome,
    Session,
    SessionError,
    SessionSettings,
    known_combinations,
    session_folders,
)
from qrfield.sessions.recorder import bench_mean_truth
from qrfield.settings import SettingError, setting
from ui.groundtruth_form import GroundTruthForm
from ui.rows_table import RowsTable
from ui.settings_form import SettingsForm

ENV_ROOT = "QRFIELD_SESSIONS_DIR"


@dataclass(frozen=True)
class SessionFolderSettings:
    """Where the app makes new sessions."""

    root: str = setting(
        "",
        label="sessions folder",
        help=f"new sessions are made in this folder (empty = ${ENV_ROOT} or ~/qrfield-sessions)",
    )


def sessions_root(settings: SessionFolderSettings) -> Path:
    """The folder of new sessions: the setting, else $QRFIELD_SESSIONS_DIR, else ~/qrfield-sessions."""
    text = settings.root.strip() or os.environ.get(ENV_ROOT, "").strip()
    return Path(text).expanduser() if text else Path.home() / "qrfield-sessions"


@dataclass(frozen=True)
class BenchContext:
    """What the window measures with now (recorded in a new session, checked before each row)."""

    camera: CameraModel
    side_mm: float
    methods: tuple[str, ...]
    solver_settings: dict[str, Any] = field(default_factory=dict)


class SessionPanel(QtWidgets.QWidget):
    """The Session tab. ``context()`` returns the window's current :class:`BenchContext`."""

    rowLogged = QtCore.Signal(int)  # the row is on disk
    rowPending = QtCore.Signal(str)  # a write failed; the message
    sessionChanged = QtCore.Signal(object)  # the open Session or None

    def __init__(self, store: Any, context: Any, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.context = context
        self.session: Session | None = None
        self._collector: FrameCollector | None = None
        self._truth: GroundTruth | None = None
        self._note = ""
        self._following = False
        self._t_press = 0.0

        # ----- session: current, new, resume
        self.title = QtWidgets.QLabel("no session open: create one or resume one")
        self.title.setObjectName("session_title")
        self.title.setStyleSheet("font-weight: bold;")
        self.title.setWordWrap(True)
        self.count = QtWidgets.QLabel("")
        self.count.setObjectName("session_count")
        self.count.setWordWrap(True)
        self.warnings = QtWidgets.QLabel("")
        self.warnings.setObjectName("session_warnings")
        self.warnings.setWordWrap(True)
        self.warnings.setStyleSheet("color: #a05000;")
        self.warnings.hide()

        new_box = QtWidgets.QWidget()
        new_form = QtWidgets.QFormLayout(new_box)
        self.name_edit = QtWidgets.QLineEdit()
        self.name_edit.setObjectName("session_name")
        self.name_edit.setPlaceholderText("e.g. beta-sweep")
        self.operator_edit = QtWidgets.QLineEdit()
        self.operator_edit.setObjectName("session_operator")
        self.notes_edit = QtWidgets.QPlainTextEdit()
        self.notes_edit.setObjectName("session_notes")
        self.notes_edit.setTabChangesFocus(True)
        self.notes_edit.setMaximumHeight(54)
        self.solver_combo = QtWidgets.QComboBox()
        self.solver_combo.addItems(list(METHODS))
        self.solver_combo.setToolTip("the pose method whose results the rows average")
        self.folder_form = SettingsForm(
            SessionFolderSettings, store.group("session_folder", SessionFolderSettings)
        )
        folder_row = QtWidgets.QHBoxLayout()
        folder_row.addWidget(self.folder_form, 1)
        browse = QtWidgets.QPushButton("Folder…")
        browse.clicked.connect(self._choose_root)
        folder_row.addWidget(browse)
        self.row_settings = SettingsForm(SessionSettings, store.group("session", SessionSettings))
        self.criteria_form = SettingsForm(AcceptanceCriteria, store.group("criteria", AcceptanceCriteria))
        self.create_button = QtWidgets.QPushButton("Create session")
        self.create_button.setObjectName("create_session")
        new_form.addRow("name", self.name_edit)
        new_form.addRow("operator", self.operator_edit)
        new_form.addRow("notes", self.notes_edit)
        new_form.addRow("solver", self.solver_combo)
        new_form.addRow(folder_row)
        new_form.addRow(self.row_settings)
        new_form.addRow(self.criteria_form)
        new_form.addRow(self.create_button)

        resume_box = QtWidgets.QWidget()
        resume_layout = QtWidgets.QVBoxLayout(resume_box)
        resume_row = QtWidgets.QHBoxLayout()
        resume_layout.addLayout(resume_row)
        self.resume_combo = QtWidgets.QComboBox()
        self.resume_combo.setObjectName("resume_choice")
        self.resume_button = QtWidgets.QPushButton("Resume")
        self.resume_button.setObjectName("resume_session")
        open_button = QtWidgets.QPushButton("Open folder…")
        resume_row.addWidget(self.resume_combo, 1)
        resume_row.addWidget(self.resume_button)
        resume_row.addWidget(open_button)
        resume_note = QtWidgets.QLabel(
            "Resuming continues the numbering after the last row; rows already logged are never rewritten."
        )
        resume_note.setWordWrap(True)
        resume_layout.addWidget(resume_note)
        resume_layout.addStretch(1)
        self.manage = QtWidgets.QTabWidget()
        self.manage.setObjectName("session_manage")
        self.manage.addTab(new_box, "New session")
        self.manage.addTab(resume_box, "Resume / open")

        # ----- the next row
        row_box = QtWidgets.QGroupBox("Next row: ground truth measured by hand")
        row_layout = QtWidgets.QVBoxLayout(row_box)
        self.form = GroundTruthForm(known_combinations())
        row_layout.addWidget(self.form)
        buttons = QtWidgets.QHBoxLayout()
        self.log_button = QtWidgets.QPushButton("Log row  (Enter)")
        self.log_button.setObjectName("log_row")
        self.cancel_button = QtWidgets.QPushButton("Cancel")
        self.cancel_button.setObjectName("cancel_row")
        self.undo_button = QtWidgets.QPushButton("Undo last row…")
        self.undo_button.setObjectName("undo_row")
        buttons.addWidget(self.log_button)
        buttons.addWidget(self.cancel_button)
        buttons.addStretch(1)
        buttons.addWidget(self.undo_button)
        row_layout.addLayout(buttons)
        self.progress = QtWidgets.QProgressBar()
        self.progress.setObjectName("row_progress")
        self.progress.setFormat("%v / %m frames")
        self.progress.setValue(0)
        row_layout.addWidget(self.progress)
        self.why = QtWidgets.QLabel("")
        self.why.setObjectName("log_blocked_reason")
        self.why.setWordWrap(True)
        self.why.setStyleSheet("color: #666;")
        row_layout.addWidget(self.why)
        self.status = QtWidgets.QLabel("")
        self.status.setObjectName("session_status")
        self.status.setWordWrap(True)
        row_layout.addWidget(self.status)

        # ----- pending banner
        self.banner = QtWidgets.QWidget()
        self.banner.setObjectName("pending_banner")
        banner_layout = QtWidgets.QHBoxLayout(self.banner)
        banner_layout.setContentsMargins(0, 0, 0, 0)
        self.banner_text = QtWidgets.QLabel("")
        self.banner_text.setWordWrap(True)
        self.banner_text.setStyleSheet("background: #a01818; color: white; padding: 6px; font-weight: bold;")
        self.retry_button = QtWidgets.QPushButton("Retry")
        self.retry_button.setObjectName("retry_pending")
        self.export_button = QtWidgets.QPushButton("Save pending elsewhere…")
        self.export_button.setObjectName("export_pending")
        banner_layout.addWidget(self.banner_text, 1)
        banner_layout.addWidget(self.retry_button)
        banner_layout.addWidget(self.export_button)
        self.banner.hide()

        self.table = RowsTable()
        self.table.setMinimumHeight(180)

        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self.title)
        layout.addWidget(self.count)
        layout.addWidget(self.warnings)
        layout.addWidget(self.banner)
        layout.addWidget(row_box)
        layout.addWidget(self.table, 1)
        layout.addWidget(self.manage)

        # ----- wiring
        self.create_button.clicked.connect(self.create_from_form)
        self.resume_button.clicked.connect(self._resume_chosen)
        open_button.clicked.connect(self._open_folder)
        self.log_button.clicked.connect(self.log_row)
        self.form.submitted.connect(self.log_row)
        self.form.validityChanged.connect(lambda _valid: self._update_state())
        self.cancel_button.clicked.connect(self.cancel_row)
        self.undo_button.clicked.connect(self.undo_row)
        self.retry_button.clicked.connect(self.retry)
        self.export_button.clicked.connect(self.export_pending)
        self.folder_form.changed.connect(lambda *_: self.refresh_folders())
        self.manage.currentChanged.connect(lambda _index: self.refresh_folders())
        self.refresh_folders()
        self._update_state()

    # ---------------------------------------------------------------- settings
    def root(self) -> Path:
        return sessions_root(self.folder_form.value())

    def save_settings(self, store: Any) -> None:
        store.set_group("session_folder", self.folder_form.value())
        store.set_group("session", self.row_settings.value())
        store.set_group("criteria", self.criteria_form.value())

    def set_default_solver(self, methods: tuple[str, ...]) -> None:
        """Preselect the solver of a new session: the thesis' model when it runs, else the one that runs."""
        self.solver_combo.setCurrentText("numerical" if "numerical" in methods or not methods else methods[0])

    def refresh_folders(self) -> None:
        current = self.resume_combo.currentData()
        self.resume_combo.clear()
        for folder in reversed(session_folders(self.root())):  # newest first
            self.resume_combo.addItem(folder.name, str(folder))
        if current:
            index = self.resume_combo.findData(current)
            if index >= 0:
                self.resume_combo.setCurrentIndex(index)

    # ---------------------------------------------------------------- dialogs (tests replace these)
    def ask_confirm(self, title: str, text: str) -> bool:
        answer = QtWidgets.QMessageBox.question(self, title, text)
        return answer == QtWidgets.QMessageBox.StandardButton.Yes

    def ask_pending_choice(self, message: str) -> str:
        """'retry', 'save', 'discard' or 'cancel' (keep the app open)."""
        box = QtWidgets.QMessageBox(self)
        box.setIcon(QtWidgets.QMessageBox.Icon.Warning)
        box.setWindowTitle("Rows not written")
        box.setText(message)
        buttons = {
            "retry": box.addButton("Retry", QtWidgets.QMessageBox.ButtonRole.AcceptRole),
            "save": box.addButton("Save elsewhere…", QtWidgets.QMessageBox.ButtonRole.ActionRole),
            "discard": box.addButton("Discard them", QtWidgets.QMessageBox.ButtonRole.DestructiveRole),
            "cancel": box.addButton("Keep the app open", QtWidgets.QMessageBox.ButtonRole.RejectRole),
        }
        box.exec()
        clicked = box.clickedButton()
        return next((name for name, button in buttons.items() if button is clicked), "cancel")

    def ask_save_path(self) -> str:
        path, _ = QtWidgets.QFileDialog.getSaveFileName(
            self, "Save pending rows elsewhere", str(Path.home() / "qrfield-pending-rows.csv"), "CSV (*.csv)"
        )
        return path

    def ask_folder(self) -> str:
        return QtWidgets.QFileDialog.getExistingDirectory(self, "Open a session folder", str(self.root()))

    # ---------------------------------------------------------------- open / create
    def create_from_form(self) -> Session | None:
        """Create a session from the New box and the window's context; errors go to the status line."""
        if not self._release_current():
            return None
        ctx: BenchContext = self.context()
        solver = self.solver_combo.currentText()
        try:
            session = Session.create(
                self.root(),
                self.name_edit.text(),
                camera=ctx.camera,
                side_mm=ctx.side_mm,
                solver=solver,
                solver_settings=ctx.solver_settings.get(solver),
                criteria=self.criteria_form.value(),
                frames_per_row=self.row_settings.value().frames_per_row,
                operator=self.operator_edit.text(),
                notes=self.notes_edit.toPlainText(),
            )
        except (SessionError, SettingError, OSError) as exc:
            self._say(f"cannot create the session: {exc}", error=True)
            return None
        self._use(session)
        self._say(f"created session {session.path.name} in {session.path.parent}")
        return session

    def open_session(self, path: str | os.PathLike[str]) -> Session | None:
        """Resume the session in ``path`` (its warnings are shown); None with a message if it cannot."""
        if not self._release_current():
            return None
        try:
            session = Session.open(path)
        except (SessionError, OSError) as exc:
            self._say(f"cannot open {path}: {exc}", error=True)
            return None
        self._use(session)
        self._say(f"resumed {session.path.name}: {len(session.rows)} rows, next row {session.next_row}")
        return session

    def _resume_chosen(self) -> None:
        path = self.resume_combo.currentData()
        if path:
            self.open_session(path)

    def _open_folder(self) -> None:
        path = self.ask_folder()
        if path:
            self.open_session(path)

    def _choose_root(self) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Sessions folder", str(self.root()))
        if path:
            widget = self.folder_form.widgets["root"]
            assert isinstance(widget, QtWidgets.QLineEdit)
            widget.setText(path)
            widget.editingFinished.emit()

    def _release_current(self) -> bool:
        """Close the open session before another is used; False if its pending rows must stay."""
        if self.session is None:
            return True
        if not self.resolve_pending():
            return False
        self.cancel_row()
        self.session.close()
        self.session = None
        return True

    def _use(self, session: Session) -> None:
        self.session = session
        self.table.show_rows(session.rows)
        self.warnings.setText("\n".join(f"⚠ {w}" for w in session.warnings))
        self.warnings.setVisible(bool(session.warnings))
        self.banner.setVisible(bool(session.pending))
        self.refresh_folders()
        self._update_state()
        self.sessionChanged.emit(session)

    # ---------------------------------------------------------------- logging
    def blocked_reason(self) -> str:
        """Why "Log row" cannot be pressed now ("" when it can)."""
        if self.session is None:
            return "open or create a session first"
        if self._collector is not None:
            return "collecting frames…"
        if not self.form.valid:
            bad = ", ".join(self.form.errors)
            return f"fix the marked field(s) first: {bad}"
        solver = self.session.info.solver
        ctx: BenchContext = self.context()
        if solver not in ctx.methods:
            return (
                f"this session measures with '{solver}', which is not running: choose it (or 'both') "
                "in Detect & solve"
            )
        return ""

    def context_notes(self) -> list[str]:
        """Differences between the session's recorded setup and the window's (shown, not blocking)."""
        if self.session is None:
            return []
        info, ctx = self.session.info, self.context()
        notes = []
        if abs(info.side_mm - ctx.side_mm) > 1e-9:
            notes.append(f"the app's QR side is {ctx.side_mm:g} mm, the session's {info.side_mm:g} mm")
        if info.camera.name != ctx.camera.name or info.camera.size != ctx.camera.size:
            notes.append(
                f"the app's camera is {ctx.camera.name} {ctx.camera.width}x{ctx.camera.height}, the "
                f"session's {info.camera.name} {info.camera.width}x{info.camera.height}"
            )
        return notes

    def log_row(self) -> bool:
        """Start collecting the next N frames for a row; False (with the reason shown) if it cannot."""
        reason = self.blocked_reason()
        if reason:
            self._say(f"cannot log: {reason}", error=self._collector is None)
            return False
        assert self.session is not None
        self._truth = self.form.truth()
        self._note = self.form.note.text()
        self._following = self.form.following
        self._collector = FrameCollector(self.session.info.frames_per_row, method=self.session.info.solver)
        self._t_press = time.monotonic()
        self.progress.setRange(0, self._collector.frames_wanted)
        self.progress.setValue(0)
        self._say(f"collecting {self._collector.frames_wanted} frames for row {self.session.next_row}…")
        self._update_state()
        return True

    def cancel_row(self) -> None:
        if self._collector is None:
            return
        self._collector = None
        self.progress.setValue(0)
        self._say("row cancelled: nothing logged")
        self._update_state()

    @property
    def collecting(self) -> bool:
        return self._collector is not None

    def on_processed(self, item: Any) -> None:
        """One result the window drew (ui.worker.Processed): follow the bench's truth, or collect it."""
        result = item.result
        collector = self._collector
        if collector is None:
            truth = getattr(result, "truth", None)
            if truth is not None:
                self.form.follow(truth.position_mm, truth.angles_deg)
            return
        if item.frame.t_capture < self._t_press:
            return  # captured before "Log row" was pressed
        done = collector.add(result)
        self.progress.setValue(collector.progress[0])
        if done:
            self._finish_row(collector)

    def _finish_row(self, collector: FrameCollector) -> None:
        assert self.session is not None and self._truth is not None
        self._collector = None
        truth = self._truth
        if self._following:
            truth = bench_mean_truth(collector.frames, truth.combo, collector.method) or truth
        measurement = collector.measurement(truth, self.session.info.criteria, note=self._note)
        try:
            outcome = self.session.log(measurement)
        except SessionError as exc:  # refused before anything is written (e.g. a note too long)
            self._say(f"row NOT logged: {exc}", error=True)
            self._update_state()
            return
        verdict = "pass" if measurement.judgement.passed else f"fail ({measurement.judgement.reason})"
        self._after(outcome, f"logged row {outcome.row}: {verdict}")
        if outcome.ok and outcome.row is not None:
            self.rowLogged.emit(outcome.row)

    def undo_row(self) -> None:
        """Withdraw the last row (after confirmation): a withdrawal record is appended, nothing deleted."""
        session = self.session
        if session is None or self._collector is not None:
            return
        last = next((r for r in reversed(session.rows) if not r.withdrawn), None)
        if last is None:
            self._say("nothing to undo")
            return
        if not self.ask_confirm(
            "Withdraw row", f"Withdraw row {last.number}? Its line stays in rows.csv, marked withdrawn."
        ):
            return
        outcome = session.withdraw(last.number)
        self._after(outcome, f"withdrew row {last.number}")

    def retry(self) -> LogOutcome | None:
        if self.session is None:
            return None
        outcome = self.session.retry()
        self._after(outcome, outcome.message)
        for label in outcome.logged:
            if label.isdigit():
                self.rowLogged.emit(int(label))
        return outcome

    def export_pending(self) -> int:
        """Save the pending rows to a file the operator chooses; they stay pending here too."""
        if self.session is None or not self.session.pending:
            return 0
        path = self.ask_save_path()
        if not path:
            return 0
        try:
            count = self.session.export_pending(path)
        except OSError as exc:
            self._say(f"could not save the pending rows to {path}: {exc}", error=True)
            return 0
        self._say(f"saved {count} pending record(s) to {path} (they are still retried here)")
        return count

    def _after(self, outcome: LogOutcome, success: str) -> None:
        self.table.refresh()
        if outcome.ok:
            self.banner.setVisible(bool(self.session and self.session.pending))
            self._say(success)
        else:
            self.banner_text.setText(outcome.message)
            self.banner.show()
            self._say(outcome.message, error=True)
            self.rowPending.emit(outcome.message)
        self._update_state()

    # ---------------------------------------------------------------- closing
    def resolve_pending(self) -> bool:
        """Before closing: ask Retry / Save elsewhere / Discard for pending rows. True = may close."""
        while self.session is not None and self.session.pending:
            n = len(self.session.pending)
            choice = self.ask_pending_choice(
                f"{n} record(s) of session {self.session.path.name} are not written to rows.csv "
                f"({self.banner_text.text() or 'the last write failed'}). Retry, save them elsewhere, "
                "or discard them?"
            )
            if choice == "retry":
                self.retry()
            elif choice == "save":
                if self.export_pending():
                    return True
            else:
                return choice == "discard"  # "cancel": keep the app (and the rows) open
        return True

    def confirm_close(self) -> bool:
        """The window is closing: cancel a row being collected and resolve pending rows."""
        self.cancel_row()
        return self.resolve_pending()

    def shutdown(self) -> None:
        self._collector = None
        if self.session is not None:
            self.session.close()

    # ---------------------------------------------------------------- state
    def _say(self, text: str, error: bool = False) -> None:
        self.status.setText(text)
        self.status.setStyleSheet("color: #c0392b; font-weight: bold;" if error else "color: #1d6b1d;")

    def _update_state(self) -> None:
        session = self.session
        collecting = self._collector is not None
        reason = self.blocked_reason()
        self.log_button.setEnabled(not reason)
        self.cancel_button.setEnabled(collecting)
        self.form.setEnabled(not collecting)
        self.undo_button.setEnabled(
            session is not None and not collecting and any(not r.withdrawn for r in session.rows)
        )
        notes = self.context_notes()
        self.why.setText("\n".join([reason, *(f"⚠ {n}" for n in notes)]).strip() if not collecting else "")
        if session is None:
            self.title.setText("no session open: create one or resume one")
            self.count.setText("")
            return
        info = session.info
        self.title.setText(f"session {info.name}  ({session.path})")
        withdrawn = sum(1 for r in session.rows if r.withdrawn)
        active = [r for r in session.rows if not r.withdrawn]
        passed = sum(1 for r in active if r.passed)
        self.count.setText(
            f"{len(active)} rows ({passed} pass), {withdrawn} withdrawn, next row {session.next_row}; "
            f"solver {info.solver}, {info.frames_per_row} frames per row, QR side {info.side_mm:g} mm"
            + (f"; {len(session.pending)} NOT WRITTEN" if session.pending else "")
        )

    def refresh_state(self) -> None:
        """Re-check what may be logged (the window's method or camera changed)."""
        self._update_state()
