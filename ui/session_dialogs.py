"""The Session tab's two dialogs: New session (name, operator, solver, frames per row, criteria,
sessions folder) and Resume (the sessions in the sessions folder, newest first, or another folder).

Both are opened with ``open()`` (window-modal, never a nested event loop) and hand the choice to
the panel, which creates or opens the session and closes the dialog when that worked; when it did
not, the reason stays in the dialog's own message line. Both fit an 800x480 screen.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.methods import METHODS
from qrfield.sessions import AcceptanceCriteria, SessionSettings, session_folders
from qrfield.sessions.folders import ENV_ROOT as ENV_ROOT  # the core's rule, named here for the panel
from qrfield.sessions.folders import SessionFolderSettings, sessions_root
from ui.groundtruth_form import WrappedLabel
from ui.settings_form import SettingsForm
from ui.text import short_path
from ui.touch import FOLDER, TOUCH_PX, ask_path, fit_to_screen, touch_button

__all__ = [
    "ENV_ROOT",
    "TOUCH_PX",
    "NewSessionDialog",
    "ResumeDialog",
    "SessionFolderSettings",
    "sessions_root",
    "touch_button",
]


def _message_label() -> WrappedLabel:
    label = WrappedLabel("")
    label.setStyleSheet("color: #c0392b; font-weight: bold;")
    label.hide()
    return label


class NewSessionDialog(QtWidgets.QDialog):
    """The New session form; ``createRequested`` when Create is pressed (the panel creates)."""

    createRequested = QtCore.Signal()

    def __init__(self, store: Any, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("qrfield — new session")
        self.setObjectName("new_session_dialog")
        self.setMinimumWidth(440)
        self._build_fields(store)
        self._build_buttons()
        # The fields scroll (ten rows of 44 px are more than an 800x480 screen holds with the title
        # bar); the message and Create / Cancel stay in view under them.
        fields = QtWidgets.QWidget()
        fields.setLayout(self.form)
        self.fields_area = QtWidgets.QScrollArea()
        self.fields_area.setObjectName("new_session_fields")
        self.fields_area.setWidget(fields)
        self.fields_area.setWidgetResizable(True)
        self.fields_area.setFrameShape(QtWidgets.QFrame.Shape.NoFrame)
        self.fields_area.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(6, 6, 6, 6)
        layout.addWidget(self.fields_area, 1)
        layout.addWidget(self.message)
        layout.addLayout(self.buttons)

    def showEvent(self, event: QtGui.QShowEvent) -> None:
        super().showEvent(event)
        fields = self.fields_area.widget().sizeHint()
        wanted = QtCore.QSize(max(self.width(), fields.width() + 40), fields.height() + 2 * TOUCH_PX + 40)
        fit_to_screen(self, self.parentWidget(), wanted)  # all of it on a desktop, the screen at 800x480

    def _build_fields(self, store: Any) -> None:
        self.name_edit = QtWidgets.QLineEdit()
        self.name_edit.setObjectName("session_name")
        self.name_edit.setPlaceholderText("e.g. beta-sweep")
        self.operator_edit = QtWidgets.QLineEdit()
        self.operator_edit.setObjectName("session_operator")
        self.notes_edit = QtWidgets.QPlainTextEdit()
        self.notes_edit.setObjectName("session_notes")
        self.notes_edit.setTabChangesFocus(True)
        self.notes_edit.setMaximumHeight(48)
        self.solver_combo = QtWidgets.QComboBox()
        self.solver_combo.addItems(list(METHODS))
        self.solver_combo.setToolTip("the pose method whose results the rows average")
        self.folder_form = SettingsForm(
            SessionFolderSettings, store.group("session_folder", SessionFolderSettings)
        )
        root = self.folder_form.widgets["root"]
        assert isinstance(root, QtWidgets.QLineEdit)
        root.setPlaceholderText(short_path(sessions_root(SessionFolderSettings())))
        browse = touch_button("Folder…", "sessions_folder")
        browse.clicked.connect(self._choose_root)
        folder_row = QtWidgets.QHBoxLayout()
        folder_row.addWidget(self.folder_form, 1)
        folder_row.addWidget(browse)
        self.row_settings = SettingsForm(SessionSettings, store.group("session", SessionSettings))
        self.criteria_form = SettingsForm(AcceptanceCriteria, store.group("criteria", AcceptanceCriteria))
        self.form = QtWidgets.QFormLayout()
        self.form.setFieldGrowthPolicy(QtWidgets.QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.form.addRow("name", self.name_edit)
        self.form.addRow("operator", self.operator_edit)
        self.form.addRow("notes", self.notes_edit)
        self.form.addRow("solver", self.solver_combo)
        self.form.addRow(folder_row)
        self.form.addRow(self.row_settings)
        self.form.addRow(self.criteria_form)
        self.message = _message_label()

    def _build_buttons(self) -> None:
        self.create_button = touch_button("Create session", "create_session")
        self.create_button.setDefault(True)
        cancel = touch_button("Cancel")
        self.buttons = QtWidgets.QHBoxLayout()
        self.buttons.addStretch(1)
        self.buttons.addWidget(cancel)
        self.buttons.addWidget(self.create_button)
        self.create_button.clicked.connect(self.createRequested)
        cancel.clicked.connect(self.reject)

    def root(self) -> Path:
        return sessions_root(self.folder_form.value())

    def say(self, text: str) -> None:
        self.message.setText(text)
        self.message.setVisible(bool(text))

    def _choose_root(self) -> None:
        path = ask_path(self, "Sessions folder", self.root(), mode=FOLDER)
        if path:
            widget = self.folder_form.widgets["root"]
            assert isinstance(widget, QtWidgets.QLineEdit)
            widget.setText(path)
            widget.editingFinished.emit()


class ResumeDialog(QtWidgets.QDialog):
    """The sessions of the sessions folder, newest first; ``resumeRequested(path)`` on Resume."""

    resumeRequested = QtCore.Signal(str)

    def __init__(
        self, root: Callable[[], Path], ask_folder: Callable[[], str], parent: QtWidgets.QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle("qrfield — resume a session")
        self.setObjectName("resume_dialog")
        self.setMinimumWidth(440)
        self.root = root
        self.ask_folder = ask_folder
        self.where = WrappedLabel("")
        self.list = QtWidgets.QListWidget()
        self.list.setObjectName("resume_choice")
        self.list.itemDoubleClicked.connect(lambda _item: self._resume_chosen())
        note = WrappedLabel(
            "Resuming continues the numbering after the last row; rows already logged are never rewritten."
        )
        note.setStyleSheet("color: #555;")
        self.message = _message_label()
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self.where)
        layout.addWidget(self.list, 1)
        layout.addWidget(note)
        layout.addWidget(self.message)
        layout.addLayout(self._build_buttons())

    def _build_buttons(self) -> QtWidgets.QHBoxLayout:
        """Other folder… on the left; Cancel and Resume (the default) on the right."""
        self.resume_button = touch_button("Resume", "resume_session")
        self.resume_button.setDefault(True)
        other = touch_button("Other folder…", "resume_other")
        cancel = touch_button("Cancel")
        buttons = QtWidgets.QHBoxLayout()
        buttons.addWidget(other)
        buttons.addStretch(1)
        buttons.addWidget(cancel)
        buttons.addWidget(self.resume_button)
        self.resume_button.clicked.connect(self._resume_chosen)
        other.clicked.connect(self._other_folder)
        cancel.clicked.connect(self.reject)
        return buttons

    def refresh(self) -> None:
        """List the sessions folder again (newest first)."""
        root = self.root()
        self.list.clear()
        for folder in reversed(session_folders(root)):
            item = QtWidgets.QListWidgetItem(folder.name)
            item.setData(QtCore.Qt.ItemDataRole.UserRole, str(folder))
            item.setToolTip(str(folder))
            self.list.addItem(item)
        if self.list.count():
            self.list.setCurrentRow(0)
        self.where.setText(
            f"Sessions in {short_path(root)}:"
            if self.list.count()
            else f"No sessions in {short_path(root)} yet: press Other folder… or make a new one."
        )
        self.resume_button.setEnabled(self.list.count() > 0)

    def chosen(self) -> str:
        item = self.list.currentItem()
        return str(item.data(QtCore.Qt.ItemDataRole.UserRole)) if item is not None else ""

    def choose(self, path: str | os.PathLike[str]) -> bool:
        """Select the listed session at ``path``; False if it is not listed."""
        for row in range(self.list.count()):
            if self.list.item(row).data(QtCore.Qt.ItemDataRole.UserRole) == str(path):
                self.list.setCurrentRow(row)
                return True
        return False

    def say(self, text: str) -> None:
        self.message.setText(text)
        self.message.setVisible(bool(text))

    def _resume_chosen(self) -> None:
        path = self.chosen()
        if path:
            self.resumeRequested.emit(path)

    def _other_folder(self) -> None:
        path = self.ask_folder()
        if path:
            self.resumeRequested.emit(path)
