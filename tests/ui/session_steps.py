"""Steps of the Session tab as an operator takes them, shared by the session tests: make a
session through its dialog, type the ground truth field by field, log a row with Enter."""

from __future__ import annotations

import csv
from pathlib import Path

from PySide6 import QtCore, QtWidgets

WAIT_MS = 15000
LEFT = QtCore.Qt.MouseButton.LeftButton
FRAMES = 3
POSE_FIELDS = ("x", "y", "z", "alpha", "beta", "gamma")
# The virtual bench's default pose: x 10, y -5, z 300 mm; alpha 15, beta -20, gamma 10 degrees.
COMBO = "alpha+beta-gamma+"


def show_tab(window, widget) -> None:
    """Bring the tab holding ``widget`` (inside its scroll area) to the front."""
    tabs = window.work_tabs
    pages = [tabs.widget(i) for i in range(tabs.count())]
    index = next(i for i, page in enumerate(pages) if widget is page or page.isAncestorOf(widget))
    tabs.setCurrentIndex(index)
    assert tabs.tabText(index) in ("Session", "Analysis")
    assert tabs.tabText(0) == "Session"  # the first thing the app shows


def click_box(qtbot, box: QtWidgets.QCheckBox) -> None:
    """Click a check box on its indicator (a click right of its text does not toggle it)."""
    was = box.isChecked()
    option = QtWidgets.QStyleOptionButton()
    box.initStyleOption(option)
    indicator = box.style().subElementRect(QtWidgets.QStyle.SubElement.SE_CheckBoxIndicator, option, box)
    qtbot.mouseClick(box, LEFT, pos=indicator.center())
    assert box.isChecked() != was


def rows_csv(session_dir: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(session_dir / "rows.csv", newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        header = next(reader)
        return header, [dict(zip(header, line, strict=True)) for line in reader]


def create_session(qtbot, window, name: str = "bench test"):
    """New session… (first on the Session tab), fill in the dialog, Create."""
    panel = window.session_panel
    qtbot.mouseClick(panel.new_button, LEFT)
    dialog = panel.new_dialog
    assert dialog.isVisible()
    panel.row_settings.widgets["frames_per_row"].setValue(FRAMES)
    qtbot.keyClicks(dialog.name_edit, name)
    qtbot.keyClicks(dialog.operator_edit, "tester")
    qtbot.mouseClick(dialog.create_button, LEFT)
    assert panel.session is not None, dialog.message.text()
    assert not dialog.isVisible()
    # The open session's name, folder and row count are shown at the top of the tab.
    assert name.replace(" ", "-") in panel.count.toolTip() and "0 rows" in panel.title.text()
    qtbot.waitUntil(lambda: panel.form.follow_box.isEnabled(), timeout=WAIT_MS)  # frames with truth came
    return panel


def bench(window) -> dict[str, float]:
    pose = window.virtual_form.value().pose
    return dict(zip(POSE_FIELDS, [*pose.position_mm, *pose.angles_deg], strict=True))


def type_truth(qtbot, panel, texts: dict[str, str], combo: str = COMBO) -> None:
    """Type the ground truth as an operator: select the field's text, type, Tab to the next field."""
    form = panel.form
    if form.follow_box.isChecked():
        click_box(qtbot, form.follow_box)
    widget: QtWidgets.QWidget = form.edits["x"]
    for name in POSE_FIELDS:
        assert widget is form.edits[name]  # the Tab order is x, y, z, alpha, beta, gamma
        widget.selectAll()
        qtbot.keyClicks(widget, texts[name])
        widget = widget.nextInFocusChain()
        while not widget.focusPolicy() & QtCore.Qt.FocusPolicy.TabFocus:
            widget = widget.nextInFocusChain()
    assert widget is form.combo  # then the combination, picked from its list unless already shown
    if form.combo.currentText() != combo:
        pick(form.combo, combo)
    assert form.combo.currentText() == combo


def pick(box: QtWidgets.QComboBox, text: str) -> None:
    """Choose ``text`` in a combo box as a click in its list does (typing its name instead would
    depend on the keyboard-search interval, which a loaded machine overruns)."""
    index = box.findText(text)
    assert index >= 0, text
    box.setCurrentIndex(index)
    box.activated.emit(index)


def log_by_enter(qtbot, panel, row: int, widget: QtWidgets.QWidget | None = None) -> None:
    with qtbot.waitSignal(panel.rowLogged, timeout=WAIT_MS) as blocker:
        qtbot.keyClick(widget or panel.form.edits["gamma"], QtCore.Qt.Key.Key_Return)
    assert blocker.args == [row]
