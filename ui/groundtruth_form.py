"""The ground-truth form: x, y, z (mm), alpha, beta, gamma (deg), the rotation combination and a note.

Each field is checked live with :func:`qrfield.sessions.validate_field`; a bad field gets a red
border and background, its message as tooltip and in a label beside it, and :attr:`valid` turns
False (``validityChanged``), so the panel can disable "Log row": a half row is never logged.
Enter anywhere in the form emits ``submitted``. The form keeps its values after a row is logged.

On the virtual bench the pose fields follow the bench's true pose (:meth:`follow`) while the
"follow the bench" box is ticked; typing into a pose field unticks it (the operator's value wins).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.sessions import GroundTruth, check_ground_truth, truth_fields, validate_field

#: Pose fields in form (and Tab) order, with their labels and units.
POSE_FIELDS = (
    ("x", "x", "mm"),
    ("y", "y", "mm"),
    ("z", "z", "mm"),
    ("alpha", "α alpha", "deg"),
    ("beta", "β beta", "deg"),
    ("gamma", "γ gamma", "deg"),
)
BAD_STYLE = "border: 2px solid #c0392b; background: #fdecea;"
HELP = {
    "x": "x of the QR centre in the camera frame (+X right), mm; a number, optionally with 'mm'",
    "y": "y of the QR centre in the camera frame (+Y down), mm",
    "z": "z of the QR centre in the camera frame (+Z forward along the optical axis), mm",
    "alpha": "rotation about X, degrees (R = Rx(alpha) Ry(beta) Rz(gamma)), in (-180, 180]",
    "beta": "rotation about Y, degrees, in [-90, 90]",
    "gamma": "rotation about Z, degrees, in (-180, 180]",
    "combo": "the rotation combination this row belongs to (the simulation's names)",
}


class WrappedLabel(QtWidgets.QLabel):
    """A word-wrapped label that asks for the height its text needs at its current width (a grid
    cell otherwise gives a wrapped label the height of its unwrapped width and cuts lines off)."""

    def __init__(self, text: str = "") -> None:
        super().__init__(text)
        self.setWordWrap(True)

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:
        super().resizeEvent(event)
        self._fit()

    def setText(self, text: str) -> None:
        super().setText(text)
        self._fit()

    def _fit(self) -> None:
        needed = self.heightForWidth(self.width()) if self.text() else 0
        if needed > 0 and needed != self.minimumHeight():
            self.setMinimumHeight(needed)


class GroundTruthForm(QtWidgets.QWidget):
    """The hand-measured pose of the next row. ``combinations``: allowed names, or None (free text)."""

    validityChanged = QtCore.Signal(bool)
    submitted = QtCore.Signal()

    def __init__(
        self, combinations: Sequence[str] | None = None, parent: QtWidgets.QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.combinations = list(combinations) if combinations else None
        self.edits: dict[str, QtWidgets.QLineEdit] = {}
        self.messages: dict[str, QtWidgets.QLabel] = {}
        grid = QtWidgets.QGridLayout(self)
        grid.setContentsMargins(0, 0, 0, 0)
        for row, (name, label, unit) in enumerate(POSE_FIELDS):
            edit = QtWidgets.QLineEdit()
            edit.setObjectName(f"gt_{name}")
            edit.setPlaceholderText(unit)
            edit.setToolTip(HELP[name])
            edit.setMaximumWidth(120)
            edit.textChanged.connect(lambda _text, n=name: self._check(n))
            edit.textEdited.connect(self._typed)
            self.edits[name] = edit
            grid.addWidget(QtWidgets.QLabel(label), 2 * row, 0)
            grid.addWidget(edit, 2 * row, 1)
            grid.addWidget(QtWidgets.QLabel(unit), 2 * row, 2)
            self.messages[name] = self._message_label(name)
            grid.addWidget(self.messages[name], 2 * row + 1, 1, 1, 3)  # under its field
        self.combo = QtWidgets.QComboBox()
        self.combo.setObjectName("gt_combo")
        self.combo.setToolTip(HELP["combo"])
        if self.combinations:
            self.combo.addItems(self.combinations)
            self.combo.setPlaceholderText("choose…")
            self.combo.setCurrentIndex(-1)
        else:
            self.combo.setEditable(True)
            self.combo.lineEdit().setPlaceholderText("combination name")
        self.combo.currentTextChanged.connect(lambda _text: self._check("combo"))
        row = 2 * len(POSE_FIELDS)
        grid.addWidget(QtWidgets.QLabel("combination"), row, 0)
        grid.addWidget(self.combo, row, 1, 1, 3)
        self.messages["combo"] = self._message_label("combo")
        grid.addWidget(self.messages["combo"], row + 1, 1, 1, 3)
        row += 1
        self.note = QtWidgets.QLineEdit()
        self.note.setObjectName("gt_note")
        self.note.setPlaceholderText("optional, one line")
        grid.addWidget(QtWidgets.QLabel("note"), row + 1, 0)
        grid.addWidget(self.note, row + 1, 1, 1, 3)
        self.follow_box = QtWidgets.QCheckBox("follow the bench (pre-fill with its true pose)")
        self.follow_box.setObjectName("follow_bench")
        self.follow_box.setChecked(True)
        self.follow_box.setEnabled(False)  # until a frame with a true pose arrives
        self.follow_box.toggled.connect(self._follow_toggled)
        self._bench_pose: tuple[Sequence[float], Sequence[float]] | None = None
        grid.addWidget(self.follow_box, row + 2, 0, 1, 4)
        grid.setColumnStretch(3, 1)
        order = [*self.edits.values(), self.combo, self.note]
        for first, second in itertools.pairwise(order):
            QtWidgets.QWidget.setTabOrder(first, second)
        self.errors: dict[str, str] = {}
        self._valid = False
        for name in self.messages:
            self._check(name, emit=False)
        self._valid = not self.errors

    @staticmethod
    def _message_label(name: str) -> QtWidgets.QLabel:
        label = WrappedLabel("")
        label.setObjectName(f"gt_{name}_message")
        label.setStyleSheet("color: #c0392b;")
        label.hide()
        return label

    # ---------------------------------------------------------------- values
    def fields(self) -> dict[str, str]:
        """The texts typed, by field name (x .. gamma, combo)."""
        out = {name: edit.text() for name, edit in self.edits.items()}
        out["combo"] = self.combo.currentText()
        return out

    def truth(self) -> GroundTruth | None:
        """The ground truth when every field is good, else None."""
        truth, _errors = check_ground_truth(self.fields(), self.combinations)
        return truth

    @property
    def following(self) -> bool:
        """True while the pose fields show the virtual bench's true pose ("follow the bench" ticked)."""
        return self.follow_box.isEnabled() and self.follow_box.isChecked()

    @property
    def valid(self) -> bool:
        return self._valid

    def set_fields(self, fields: dict[str, Any]) -> None:
        """Show these texts (any of x .. gamma, combo); validation runs as for typing."""
        for name, edit in self.edits.items():
            if name in fields and edit.text() != str(fields[name]):
                edit.setText(str(fields[name]))
        combo = fields.get("combo")
        if combo:
            self.combo.setCurrentText(str(combo))

    def follow(self, position_mm: Sequence[float], angles_deg: Sequence[float]) -> None:
        """A frame's true pose (virtual bench): enable the box, and fill the pose fields if it is ticked."""
        self._bench_pose = (position_mm, angles_deg)
        if not self.follow_box.isEnabled():
            self.follow_box.setEnabled(True)
        if self.follow_box.isChecked():
            values = truth_fields(position_mm, angles_deg)
            values.pop("combo")
            self.set_fields(values)

    def _follow_toggled(self, on: bool) -> None:
        if on and self._bench_pose is not None:
            self.follow(*self._bench_pose)  # at once, not at the next frame

    # ---------------------------------------------------------------- validation
    def _typed(self, _text: str) -> None:
        """The operator typed a pose value: it must not be overwritten by the bench."""
        if self.follow_box.isChecked():
            self.follow_box.setChecked(False)

    def _check(self, name: str, emit: bool = True) -> None:
        text = self.combo.currentText() if name == "combo" else self.edits[name].text()
        _value, message = validate_field(name, text, self.combinations)
        widget: QtWidgets.QWidget = self.combo if name == "combo" else self.edits[name]
        if message:
            self.errors[name] = message
            widget.setStyleSheet(BAD_STYLE)
            widget.setToolTip(f"{name}: {message}")
            self.messages[name].setText(message)
            self.messages[name].show()
        else:
            self.errors.pop(name, None)
            widget.setStyleSheet("")
            widget.setToolTip(HELP[name])
            self.messages[name].setText("")
            self.messages[name].hide()
        valid = not self.errors
        if valid != self._valid:
            self._valid = valid
            if emit:
                self.validityChanged.emit(valid)

    # ---------------------------------------------------------------- keys
    def keyPressEvent(self, event: QtGui.QKeyEvent) -> None:
        # Line edits and the combination box pass Return/Enter on to their parent: one place logs.
        if event.key() in (QtCore.Qt.Key.Key_Return, QtCore.Qt.Key.Key_Enter):
            self.submitted.emit()
            event.accept()
            return
        super().keyPressEvent(event)
