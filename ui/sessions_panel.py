"""The Session tab: the session bar (New, Resume, Export, the open session's name, folder and rows),
the ground-truth form, "Log row" / Cancel / Undo, and the rows table, laid out to fit 800x480.

A thin layer over :mod:`qrfield.sessions`. "Log row" arms the core's one row recorder
(:class:`qrfield.sessions.recorder.RowRecorder`, which ``qrfield session log`` and the guide use
too): a sink of the worker's frame loop, it collects the next N frames the loop processes (every
one, not only those the window draws; only frames captured after the press count), averages and
judges them for the session's solver and criteria. The panel shows its progress on its timer and
on each redraw, and logs the finished row with :meth:`Session.log` on the GUI thread (one append
and fsync per row). When the form follows the virtual bench, the row's ground truth is the bench's
mean true pose over the frames collected (a wobbling bench moves while the row is measured). The
status says "logged row K" only when ``log`` returned "logged"; a row that could not be written
stays in the session's pending queue and a red banner offers Retry and "Save pending elsewhere…".

Frames must be arriving: "Log row" is disabled, with the reason, while no frame has come for
``frame_timeout_s`` (no source, a source that failed or stalled), and a row being collected is
given up, nothing logged, when frames stop for that long or the source fails. A row whose
combination label disagrees with the signs of its angles is logged only after the operator says
so (:meth:`ask_combo_choice`). At start the window offers to reopen the last session
(:meth:`offer_reopen`, a banner: no dialog in the way).

Guided logging (a session that follows a plan: *Plan…* attaches one, a resumed session brings its
own): the guide strip (:mod:`ui.guide_panel`) shows the current target, the live difference to it
and whether the card is still, and the form holds the target's pose (editable before logging,
e.g. when the jig reads differently). Its rows are measured by the core's
:class:`qrfield.sessions.guide.Guide`, which the window hands every result of the frame loop to
(a sink on the worker's thread: every frame, not the ones drawn); "Log target" (or Enter) asks it
for a row now, "log when still" lets it log by itself (:mod:`qrfield.sessions.guide` says when),
and each finished row is entered in the plan's progress and logged here on the GUI thread, then
the next target to do is shown. Skip leaves a target; choosing a target with a row and logging it
again withdraws its old row first (after a question): a redo.

Dialogs go through small methods (:meth:`ask_confirm`, :meth:`ask_pending_choice`,
:meth:`ask_save_path`, :meth:`ask_export_path`, :meth:`ask_folder`, :meth:`ask_combo_choice`,
:meth:`ask_plan_path`) so that tests can answer them.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

from qrfield.camera import CameraModel
from qrfield.handeye.setups import CAMERA
from qrfield.methods import NUMERICAL
from qrfield.sessions import (
    LogOutcome,
    Session,
    SessionError,
    SessionSettings,
    known_combinations,
    read_session,
)
from qrfield.sessions.combo_signs import sign_table
from qrfield.sessions.export import DEFAULT_NAME, export_session
from qrfield.sessions.guide import Guide, GuideSettings
from qrfield.sessions.plan import PlanError, PlanTarget, read_plan
from qrfield.sessions.progress import DONE, PlanProgress, attach_plan
from qrfield.sessions.recorder import RecordedRow, RowRecorder
from qrfield.sessions.stillness import StillnessSettings
from qrfield.settings import SettingError
from ui.groundtruth_form import FIELD_NAMES, ElidedLabel, GroundTruthForm, WrappedLabel
from ui.guide_panel import GuidePanel
from ui.rows_table import RowsTable
from ui.session_dialogs import (
    ENV_ROOT,
    NewSessionDialog,
    ResumeDialog,
    SessionFolderSettings,
    sessions_root,
    touch_button,
)
from ui.text import short_path
from ui.touch import FOLDER, SAVE, answer, ask_path, message_box, yes_no

__all__ = ["ENV_ROOT", "BenchContext", "SessionFolderSettings", "SessionPanel", "sessions_root"]

#: Config key of the last session used (offered again at the next start).
LAST_SESSION_KEY = "last_session"
#: How often the panel re-checks that frames arrive (ms).
LIVENESS_MS = 250
#: Colours of the status line by kind of message.
STATUS_STYLES = {
    "ok": "color: #1d6b1d;",
    "fail": "color: #a05000; font-weight: bold;",
    "error": "color: #c0392b; font-weight: bold;",
    "info": "color: #444;",
}


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
        #: The one row recorder (a sink the window adds to the worker's frame loop: every frame).
        self.recorder = RowRecorder()
        self._last_frame_t: float | None = None  # monotonic time of the last frame drawn
        self._last_pose_t: float | None = None  # ... of the last one with a pose of the session's solver
        self._source_problem = ""  # why the source gave no frames (it failed), "" while it runs
        self._reopen_path = ""
        self._last_session = str(store.value(LAST_SESSION_KEY) or "")
        #: The guided experiment: the core's guide (a frame sink the window feeds with every
        #: result), the open session's plan and the target shown (None without a plan).
        self.stillness_settings = store.group("stillness", StillnessSettings)
        self.guide_settings = store.group("guide", GuideSettings)
        self.guide = Guide(NUMERICAL, stillness=self.stillness_settings, settings=self.guide_settings)
        self.plan: PlanProgress | None = None
        self.target: PlanTarget | None = None
        self._guide_row = 0  # the row number a guided row being collected will get

        self.new_dialog = NewSessionDialog(store, self)
        self.resume_dialog = ResumeDialog(self.root, lambda: self.ask_folder(), self)
        self._build_session_bar()
        self._build_banners()
        self._build_row_box()
        self.guide_panel = GuidePanel()
        self.guide_panel.hide()
        self.table = RowsTable()
        # The part that gives way: at 800x480 with a plan and the pending-rows banner, the banner and
        # every button stay whole and the table shrinks to a few pixels (it scrolls inside itself).
        self.table.setMinimumHeight(16)
        self._build_layout()
        self._wire()
        self.timer = QtCore.QTimer(self)  # frames still arriving? (tick)
        self.timer.timeout.connect(self.tick)
        self.timer.start(LIVENESS_MS)
        self._update_state()

    # ---------------------------------------------------------------- builders
    def _build_layout(self) -> None:
        """Top to bottom: the session bar and its two one-line labels, the guide strip, the form
        and the actions; then, in one place below every button but the banners', the banners and
        the messages (status, why Log row is blocked, the form's, the guide's, the session's
        warnings), whose coming and going moves only the rows table (the part that scrolls)."""
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.setSpacing(2)
        layout.addLayout(self.session_bar)
        for widget in (self.title, self.count, self.guide_panel, self.form):
            layout.addWidget(widget)
        layout.addLayout(self.actions)
        self.messages = (
            self.status,
            self.why,
            *self.form.messages,
            self.guide_panel.note,
            self.warnings,
        )
        for widget in (self.reopen_banner, self.banner, *self.messages):
            layout.addWidget(widget)
        layout.addWidget(self.table, 1)

    def _build_session_bar(self) -> None:
        self.new_button = touch_button("New session…", "new_session")
        self.resume_button = touch_button("Resume…", "resume")
        self.export_button = touch_button("Export…", "export_rows")
        self.export_button.setToolTip(
            "write the rows in force (withdrawn rows left out) to a CSV with units in the column names"
        )
        self.plan_button = touch_button("Plan…", "load_plan")
        self.plan_button.setToolTip(
            "follow an experiment plan (qrfield plan): the Session tab guides to each target in turn"
        )
        self.session_bar = QtWidgets.QHBoxLayout()
        self.session_bar.addWidget(self.new_button)
        self.session_bar.addWidget(self.resume_button)
        self.session_bar.addStretch(1)
        self.session_bar.addWidget(self.plan_button)
        self.session_bar.addWidget(self.export_button)
        self.title = ElidedLabel("")
        self.title.setObjectName("session_title")
        self.title.setStyleSheet("font-weight: bold;")
        self.count = ElidedLabel("")
        self.count.setObjectName("session_count")
        self.count.setStyleSheet("color: #444;")

    def _build_banners(self) -> None:
        self.reopen_text = WrappedLabel("")
        self.reopen_button = touch_button("Reopen", "reopen_last")
        self.reopen_no = touch_button("Not now", "reopen_no")
        self.reopen_banner = _banner(
            "reopen_banner", self.reopen_text, (self.reopen_button, self.reopen_no), "#e8f0fb"
        )
        self.warnings = WrappedLabel("")
        self.warnings.setObjectName("session_warnings")
        self.warnings.setStyleSheet("color: #a05000;")
        self.warnings.hide()
        self.banner_text = WrappedLabel("")
        self.banner_text.setStyleSheet("color: white; font-weight: bold;")
        self.retry_button = touch_button("Retry", "retry_pending")
        self.pending_button = touch_button("Save pending…", "export_pending")
        self.pending_button.setToolTip("save the rows not yet written to another file (another drive)")
        self.banner = _banner(
            "pending_banner", self.banner_text, (self.retry_button, self.pending_button), "#a01818"
        )

    def _build_row_box(self) -> None:
        table = sign_table()
        self.form = GroundTruthForm(known_combinations(), signs=table)
        self.log_button = touch_button("Log row", "log_row")
        self.log_button.setToolTip("collect the session's frames per row and log their mean")
        self.cancel_button = touch_button("Cancel", "cancel_row")
        self.undo_button = touch_button("Undo…", "undo_row")
        self.undo_button.setToolTip("withdraw the last row (its line stays in rows.csv, marked withdrawn)")
        self.progress = QtWidgets.QProgressBar()
        self.progress.setObjectName("row_progress")
        self.progress.setMinimumWidth(70)
        self.progress.setRange(0, SessionSettings().frames_per_row)
        self.progress.setValue(0)
        self.actions = QtWidgets.QHBoxLayout()
        self.actions.addWidget(self.log_button)
        self.actions.addWidget(self.cancel_button)
        self.actions.addWidget(self.progress, 1)
        self.actions.addWidget(self.undo_button)
        self.why = WrappedLabel("")
        self.why.setObjectName("log_blocked_reason")
        self.why.setStyleSheet("color: #555;")
        self.status = WrappedLabel("")
        self.status.setObjectName("session_status")

    def _wire(self) -> None:
        self.new_button.clicked.connect(self.show_new_dialog)
        self.resume_button.clicked.connect(self.show_resume_dialog)
        self.export_button.clicked.connect(self.export_rows)
        self.new_dialog.createRequested.connect(self.create_from_form)
        self.resume_dialog.resumeRequested.connect(self._resume_requested)
        self.reopen_button.clicked.connect(self.reopen_last)
        self.reopen_no.clicked.connect(lambda: self.reopen_banner.hide())
        self.log_button.clicked.connect(self.log_row)
        self.form.submitted.connect(self.log_row)
        self.form.changed.connect(self._update_state)
        self.cancel_button.clicked.connect(self.cancel_row)
        self.undo_button.clicked.connect(self.undo_row)
        self.retry_button.clicked.connect(self.retry)
        self.pending_button.clicked.connect(self.export_pending)
        self.plan_button.clicked.connect(self.choose_plan)
        self.guide_panel.targetChosen.connect(self.choose_target)
        self.guide_panel.skipRequested.connect(self.skip_target)
        self.guide_panel.autoToggled.connect(lambda _on: self._sync_guide())
        self.form.changed.connect(self._sync_guide)
        self.form.note.textChanged.connect(lambda _text: self._sync_guide())

    # ---------------------------------------------------------------- settings
    def root(self) -> Path:
        return self.new_dialog.root()

    # The New session form's parts, under the names the panel had when the form was inline.
    @property
    def name_edit(self) -> QtWidgets.QLineEdit:
        return self.new_dialog.name_edit

    @property
    def operator_edit(self) -> QtWidgets.QLineEdit:
        return self.new_dialog.operator_edit

    @property
    def row_settings(self) -> Any:
        return self.new_dialog.row_settings

    @property
    def criteria_form(self) -> Any:
        return self.new_dialog.criteria_form

    @property
    def create_button(self) -> QtWidgets.QPushButton:
        return self.new_dialog.create_button

    def frame_timeout_s(self) -> float:
        return float(self.row_settings.value().frame_timeout_s)

    def save_settings(self, store: Any) -> None:
        store.set_group("stillness", self.stillness_settings)
        store.set_group("guide", self.guide_settings)
        store.set_group("session_folder", self.new_dialog.folder_form.value())
        store.set_group("session", self.row_settings.value())
        store.set_group("criteria", self.criteria_form.value())
        current = str(self.session.path) if self.session is not None else self._last_session
        store.set_value(LAST_SESSION_KEY, current)

    def set_default_solver(self, methods: tuple[str, ...]) -> None:
        """Preselect the solver of a new session: the thesis' model when it runs, else the one that runs."""
        self.new_dialog.solver_combo.setCurrentText(
            NUMERICAL if NUMERICAL in methods or not methods else methods[0]
        )

    # ---------------------------------------------------------------- dialogs (tests replace these)
    def ask_confirm(self, title: str, text: str) -> bool:
        return answer(*yes_no(self, title, text), "no") == "yes"

    def pending_choice_box(self, message: str) -> tuple[QtWidgets.QMessageBox, dict[str, Any]]:
        """The question of :meth:`ask_pending_choice`, not run (tests measure it)."""
        role = QtWidgets.QMessageBox.ButtonRole
        buttons = [
            ("retry", "Retry", role.AcceptRole),
            ("save", "Save elsewhere…", role.ActionRole),
            ("discard", "Discard them", role.DestructiveRole),
            ("cancel", "Keep the app open", role.RejectRole),
        ]
        return message_box(self, "Rows not written", message, buttons, QtWidgets.QMessageBox.Icon.Warning)

    def ask_pending_choice(self, message: str) -> str:
        """'retry', 'save', 'discard' or 'cancel' (keep the app open)."""
        return answer(*self.pending_choice_box(message), "cancel")

    def combo_choice_box(
        self, message: str, suggestion: str | None
    ) -> tuple[QtWidgets.QMessageBox, dict[str, Any]]:
        """The question of :meth:`ask_combo_choice`, not run (tests measure it)."""
        role = QtWidgets.QMessageBox.ButtonRole
        buttons = [("keep", "Log as labelled", role.AcceptRole)]
        if suggestion:
            buttons.append(("use", f"Use '{suggestion}'", role.ActionRole))
        buttons.append(("cancel", "Cancel", role.RejectRole))
        text = f"{message[0].upper()}{message[1:]}.\n\nLog the row anyway?"
        return message_box(self, "Combination and angles disagree", text, buttons)

    def ask_combo_choice(self, message: str, suggestion: str | None) -> str:
        """'keep' (log as labelled), 'use' (relabel with ``suggestion``) or 'cancel'."""
        return answer(*self.combo_choice_box(message, suggestion), "cancel")

    def ask_save_path(self) -> str:
        default = Path.home() / "qrfield-pending-rows.csv"
        return ask_path(self, "Save pending rows elsewhere", default, mode=SAVE, name_filter="CSV (*.csv)")

    def ask_export_path(self, default: Path) -> str:
        return ask_path(self, "Export the rows in force", default, mode=SAVE, name_filter="CSV (*.csv)")

    def ask_folder(self) -> str:
        return ask_path(self, "Open a session folder", self.root(), mode=FOLDER)

    def ask_plan_path(self) -> str:
        plans = "Plans (*.csv);;All files (*)"
        return ask_path(self, "Follow an experiment plan", self.root(), name_filter=plans)

    # ---------------------------------------------------------------- open / create
    def show_new_dialog(self) -> NewSessionDialog:
        self.new_dialog.say("")
        self.new_dialog.open()
        self.new_dialog.name_edit.setFocus()
        return self.new_dialog

    def show_resume_dialog(self) -> ResumeDialog:
        self.resume_dialog.say("")
        self.resume_dialog.refresh()
        self.resume_dialog.open()
        return self.resume_dialog

    def create_from_form(self) -> Session | None:
        """Create a session from the New session form and the window's context; an error stays in
        the form (and the status line), the form closes when the session is made."""
        if not self._release_current():
            return None
        ctx: BenchContext = self.context()
        dialog = self.new_dialog
        solver = dialog.solver_combo.currentText()
        try:
            session = Session.create(
                self.root(),
                dialog.name_edit.text(),
                camera=ctx.camera,
                side_mm=ctx.side_mm,
                solver=solver,
                solver_settings=ctx.solver_settings.get(solver),
                criteria=dialog.criteria_form.value(),
                frames_per_row=dialog.row_settings.value().frames_per_row,
                operator=dialog.operator_edit.text(),
                notes=dialog.notes_edit.toPlainText(),
            )
        except (SessionError, SettingError, OSError) as exc:
            dialog.say(f"cannot create the session: {exc}")
            self._say(f"cannot create the session: {exc}", "error")
            return None
        dialog.accept()
        self._use(session)
        self._say(f"created session {session.path.name}", "ok")
        return session

    def open_session(self, path: str | os.PathLike[str]) -> Session | None:
        """Resume the session in ``path`` (its warnings are shown); None with a message if it cannot."""
        if not self._release_current():
            return None
        try:
            session = Session.open(path)
            if session.info.pose_frame != CAMERA:
                # The app measures and logs in the camera frame: its rows would not be the session's.
                frame = session.info.pose_frame
                session.close()
                raise SessionError(
                    f"its rows are in the {frame} frame (qrfield session new --frame {frame}); the app logs "
                    f"in the camera frame: log them with qrfield session log"
                )
        except (SessionError, OSError) as exc:
            self.resume_dialog.say(f"cannot open {path}: {exc}")
            self._say(f"cannot open {path}: {exc}", "error")
            return None
        self.resume_dialog.accept()
        self._use(session)
        self._say(f"resumed {session.path.name}: {len(session.rows)} rows, next row {session.next_row}", "ok")
        return session

    def _resume_requested(self, path: str) -> None:
        self.open_session(path)

    def offer_reopen(self) -> bool:
        """Offer (a banner, not a dialog) to reopen the session used last; False if there is none."""
        path = self._last_session
        if self.session is not None or not path:
            return False
        try:
            info, content = read_session(path)
        except (SessionError, OSError):
            return False
        rows = sum(1 for r in content.rows if not r.withdrawn)
        self._reopen_path = path
        self.reopen_text.setText(f"Reopen the last session, {info.name} ({rows} rows)?")
        self.reopen_banner.setToolTip(path)
        self.reopen_banner.show()
        return True

    def reopen_last(self) -> Session | None:
        self.reopen_banner.hide()
        return self.open_session(self._reopen_path) if self._reopen_path else None

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
        self._last_session = str(session.path)
        self.reopen_banner.hide()
        self.table.show_rows(session.rows)
        self.warnings.setText("\n".join(f"⚠ {w}" for w in session.warnings))
        self.warnings.setVisible(bool(session.warnings))
        self.banner.setVisible(bool(session.pending))
        self.progress.setRange(0, session.info.frames_per_row)
        self.progress.setValue(0)
        info = session.info
        self.guide.configure(method=info.solver, criteria=info.criteria, frames_per_row=info.frames_per_row)
        plan = None
        try:
            plan = PlanProgress.load(session.path, session.rows)
        except (PlanError, SessionError, OSError) as exc:
            self._add_warning(f"the session's plan cannot be read ({exc}); logging without it")
        self._use_plan(plan)
        self._update_state()
        self.sessionChanged.emit(session)

    def _add_warning(self, text: str) -> None:
        shown = [line for line in self.warnings.text().split("\n") if line]
        self.warnings.setText("\n".join([*shown, f"⚠ {text}"]))
        self.warnings.show()

    # ---------------------------------------------------------------- guided experiments
    @property
    def guided(self) -> bool:
        """The open session follows a plan (the guide strip is shown)."""
        return self.session is not None and self.plan is not None

    def choose_plan(self) -> PlanProgress | None:
        """*Plan…*: the operator picks a plan file for the open session."""
        path = self.ask_plan_path()
        return self.load_plan(path) if path else None

    def load_plan(self, path: str | os.PathLike[str]) -> PlanProgress | None:
        """Attach the plan in ``path`` to the open session and guide to its first target to do;
        None, with every problem of the file named, when it cannot be used."""
        session = self.session
        if session is None:
            self._say("open a session first: New session… or Resume…", "error")
            return None
        if self.collecting:
            self._say("wait for the row being collected (or Cancel it) first", "error")
            return None
        try:
            targets = read_plan(path)
            plan = attach_plan(session.path, targets, session.rows, source=str(path))
        except PlanError as exc:
            shown = exc.problems[:6] + (
                [f"… and {len(exc.problems) - 6} more"] if len(exc.problems) > 6 else []
            )
            self._say("plan not used:\n" + "\n".join(shown), "error")
            return None
        except (SessionError, OSError) as exc:
            self._say(f"plan not used: {exc}", "error")
            return None
        self._use_plan(plan)
        counts = plan.counts(session.rows)
        self._say(
            f"following {Path(path).name}: {len(plan.targets)} targets, {counts['done']} done, "
            f"{counts['todo']} to do",
            "ok",
        )
        self._update_state()
        return plan

    def _use_plan(self, plan: PlanProgress | None) -> None:
        self.plan = plan
        self.guide.cancel()
        if plan is None or self.session is None:
            self.guide_panel.hide()
            self.target = None
            self.guide.set_target(None)
            self.guide.set_auto(False)
            return
        for warning in plan.warnings:
            self._add_warning(warning)
        self.guide_panel.show()
        self.form.bench_gone()  # the ground truth is the target's, not the bench's
        self.go_to(plan.next_target(self.session.rows))

    def go_to(self, target: PlanTarget | None) -> None:
        """Show ``target`` (None: every target has a row): the chooser, the form, the guide."""
        self.target = target
        if target is not None:
            with QtCore.QSignalBlocker(self.form.note):
                self.form.note.setText(target.note)
            self.form.set_fields(target.truth.as_fields())
        self.guide.set_target(
            target, self.form.truth() if target is not None else None, self.form.note.text()
        )
        self._show_targets()
        self._sync_guide()
        self._update_state()

    def _show_targets(self) -> None:
        if self.plan is None or self.session is None:
            return
        states = self.plan.states(self.session.rows)
        self.guide_panel.show_targets(states, self.target.number if self.target is not None else None)

    def choose_target(self, number: int) -> None:
        """The operator chose a target in the strip (to visit or redo it)."""
        if self.plan is None or self.collecting:
            self._show_targets()
            return
        self.go_to(self.plan.target(number))

    def skip_target(self) -> None:
        """Leave the current target (its state says skipped) and go to the next one to do."""
        if self.plan is None or self.target is None or self.session is None or self.collecting:
            return
        skipped = self.target.number
        try:
            self.plan.skip(skipped)
        except OSError as exc:
            self._say(f"cannot save the plan's progress: {exc}", "error")
            return
        self.go_to(self.plan.next_target(self.session.rows, after=skipped))
        self._say(f"skipped target {skipped}", "info")

    def _sync_guide(self) -> None:
        """The form's truth and note to the guide; "log when still" only with a good form."""
        if not self.guided:
            return
        truth = self.form.truth()
        self.guide.set_truth(truth, self.form.note.text())
        auto = self.guide_panel.auto_box.isChecked() and truth is not None and not self.form.mismatch()
        self.guide.set_auto(auto and self.target is not None and not self._redo_rows())

    def _redo_rows(self) -> tuple[int, ...]:
        """The rows in force of the current target (a new row for it is a redo)."""
        if self.plan is None or self.target is None or self.session is None:
            return ()
        state = self.plan.states(self.session.rows)[self.target.number - 1]
        return state.rows if state.state == DONE else ()

    def log_target(self) -> bool:
        """ "Log target": ask the guide for a row of the current target now (the next N frames)."""
        reason = self.blocked_reason()
        if reason:
            if self.session is not None and not self.form.valid:
                self.form.reveal_errors()
                reason = self.blocked_reason()
            self._say(f"cannot log: {reason}", "error")
            return False
        assert self.session is not None and self.target is not None
        if not self._combination_confirmed():
            return False
        redo = self._redo_rows()
        if redo:
            rows = ", ".join(str(r) for r in redo)
            if not self.ask_confirm(
                "Redo target",
                f"Target {self.target.number} has row {rows}. Withdraw it and log the target again?",
            ):
                return False
            for number in redo:
                outcome = self.session.withdraw(number, f"redo of target {self.target.number}")
                self._after(outcome, f"withdrew row {number}", "ok")
        self._sync_guide()
        if not self.guide.arm():
            self._say("the guide is collecting a row already", "info")
            return False
        return self._collecting(self.session.info.frames_per_row, f"target {self.target.number}")

    def _take_guided_rows(self) -> None:
        """Log the rows the guide finished (GUI thread), then show the next target to do."""
        session = self.session
        if session is None:
            self.guide.take()
            return
        view = self.guide.view()
        if view.collecting is not None:
            self.progress.setValue(view.collecting[0])
        for row in self.guide.take():
            target = row.target
            if self.plan is not None and target is not None:
                try:
                    self.plan.will_log(target.number, session.next_row)
                except OSError as exc:
                    self._add_warning(
                        f"the plan's progress cannot be saved ({exc}); the row is logged anyway"
                    )
            try:
                outcome = session.log(row.measurement)
            except SessionError as exc:
                self._say(f"row NOT logged: {exc}", "error")
                continue
            self.progress.setValue(0)
            self.form.note.clear()  # the next target brings its own note
            j = row.measurement.judgement
            verdict = "pass" if j.passed else f"fail ({j.reason})"
            where = f" (target {target.number})" if target is not None else ""
            self._after(outcome, f"logged row {outcome.row}{where}: {verdict}", "ok" if j.passed else "fail")
            if outcome.ok and outcome.row is not None:
                self.rowLogged.emit(outcome.row)
            if self.plan is not None and target is not None and self.target == target:
                self.go_to(self.plan.next_target(session.rows, after=target.number))

    # ---------------------------------------------------------------- frames
    def source_opened(self) -> None:
        """The window's source opened: frames may come again."""
        self._source_problem = ""
        self._update_state()

    def source_lost(self, message: str) -> None:
        """The window's source failed: no frames until it is reopened; a row being collected ends."""
        self._source_problem = message
        self.form.bench_gone()
        ended = self.recorder.give_up(f"the source failed while collecting ({message})")
        if ended is not None:
            self._given_up(ended)
        self._update_state()

    def measuring_changed(self, what: str) -> None:
        """``what`` (e.g. "the QR side") changed in Setup: the frames after it are measured
        differently, so a row being collected ends (nothing logged, the reason shown) instead of
        averaging frames of both settings into one row. Nothing happens between rows."""
        ended = self.recorder.give_up(f"{what} changed while collecting")
        if ended is not None:
            self._given_up(ended)
            return
        if self.guided and self.collecting and self.guide.cancel():
            self.progress.setValue(0)
            self._say(
                f"target row not logged: {what} changed while collecting; press Log target again", "error"
            )
            self._update_state()

    def live_reason(self, now: float | None = None) -> str:
        """Why no live frames arrive ("" while they do)."""
        now = time.monotonic() if now is None else now
        if self._source_problem:
            return "no frames: the source is closed (see the red banner)"
        if self._last_frame_t is None:
            return "no frames yet: open a source (Setup › Source)"
        quiet = now - self._last_frame_t
        if quiet > self.frame_timeout_s():
            return f"no frame for {quiet:.0f} s: is the source still running?"
        return ""

    def tick(self) -> None:
        """Every LIVENESS_MS: give up a row whose frames stopped; log the guide's rows; re-check what
        may be logged."""
        if self.guided:
            self._take_guided_rows()
        self._poll_row()
        if (self.blocked_reason(), self.context_notes()) != self._shown_state:
            self._update_state()

    def on_processed(self, item: Any) -> None:
        """One result the window drew (ui.worker.Processed): the bench's truth followed in the form
        and whether frames arrive; the row recorder's and the guide's progress (both fed every
        result by the frame loop) shown, and their finished rows logged."""
        result = item.result
        self._last_frame_t = time.monotonic()
        pose = result.poses.get(self.session.info.solver) if self.session is not None else None
        if pose is not None and pose.converged:  # a hint ("a row now fails"), not the average's test
            self._last_pose_t = self._last_frame_t
        if self.guided:
            self._take_guided_rows()
            self.guide_panel.show_view(self.guide.view())
            return
        if self.recorder.collecting:
            self._poll_row()
            return
        truth = getattr(result, "truth", None)
        if truth is not None:
            self.form.follow(truth.position_mm, truth.angles_deg)
        else:
            self.form.bench_gone()
        self._poll_row()  # a row that ended since the last redraw

    # ---------------------------------------------------------------- logging
    def blocked_reason(self) -> str:
        """Why "Log row" cannot be pressed now ("" when it can)."""
        if self.session is None:
            return "open a session first: New session… or Resume…"
        if self.collecting:
            return "collecting frames…"
        if self.guided and self.target is None:
            return "every target of the plan has a row (choose one in the list to redo it)"
        if not self.form.valid:
            shown = self.form.shown_errors()
            if shown:
                return "fix " + ", ".join(FIELD_NAMES[n] for n in shown) + " first"
            return "type the ground truth: " + ", ".join(FIELD_NAMES[n] for n in self.form.untouched_errors())
        solver = self.session.info.solver
        ctx: BenchContext = self.context()
        if solver not in ctx.methods:
            return (
                f"this session measures with '{solver}', which is not running: choose it (or 'both') "
                "in Setup › Detect & solve"
            )
        return self.live_reason()

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
        if self._last_frame_t is not None and not self.live_reason():
            last_pose = self._last_pose_t or 0.0
            if self._last_frame_t - last_pose > self.frame_timeout_s():
                notes.append(
                    f"no '{info.solver}' pose in the last frames: a row now is a fail (no converged frame)"
                )
        return notes

    def log_row(self) -> bool:
        """Start collecting the next N frames for a row; False (with the reason shown) if it cannot.
        With a plan: the row of the current target, measured by the guide (:meth:`log_target`)."""
        if self.guided:
            return self.log_target()
        reason = self.blocked_reason()
        if reason:
            if self.session is not None and not self.form.valid:
                self.form.reveal_errors()
                reason = self.blocked_reason()
            self._say(f"cannot log: {reason}", "info" if self.recorder.collecting else "error")
            return False
        assert self.session is not None
        if not self._combination_confirmed():
            return False
        info = self.session.info
        truth = self.form.truth()
        assert truth is not None  # the form is valid (blocked_reason)
        if not self.recorder.arm(
            truth,
            info.frames_per_row,
            method=info.solver,
            criteria=info.criteria,
            note=self.form.note.text(),
            follow_bench=self.form.following,
            frame_timeout_s=self.frame_timeout_s(),
        ):
            self._say("a row is being collected already", "info")
            return False
        return self._collecting(info.frames_per_row, f"row {self.session.next_row}")

    def _collecting(self, frames: int, what: str) -> bool:
        """A row is being collected: the progress bar at 0 of ``frames``, the status says so."""
        self.progress.setRange(0, frames)
        self.progress.setValue(0)
        self._say(f"collecting {frames} frames for {what}…", "info")
        self._update_state()
        return True

    def _combination_confirmed(self) -> bool:
        """True when the label agrees with the angles' signs, or the operator chose to log it anyway
        (or to relabel it with the combination the signs fit)."""
        mismatch = self.form.mismatch()
        if not mismatch:
            return True
        suggestion = self.form.suggestion()
        choice = self.ask_combo_choice(mismatch, suggestion)
        if choice == "use" and suggestion:
            self.form.combo.setCurrentText(suggestion)
            return True
        if choice == "keep":
            return True
        self._say(f"not logged: {mismatch}", "info")
        return False

    def cancel_row(self) -> None:
        guided, plain = self.guide.cancel(), self.recorder.cancel()
        if not (guided or plain):
            return
        self.progress.setValue(0)
        self._say("row cancelled: nothing logged", "info")
        self._update_state()

    def _given_up(self, row: RecordedRow) -> None:
        """The recorder ended a row without a measurement (frames stopped, the source failed, no
        bench truth): log nothing, say why."""
        self.progress.setValue(0)
        number = self.session.next_row if self.session is not None else "?"
        why = row.problem
        if row.stopped:
            why += f" ({row.frames_in} of {row.frames_wanted} frames came); press Log row again"
        self._say(f"row {number} not logged: {why}", "error")
        self._update_state()

    @property
    def collecting(self) -> bool:
        """A row is being collected (by "Log row", or by the guide for a target)."""
        if self.recorder.collecting:
            return True
        view = self.guide.view() if self.guided else None
        return view is not None and (view.collecting is not None or view.waiting)

    def _poll_row(self) -> None:
        """The recorder's row (GUI thread): its progress on the bar, a finished row logged, a row
        whose frames stopped for the frame timeout given up."""
        ended = self.recorder.expire()
        if ended is not None:
            self._given_up(ended)
        progress = self.recorder.progress
        if progress is not None:
            self.progress.setValue(progress[0])
        for row in self.recorder.take():
            if row.measurement is None:
                self._given_up(row)
            else:
                self._finish_row(row.measurement)

    def _finish_row(self, measurement: Any) -> None:
        assert self.session is not None
        try:
            outcome = self.session.log(measurement)
        except SessionError as exc:  # refused before anything is written (e.g. a note too long)
            self._say(f"row NOT logged: {exc}", "error")
            self._update_state()
            return
        self.progress.setValue(0)
        self.form.note.clear()  # a note belongs to its row: the next one starts without it
        passed = measurement.judgement.passed
        verdict = "pass" if passed else f"fail ({measurement.judgement.reason})"
        average = measurement.average
        misfit = (
            f"; ⚠ {average.n_misfit} of its {average.n_converged} frames misfit their corners "
            "(check the camera model and the QR side)"
            if average.mostly_misfit
            else ""
        )
        kind = "ok" if passed and not misfit else "fail"
        self._after(outcome, f"logged row {outcome.row}: {verdict}{misfit}", kind)
        if outcome.ok and outcome.row is not None:
            self.rowLogged.emit(outcome.row)

    def undo_row(self) -> None:
        """Withdraw the last row (after confirmation): a withdrawal record is appended, nothing deleted."""
        session = self.session
        if session is None or self.recorder.collecting:
            return
        last = next((r for r in reversed(session.rows) if not r.withdrawn), None)
        if last is None:
            self._say("nothing to undo", "info")
            return
        if not self.ask_confirm(
            "Withdraw row", f"Withdraw row {last.number}? Its line stays in rows.csv, marked withdrawn."
        ):
            return
        outcome = session.withdraw(last.number)
        self._after(outcome, f"withdrew row {last.number}", "ok")

    def retry(self) -> LogOutcome | None:
        if self.session is None:
            return None
        outcome = self.session.retry()
        self._after(outcome, outcome.message, "ok")
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
            self._say(f"could not save the pending rows to {path}: {exc}", "error")
            return 0
        self._say(f"saved {count} pending record(s) to {path} (they are still retried here)", "ok")
        return count

    def export_rows(self) -> int:
        """Export the rows in force of the open session to a CSV the operator names (default:
        rows-clean.csv in the session folder); returns how many rows were written."""
        session = self.session
        if session is None:
            return 0
        path = self.ask_export_path(session.path / DEFAULT_NAME)
        if not path:
            return 0
        try:
            count = export_session(session.path, path)
        except (SessionError, OSError) as exc:
            self._say(f"not exported: {exc}", "error")
            return 0
        withdrawn = sum(1 for r in session.rows if r.withdrawn)
        pending = sum(1 for r in session.rows if not r.confirmed)
        self._say(
            f"exported {count} rows to {path}"
            + (f" ({withdrawn} withdrawn left out)" if withdrawn else "")
            + (f"; {pending} row(s) not yet written are not in it" if pending else ""),
            "fail" if pending else "ok",
        )
        return count

    def _after(self, outcome: LogOutcome, success: str, kind: str) -> None:
        self.table.refresh()
        self._show_targets()
        if outcome.ok:
            self.banner.setVisible(bool(self.session and self.session.pending))
            self._say(success, kind)
        else:
            self.banner_text.setText(outcome.message)
            self.banner.show()
            self._say(outcome.message, "error")
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
        self.timer.stop()
        self.recorder.cancel()
        self.guide.cancel()
        if self.session is not None:
            self.session.close()

    # ---------------------------------------------------------------- state
    def _say(self, text: str, kind: str = "ok") -> None:
        """The status line: ``kind`` ok (green), fail (amber: a row that failed its criteria),
        error (red: nothing was done) or info (grey)."""
        self.status.setText(text)
        self.status.setProperty("kind", kind)
        self.status.setStyleSheet(STATUS_STYLES[kind])

    _shown_state: tuple[str, list[str]] = ("", [])

    def _update_state(self) -> None:
        session = self.session
        collecting = self.collecting
        reason = self.blocked_reason()
        notes = self.context_notes()
        self._shown_state = (reason, notes)
        self.log_button.setEnabled(not reason)
        self.cancel_button.setEnabled(collecting)
        self.form.setEnabled(not collecting)
        self.export_button.setEnabled(session is not None)
        self.plan_button.setEnabled(session is not None and not collecting)
        self.log_button.setText("Log target" if self.guided else "Log row")
        self.undo_button.setEnabled(
            session is not None and not collecting and any(not r.withdrawn for r in session.rows)
        )
        self.why.setText("\n".join([reason, *(f"⚠ {n}" for n in notes)]).strip() if not collecting else "")
        self.why.setVisible(bool(self.why.text()))
        if collecting:
            self.progress.setFormat("%v / %m frames")
        elif session is not None:
            self.progress.setFormat(f"{session.info.frames_per_row} frames per row")
        else:
            self.progress.setFormat("no session")
        if session is None:
            self.title.setText("No session open: start one with New session…, or Resume… one")
            self.title.setToolTip("")
            self.count.setText("")  # its line stays: nothing below it moves when a session opens
            self.count.setToolTip("")
            self.window_title_changed("")
            return
        info = session.info
        withdrawn = sum(1 for r in session.rows if r.withdrawn)
        active = [r for r in session.rows if not r.withdrawn]
        passed = sum(1 for r in active if r.passed)
        title = (
            f"{info.name}: {len(active)} rows ({passed} pass), {withdrawn} withdrawn, "
            f"next row {session.next_row}"
            + (f"; {len(session.pending)} NOT WRITTEN" if session.pending else "")
        )
        self.title.setText(title)
        details = f"solver {info.solver}, {info.frames_per_row} frames per row, QR side {info.side_mm:g} mm"
        self.title.setToolTip(f"{title}\n{details}")
        self.count.setText(f"{short_path(session.path)} · {info.solver}, QR {info.side_mm:g} mm")
        self.count.setToolTip(str(session.path))
        self.window_title_changed(f"{info.name} ({len(active)} rows)")

    def window_title_changed(self, text: str) -> None:
        """Hook for the window: the open session in a few words ("" when none)."""
        window = self.window()
        if isinstance(window, QtWidgets.QMainWindow):
            window.setWindowTitle("qrfield — bench" + (f" — {text}" if text else ""))

    def refresh_state(self) -> None:
        """Re-check what may be logged (the window's method or camera changed)."""
        self._update_state()


def _banner(
    name: str, text: QtWidgets.QLabel, buttons: tuple[QtWidgets.QPushButton, ...], background: str
) -> QtWidgets.QFrame:
    """A coloured strip: a wrapped message and its buttons on one line (hidden at first)."""
    frame = QtWidgets.QFrame()
    frame.setObjectName(name)
    frame.setStyleSheet(f"QFrame#{name} {{ background: {background}; border-radius: 3px; }}")
    layout = QtWidgets.QHBoxLayout(frame)
    layout.setContentsMargins(6, 0, 0, 0)  # its buttons are as high as the strip (800x480: every px)
    layout.addWidget(text, 1)
    for button in buttons:
        layout.addWidget(button)
    frame.hide()
    return frame
