"""The ground-truth form: x, y, z (mm), alpha, beta, gamma (deg), the rotation combination and a note.

Laid out for a small screen: x, y, z on one line, alpha, beta, gamma on the next, then the
combination and the note. Each field is checked live with :func:`qrfield.sessions.validate_field`;
:attr:`GroundTruthForm.valid` turns False when any field is bad (``validityChanged``), so the
panel can disable "Log row": a half row is never logged. A bad field is marked (red border, its
message as tooltip and in the line under the fields) only once the operator has typed into it or
after a failed attempt to log (:meth:`reveal_errors`): an empty form is not a page of red.
``changed`` is emitted on every check, so the panel's hint always names the fields bad *now*.

The combination follows the angles' signs (:mod:`qrfield.sessions.combo_signs`): when the angles
change and the combination shown disagrees with them (or none is chosen), the combination that
fits is chosen and the line beside it says so; a combination the operator picks is kept while it
agrees. :meth:`mismatch` says why the label disagrees with the angles (the panel asks first).
Enter anywhere in the form emits ``submitted``. The form keeps its pose and combination after a row
is logged (the panel clears the note: it belongs to its row).

On the virtual bench the pose fields follow the bench's true pose (:meth:`follow`) while the
"follow the bench" box is ticked; typing into a pose field unticks it (the operator's value wins).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.sessions import GroundTruth, check_ground_truth, truth_fields, validate_field
from qrfield.sessions.combo_signs import combination_mismatch, suggest_combination

#: Pose fields in form (and Tab) order: name, label, unit; three per line.
POSE_FIELDS = (
    ("x", "x", "mm"),
    ("y", "y", "mm"),
    ("z", "z", "mm"),
    ("alpha", "α", "deg"),
    ("beta", "β", "deg"),
    ("gamma", "γ", "deg"),
)
ANGLES = ("alpha", "beta", "gamma")
#: How a field is named in messages.
FIELD_NAMES = {name: name for name, _, _ in POSE_FIELDS} | {"combo": "combination"}
BAD_STYLE = "border: 2px solid #c0392b; background: #fdecea;"
ERROR_COLOUR = "#c0392b"
HELP = {
    "x": "x of the QR centre in the camera frame (+X right), mm; a number, optionally with 'mm'",
    "y": "y of the QR centre in the camera frame (+Y down), mm",
    "z": "z of the QR centre in the camera frame (+Z forward along the optical axis), mm",
    "alpha": "alpha: rotation about X, degrees (R = Rx(alpha) Ry(beta) Rz(gamma)), in (-180, 180]",
    "beta": "beta: rotation about Y, degrees, in [-90, 90]",
    "gamma": "gamma: rotation about Z, degrees, in (-180, 180]",
    "combo": "the rotation combination this row belongs to (the simulation's names); "
    "chosen from the angles' signs when they change",
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
    """The hand-measured pose of the next row.

    ``combinations``: the allowed names (the simulation's), or None (free text). ``signs``: the
    combinations' multipliers {name: (m_alpha, m_beta, m_gamma)} for the suggestion, or None.
    """

    validityChanged = QtCore.Signal(bool)
    changed = QtCore.Signal()
    submitted = QtCore.Signal()

    def __init__(
        self,
        combinations: Sequence[str] | None = None,
        signs: Mapping[str, Sequence[float]] | None = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.combinations = list(combinations) if combinations else None
        self.signs = dict(signs) if signs else None
        self.edits: dict[str, QtWidgets.QLineEdit] = {}
        self.errors: dict[str, str] = {}
        self.touched: set[str] = set()
        self._valid = False
        self._bench_pose: tuple[Sequence[float], Sequence[float]] | None = None
        grid = QtWidgets.QGridLayout(self)
        grid.setContentsMargins(0, 0, 0, 0)
        grid.setHorizontalSpacing(6)
        grid.setVerticalSpacing(3)
        self._build_pose_fields(grid)
        self._build_combo(grid)
        self._build_note_row(grid)
        self.problems = WrappedLabel("")
        self.problems.setObjectName("gt_problems")
        self.problems.setStyleSheet(f"color: {ERROR_COLOUR};")
        self.problems.hide()
        grid.addWidget(self.problems, 4, 0, 1, 7)
        order = [*self.edits.values(), self.combo, self.note]
        for first, second in itertools.pairwise(order):
            QtWidgets.QWidget.setTabOrder(first, second)
        for name in FIELD_NAMES:
            self._check(name, emit=False)
        self._valid = not self.errors

    # ---------------------------------------------------------------- builders
    def _build_pose_fields(self, grid: QtWidgets.QGridLayout) -> None:
        for k, (name, label, unit) in enumerate(POSE_FIELDS):
            row, column = divmod(k, 3)
            edit = QtWidgets.QLineEdit()
            edit.setObjectName(f"gt_{name}")
            edit.setPlaceholderText(unit)
            edit.setToolTip(HELP[name])
            edit.setMinimumWidth(64)
            edit.textChanged.connect(lambda _text, n=name: self._field_changed(n))
            edit.textEdited.connect(lambda _text, n=name: self._typed(n))
            self.edits[name] = edit
            caption = QtWidgets.QLabel(label)
            caption.setToolTip(HELP[name])
            caption.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
            grid.addWidget(caption, row, 2 * column)
            grid.addWidget(edit, row, 2 * column + 1)
            grid.setColumnStretch(2 * column + 1, 1)
            if column == 2:
                grid.addWidget(QtWidgets.QLabel(unit), row, 6)

    def _build_combo(self, grid: QtWidgets.QGridLayout) -> None:
        self.combo = QtWidgets.QComboBox()
        self.combo.setObjectName("gt_combo")
        self.combo.setToolTip(HELP["combo"])
        # As wide as the longest name (they were cut at 15 characters).
        self.combo.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToContents)
        if self.combinations:
            self.combo.addItems(self.combinations)
            self.combo.setPlaceholderText("choose…")
            self.combo.setCurrentIndex(-1)
        else:
            self.combo.setEditable(True)
            self.combo.lineEdit().setPlaceholderText("combination name")
            self.combo.lineEdit().textEdited.connect(lambda _text: self._touch("combo"))
        self.combo.currentTextChanged.connect(lambda _text: self._check("combo"))
        self.combo.activated.connect(lambda _index: self._touch("combo"))
        self.combo_note = WrappedLabel("")
        self.combo_note.setObjectName("gt_combo_note")
        self.combo_note.setStyleSheet("color: #555;")
        caption = QtWidgets.QLabel("comb.")
        caption.setToolTip(HELP["combo"])
        caption.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
        grid.addWidget(caption, 2, 0)
        grid.addWidget(self.combo, 2, 1, 1, 2)
        grid.addWidget(self.combo_note, 2, 3, 1, 4)

    def _build_note_row(self, grid: QtWidgets.QGridLayout) -> None:
        self.note = QtWidgets.QLineEdit()
        self.note.setObjectName("gt_note")
        self.note.setPlaceholderText("note (optional, one line)")
        self.follow_box = QtWidgets.QCheckBox("follow the bench")
        self.follow_box.setObjectName("follow_bench")
        self.follow_box.setToolTip("pre-fill the pose with the virtual bench's true pose")
        self.follow_box.setChecked(True)
        self.follow_box.setEnabled(False)  # until a frame with a true pose arrives
        self.follow_box.hide()
        self.follow_box.toggled.connect(self._follow_toggled)
        caption = QtWidgets.QLabel("note")
        caption.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
        grid.addWidget(caption, 3, 0)
        grid.addWidget(self.note, 3, 1, 1, 3)
        grid.addWidget(self.follow_box, 3, 4, 1, 3)

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

    def shown_errors(self) -> dict[str, str]:
        """The bad fields the form marks now (typed into, or revealed by a failed attempt)."""
        return {name: message for name, message in self.errors.items() if name in self.touched}

    def untouched_errors(self) -> list[str]:
        """Bad fields not marked yet (in practice: still empty), in form order."""
        return [name for name in FIELD_NAMES if name in self.errors and name not in self.touched]

    def reveal_errors(self) -> None:
        """Mark every bad field (after an attempt to log with them)."""
        self.touched.update(FIELD_NAMES)
        for name in FIELD_NAMES:
            self._check(name)

    def set_fields(self, fields: dict[str, Any]) -> None:
        """Show these texts (any of x .. gamma, combo); validation runs as for typing."""
        for name, edit in self.edits.items():
            if name in fields and edit.text() != str(fields[name]):
                self.touched.add(name)
                edit.setText(str(fields[name]))
        combo = fields.get("combo")
        if combo:
            self.touched.add("combo")
            self.combo.setCurrentText(str(combo))

    def follow(self, position_mm: Sequence[float], angles_deg: Sequence[float]) -> None:
        """A frame's true pose (virtual bench): offer the box, and fill the pose fields if it is ticked."""
        self._bench_pose = (position_mm, angles_deg)
        if not self.follow_box.isEnabled():
            self.follow_box.setEnabled(True)
            self.follow_box.show()
        if self.follow_box.isChecked():
            values = truth_fields(position_mm, angles_deg)
            values.pop("combo")
            self.set_fields(values)

    def bench_gone(self) -> None:
        """Frames without a true pose (another source, or none): nothing to follow any more."""
        self._bench_pose = None
        if self.follow_box.isEnabled():
            self.follow_box.setEnabled(False)
            self.follow_box.hide()

    def _follow_toggled(self, on: bool) -> None:
        if on and self._bench_pose is not None:
            self.follow(*self._bench_pose)  # at once, not at the next frame

    # ---------------------------------------------------------------- combination
    def angles(self) -> tuple[float, float, float] | None:
        """alpha, beta, gamma (deg) when all three fields are good, else None."""
        values = [validate_field(name, self.edits[name].text())[0] for name in ANGLES]
        if any(v is None for v in values):
            return None
        return (float(values[0]), float(values[1]), float(values[2]))

    def mismatch(self) -> str:
        """Why the combination shown disagrees with the angles' signs ("" when it agrees)."""
        angles = self.angles()
        combo = self.combo.currentText().strip()
        return combination_mismatch(combo, angles, self.signs) if angles and combo else ""

    def suggestion(self) -> str | None:
        """The combination the angles' signs fit (None: all about 0, no fit, or angles not valid)."""
        angles = self.angles()
        return suggest_combination(angles, self.signs) if angles else None

    def _suggest(self) -> None:
        """The angles changed: choose the combination that fits them if the one shown does not."""
        if not self.signs:
            return
        suggestion = self.suggestion()
        if suggestion and (not self.combo.currentText().strip() or self.mismatch()):
            with QtCore.QSignalBlocker(self.combo):
                self.combo.setCurrentText(suggestion)
            self._check("combo")
            self.combo_note.setText("← from the angles' signs")
        elif self.mismatch() or not self.combo_note.text().startswith("←"):
            self._note_mismatch()

    def _note_mismatch(self) -> None:
        """The line beside the combination: what the angles' signs fit when the label disagrees."""
        if not self.mismatch():
            self.combo_note.setText("")
            return
        suggestion = self.suggestion()
        self.combo_note.setText(
            f"⚠ the angles fit '{suggestion}'" if suggestion else "⚠ the angles' signs fit no combination"
        )

    # ---------------------------------------------------------------- validation
    def _typed(self, name: str) -> None:
        """The operator typed a pose value: it must not be overwritten by the bench."""
        self._touch(name)
        if self.follow_box.isChecked():
            self.follow_box.setChecked(False)

    def _touch(self, name: str) -> None:
        if name not in self.touched:
            self.touched.add(name)
            self._check(name)
        if name == "combo":
            self._note_mismatch()

    def _field_changed(self, name: str) -> None:
        self._check(name)
        if name in ANGLES:
            self._suggest()

    def _check(self, name: str, emit: bool = True) -> None:
        text = self.combo.currentText() if name == "combo" else self.edits[name].text()
        _value, message = validate_field(name, text, self.combinations)
        widget: QtWidgets.QWidget = self.combo if name == "combo" else self.edits[name]
        if message:
            self.errors[name] = message
        else:
            self.errors.pop(name, None)
        shown = bool(message) and name in self.touched
        widget.setStyleSheet(BAD_STYLE if shown else "")
        widget.setToolTip(f"{FIELD_NAMES[name]}: {message}" if shown else HELP[name])
        problems = self.shown_errors()
        self.problems.setText("; ".join(f"{FIELD_NAMES[n]}: {m}" for n, m in problems.items()))
        self.problems.setVisible(bool(problems))
        valid = not self.errors
        if valid != self._valid:
            self._valid = valid
            if emit:
                self.validityChanged.emit(valid)
        if emit:
            self.changed.emit()

    # ---------------------------------------------------------------- keys
    def keyPressEvent(self, event: QtGui.QKeyEvent) -> None:
        # Line edits and the combination box pass Return/Enter on to their parent: one place logs.
        if event.key() in (QtCore.Qt.Key.Key_Return, QtCore.Qt.Key.Key_Enter):
            self.submitted.emit()
            event.accept()
            return
        super().keyPressEvent(event)
