"""The guide strip of the Session tab when the session follows a plan: the target, the live difference, still.

Two lines, to fit the Session tab at 800x480: the target chooser (every target with its state:
the next one is chosen by itself; choosing another visits it, e.g. to redo it), "log when still"
and Skip; then the difference measured - target per DOF, large, coloured by its grade against the
session's criteria (:meth:`qrfield.sessions.criteria.AcceptanceCriteria.grade`: green within them,
amber within twice them, red beyond), and the stillness. Everything it shows comes from the core's
:class:`qrfield.sessions.guide.GuideView` and :class:`qrfield.sessions.progress.TargetState`; the
strip only draws them and passes the operator's taps on as signals.
"""

from __future__ import annotations

from collections.abc import Sequence

from PySide6 import QtCore, QtWidgets

from qrfield.sessions.criteria import FAR, GOOD, NEAR
from qrfield.sessions.guide import GuideView
from qrfield.sessions.progress import DONE, SKIPPED, TargetState
from ui.groundtruth_form import WrappedLabel
from ui.session_dialogs import touch_button
from ui.text import fixed

#: Cell colours by grade: (background, text).
GRADE_COLOURS = {GOOD: ("#d9f0d9", "#1d6b1d"), NEAR: ("#fdf0c8", "#7a5000"), FAR: ("#f7d4d4", "#a01818")}
NO_POSE = ("#eeeeee", "#777777")
#: The six cells: label, unit (a tenth of a mm or a degree is what a hand sets a jig to).
CELLS = (("Δx", "mm"), ("Δy", "mm"), ("Δz", "mm"), ("Δα", "°"), ("Δβ", "°"), ("Δγ", "°"))
MARKS = {DONE: "✓", SKIPPED: "–", "todo": " "}


def signed(value: float) -> str:
    """A difference with its sign and a tenth (whole numbers from 100 on): "+0.4", "-19.9", "+123"."""
    text = fixed(value, 0 if abs(value) >= 99.95 else 1)
    return text if text.startswith("-") or text in ("0", "0.0", "—") else f"+{text}"


def target_label(state: TargetState, total: int) -> str:
    """E.g. ``✓ 3/24 alpha+beta+ (10, 10, 0)°``."""
    t = state.target
    angles = ", ".join(f"{v:g}" for v in t.truth.angles_deg)
    return f"{MARKS.get(state.state, ' ')} {t.number}/{total} {t.combo} ({angles})°"


class GuidePanel(QtWidgets.QFrame):
    """The strip; ``show_targets`` and ``show_view`` draw, the signals carry the operator's taps."""

    targetChosen = QtCore.Signal(int)  # a target number
    skipRequested = QtCore.Signal()
    autoToggled = QtCore.Signal(bool)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("guide_panel")
        self.setStyleSheet("QFrame#guide_panel { background: #eef3fa; border-radius: 3px; }")
        self.chooser = QtWidgets.QComboBox()
        self.chooser.setObjectName("guide_target")
        self.chooser.setToolTip("the plan's targets (✓ done, – skipped); choose one to visit or redo it")
        self.chooser.setMinimumContentsLength(14)
        self.chooser.setSizeAdjustPolicy(
            QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon
        )
        self.chooser.setSizePolicy(QtWidgets.QSizePolicy.Policy.Expanding, QtWidgets.QSizePolicy.Policy.Fixed)
        self.chooser.setMinimumHeight(36)
        self.auto_box = QtWidgets.QCheckBox("log when still")
        self.auto_box.setObjectName("guide_auto")
        self.auto_box.setToolTip(
            "log the target's row by itself once the card has moved to it and been still for the hold time"
        )
        self.skip_button = touch_button("Skip", "guide_skip")
        self.skip_button.setToolTip("leave this target for now (choose it again later)")
        top = QtWidgets.QHBoxLayout()
        top.setContentsMargins(0, 0, 0, 0)
        top.addWidget(self.chooser, 1)
        top.addWidget(self.auto_box)
        top.addWidget(self.skip_button)
        #: One frame per DOF (its "grade" property: good, near or far), with a caption and a value.
        self.cells: list[QtWidgets.QFrame] = []
        self.values: list[QtWidgets.QLabel] = []
        cells = QtWidgets.QHBoxLayout()
        cells.setContentsMargins(0, 0, 0, 0)
        cells.setSpacing(2)
        for k, (label, unit) in enumerate(CELLS):
            cell, value = self._cell(f"guide_diff_{k}", f"{label} {unit}")
            self.cells.append(cell)
            self.values.append(value)
            cells.addWidget(cell, 1)
        self.still_cell, self.still = self._cell("guide_still", "still?")
        self.still_caption = self.still_cell.findChild(QtWidgets.QLabel, "guide_still_caption")
        cells.addWidget(self.still_cell, 1)
        self.note = WrappedLabel("")
        self.note.setObjectName("guide_note")
        self.note.setStyleSheet("color: #555;")
        self.note.hide()
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(4, 2, 4, 2)
        layout.setSpacing(2)
        layout.addLayout(top)
        layout.addLayout(cells)
        layout.addWidget(self.note)
        self.chooser.activated.connect(self._chosen)
        self.skip_button.clicked.connect(self.skipRequested.emit)
        self.auto_box.toggled.connect(self.autoToggled.emit)
        for cell in [*self.cells, self.still_cell]:
            self._paint(cell, NO_POSE)

    @staticmethod
    def _cell(name: str, caption: str) -> tuple[QtWidgets.QFrame, QtWidgets.QLabel]:
        """A coloured frame: a small caption over a large value."""
        frame = QtWidgets.QFrame()
        frame.setObjectName(name)
        frame.setSizePolicy(QtWidgets.QSizePolicy.Policy.Expanding, QtWidgets.QSizePolicy.Policy.Fixed)
        top = QtWidgets.QLabel(caption)
        top.setObjectName(f"{name}_caption")
        top.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        top.setStyleSheet("font-size: 8pt;")
        value = QtWidgets.QLabel("—")
        value.setObjectName(f"{name}_value")
        value.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        value.setStyleSheet("font-size: 12pt; font-weight: bold;")
        layout = QtWidgets.QVBoxLayout(frame)
        layout.setContentsMargins(1, 1, 1, 1)
        layout.setSpacing(0)
        layout.addWidget(top)
        layout.addWidget(value)
        return frame, value

    # ---------------------------------------------------------------- drawing
    def show_targets(self, states: Sequence[TargetState], current: int | None) -> None:
        """Fill the chooser (each target with its state) and select ``current`` (a target number)."""
        with QtCore.QSignalBlocker(self.chooser):
            self.chooser.clear()
            for state in states:
                self.chooser.addItem(target_label(state, len(states)), state.target.number)
            index = self.chooser.findData(current) if current is not None else -1
            self.chooser.setCurrentIndex(index)
            if current is None:
                self.chooser.setPlaceholderText("every target has a row ✓")
        self.skip_button.setEnabled(current is not None)

    def show_view(self, view: GuideView) -> None:
        """The difference per DOF (graded), the stillness, and a hint when the guide waits."""
        grades = view.grades
        for k, (cell, value) in enumerate(zip(self.cells, self.values, strict=True)):
            if grades is None:
                value.setText("—")
                cell.setProperty("grade", None)
                self._paint(cell, NO_POSE)
                continue
            grade = grades.position[k] if k < 3 else grades.angles[k - 3]
            value.setText(signed(float(view.difference[k])))
            cell.setProperty("grade", grade)
            self._paint(cell, GRADE_COLOURS[grade])
        if grades is not None:
            self.cells[0].setToolTip(f"distance {fixed(grades.distance_mm, 2)} mm ({grades.distance})")
        state = view.stillness
        if view.collecting is not None:
            caption, text, colours = (
                "logging",
                f"{view.collecting[0]}/{view.collecting[1]}",
                GRADE_COLOURS[NEAR],
            )
        elif state.still:
            caption, text, colours = "still", "●", GRADE_COLOURS[GOOD]
        elif state.held_s > 0:
            caption, text, colours = "settling", f"{state.held_s:.1f} s", GRADE_COLOURS[NEAR]
        else:
            caption, text, colours = ("moving" if grades is not None else "no pose"), "○", GRADE_COLOURS[FAR]
        self.still_caption.setText(caption)
        self.still.setText(text)
        self.still.setProperty("still", state.still)
        self.still_cell.setToolTip(
            state.reason or f"still for {state.held_s:.1f} s (of {state.hold_s:.1f} s)"
        )
        self._paint(self.still_cell, colours)
        hint = view.problem or (view.auto_reason if view.auto else "")
        if view.waiting:
            hint = "waiting for the card to be still…"
        self.note.setText(hint)
        self.note.setVisible(bool(hint))

    @staticmethod
    def _paint(frame: QtWidgets.QFrame, colours: tuple[str, str]) -> None:
        background, text = colours
        frame.setStyleSheet(
            f"QFrame#{frame.objectName()} {{ background: {background}; border-radius: 3px; }} "
            f"QLabel {{ color: {text}; }}"
        )

    def _chosen(self, index: int) -> None:
        number = self.chooser.itemData(index)
        if number is not None:
            self.targetChosen.emit(int(number))
