"""The ground-truth form: x, y, z (mm), alpha, beta, gamma (deg), the rotation combination and a note.

Laid out for a small screen: x, y, z on one line (with "follow the bench" at its end on the
virtual bench), alpha, beta, gamma on the next, then the combination and the note on one line;
under them the form's two messages (what the combination's signs say, and the bad fields), which
the Session tab moves below its buttons (:attr:`GroundTruthForm.messages`), so that no message
that comes and goes ever moves a button; on a wide tab the six pose fields share one line. Each
field is checked live with :func:`qrfield.sessions.validate_field`;
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

from qrfield.geometry import ANGLE_NAMES
from qrfield.sessions import GroundTruth, check_ground_truth, truth_fields, validate_field
from qrfield.sessions.combo_signs import combination_mismatch, suggest_combination
from ui.touch import TOUCH_PX, TouchCheckBox

#: Pose fields in form (and Tab) order: name, label, unit; three per line.
POSE_FIELDS = (
    ("x", "x", "mm"),
    ("y", "y", "mm"),
    ("z", "z", "mm"),
    ("alpha", "α", "deg"),
    ("beta", "β", "deg"),
    ("gamma", "γ", "deg"),
)
ANGLES = ANGLE_NAMES
#: How a field is named in messages.
FIELD_NAMES = {name: name for name, _, _ in POSE_FIELDS} | {"combo": "combination"}
#: The narrowest a pose field gets (px): on one line of six, "-123.45" and its frame; on two lines.
ONE_ROW_EDIT_PX = 54
TWO_ROW_EDIT_PX = 64
#: A bad field: a red border 2 px wide, its content 4 px lower, so that it stays TOUCH_PX high and
#: marking it never moves anything.
BAD_STYLE = (
    "border: 2px solid #c0392b; background: #fdecea; "
    f"min-height: {TOUCH_PX - 4}px; max-height: {TOUCH_PX - 4}px;"
)
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


class ElidedLabel(QtWidgets.QLabel):
    """A one-line label that shows as much of its text as fits, with "…" (its height never
    changes); :meth:`full_text` is the whole text, which its tooltip shows unless one is set."""

    def __init__(self, text: str = "") -> None:
        super().__init__()
        self._full = ""
        self._own_tip = False
        size = QtWidgets.QSizePolicy.Policy
        self.setSizePolicy(size.Ignored, size.Fixed)
        self.setMinimumWidth(20)
        self.setText(text)

    def full_text(self) -> str:
        return self._full

    def setText(self, text: str) -> None:
        self._full = text
        self._elide()

    def setToolTip(self, text: str) -> None:
        self._own_tip = bool(text)
        super().setToolTip(text)

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:
        super().resizeEvent(event)
        self._elide()

    def sizeHint(self) -> QtCore.QSize:
        margins = self.contentsMargins()
        height = self.fontMetrics().height() + margins.top() + margins.bottom() + 2 * self.margin()
        return QtCore.QSize(self.fontMetrics().horizontalAdvance(self._full), height)

    def minimumSizeHint(self) -> QtCore.QSize:
        return QtCore.QSize(20, self.sizeHint().height())

    def _elide(self) -> None:
        room = max(0, self.contentsRect().width() - 2 * self.margin())
        shown = self.fontMetrics().elidedText(self._full, QtCore.Qt.TextElideMode.ElideRight, room)
        super().setText(shown)
        if not self._own_tip:
            super().setToolTip(self._full if shown != self._full else "")


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
        self.grid = QtWidgets.QGridLayout(self)
        self.grid.setContentsMargins(0, 0, 0, 0)
        self.grid.setHorizontalSpacing(6)
        self.grid.setVerticalSpacing(2)
        self._build_pose_fields()
        self._build_combo()
        self._build_note_row()
        self.problems = WrappedLabel("")
        self.problems.setObjectName("gt_problems")
        self.problems.setStyleSheet(f"color: {ERROR_COLOUR};")
        self.problems.hide()
        #: The form's messages (the owner may lay them out elsewhere: below its buttons).
        self.messages = (self.combo_note, self.problems)
        self.one_row = False
        self._place(one_row=False)
        order = [*self.edits.values(), self.combo, self.note]
        for first, second in itertools.pairwise(order):
            QtWidgets.QWidget.setTabOrder(first, second)
        for name in FIELD_NAMES:
            self._check(name, emit=False)
        self._valid = not self.errors

    # ---------------------------------------------------------------- builders
    def _build_pose_fields(self) -> None:
        self.captions: dict[str, QtWidgets.QLabel] = {}
        for name, label, unit in POSE_FIELDS:
            edit = QtWidgets.QLineEdit()
            edit.setObjectName(f"gt_{name}")
            edit.setPlaceholderText(unit)
            edit.setToolTip(HELP[name])
            edit.textChanged.connect(lambda _text, n=name: self._field_changed(n))
            edit.textEdited.connect(lambda _text, n=name: self._typed(n))
            self.edits[name] = edit
            caption = QtWidgets.QLabel(label)
            caption.setToolTip(HELP[name])
            caption.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
            self.captions[name] = caption
        self.units = (QtWidgets.QLabel("mm"), QtWidgets.QLabel("deg"))

    def _build_combo(self) -> None:
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
        self.combo_note.hide()
        self.combo_caption = QtWidgets.QLabel("comb.")
        self.combo_caption.setToolTip(HELP["combo"])
        self.combo_caption.setAlignment(
            QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter
        )

    def _build_note_row(self) -> None:
        self.note = QtWidgets.QLineEdit()
        self.note.setObjectName("gt_note")
        self.note.setPlaceholderText("note (optional, one line)")
        self.follow_box = TouchCheckBox("follow the bench")
        self.follow_box.setObjectName("follow_bench")
        self.follow_box.setToolTip("pre-fill the pose with the virtual bench's true pose")
        self.follow_box.setChecked(True)
        self.follow_box.setEnabled(False)  # until a frame with a true pose arrives
        self.follow_box.hide()
        self.follow_box.toggled.connect(self._follow_toggled)
        note_caption = QtWidgets.QLabel("note")
        note_caption.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
        self.last_row = QtWidgets.QHBoxLayout()  # the combination and the note, on one line
        self.last_row.setSpacing(6)
        self.last_row.addWidget(self.combo_caption)
        self.last_row.addWidget(self.combo)
        self.last_row.addWidget(note_caption)
        self.last_row.addWidget(self.note, 1)

    def _place(self, one_row: bool) -> None:
        """Lay the fields out: the six pose fields on one line (``one_row``; no unit labels, the
        fields' placeholders and tooltips say them) or three per line, "follow the bench" at the end
        of the first; then the combination and the note, then the messages."""
        grid = self.grid
        for widget in [*self.captions.values(), *self.edits.values(), *self.units, self.follow_box]:
            grid.removeWidget(widget)
        grid.removeItem(self.last_row)
        for widget in self.messages:
            grid.removeWidget(widget)
        for column in range(grid.columnCount()):
            grid.setColumnStretch(column, 0)
        per_row = 6 if one_row else 3
        for edit in self.edits.values():
            # On one line the fields only go there when each gets ONE_ROW_EDIT_PX (fit_width); their
            # minimum is lower, so that the form never asks its tab to grow (it would stay one line).
            edit.setMinimumWidth(ONE_ROW_EDIT_PX - 20 if one_row else TWO_ROW_EDIT_PX)
        for k, (name, _label, _unit) in enumerate(POSE_FIELDS):
            row, column = divmod(k, per_row)
            grid.addWidget(self.captions[name], row, 2 * column)
            grid.addWidget(self.edits[name], row, 2 * column + 1)
            grid.setColumnStretch(2 * column + 1, 1)
        end = 2 * per_row
        for row, unit in enumerate(self.units):
            unit.setVisible(not one_row)
            if not one_row:
                grid.addWidget(unit, row, end)
        follow_column = end if one_row else end + 1
        grid.addWidget(self.follow_box, 0, follow_column)
        rows = 1 if one_row else 2
        grid.addLayout(self.last_row, rows, 0, 1, follow_column + 1)
        for k, widget in enumerate(self.messages):
            if widget.parentWidget() is self:  # not laid out elsewhere by the owner
                grid.addWidget(widget, rows + 1 + k, 0, 1, follow_column + 1)
        self.one_row = one_row

    def one_row_width(self) -> int:
        """The width (px) the six pose fields need on one line, with "follow the bench" if shown."""
        spacing = self.grid.horizontalSpacing()
        captions = sum(c.sizeHint().width() for c in self.captions.values())
        need = captions + 6 * ONE_ROW_EDIT_PX + 11 * spacing
        if not self.follow_box.isHidden():
            need += self.follow_box.sizeHint().width() + spacing
        return need

    def fit_width(self) -> None:
        """Six fields on one line when they fit (a wide tab, or no "follow the bench" beside them)."""
        one_row = self.width() >= self.one_row_width()
        if one_row != self.one_row:
            self._place(one_row)

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:
        super().resizeEvent(event)
        self.fit_width()

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
            self.fit_width()
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
            self.fit_width()

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
            self._set_combo_note("← from the angles' signs")
        elif self.mismatch() or not self.combo_note.text().startswith("←"):
            self._note_mismatch()

    def _note_mismatch(self) -> None:
        """The line beside the combination: what the angles' signs fit when the label disagrees."""
        if not self.mismatch():
            self._set_combo_note("")
            return
        suggestion = self.suggestion()
        self._set_combo_note(
            f"⚠ the angles fit '{suggestion}'" if suggestion else "⚠ the angles' signs fit no combination"
        )

    def _set_combo_note(self, text: str) -> None:
        self.combo_note.setText(text)
        self.combo_note.setVisible(bool(text))

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
