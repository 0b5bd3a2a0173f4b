"""On the Raspberry Pi Touch Display (800x480) and at 1024x600 every button of the calibration
dialog (on each of its pages) and of the Simulation tab (on each of its pages, after a run) is in
view without scrolling: inside the top-level window, not in a scroll area, not cut by a parent,
its text whole; no label's text is cut. Lists, tables, the result text and the study's long form
may scroll inside themselves (they hold no button). The helpers are test_app_layout's."""

from __future__ import annotations

import pytest
from PySide6 import QtCore, QtWidgets
from test_app_layout import WAIT_MS, clipped_by_parents, cut_labels, in_scroll_area, name, settle

from qrfield.camera import resolve_camera
from ui.calibration_dialog import RESULT_PAGE, VIEWS_PAGE, CalibrationDialog

pytestmark = [pytest.mark.gui, pytest.mark.slow]
SIZES = [(800, 480), (1024, 600)]
IDS = [f"{w}x{h}" for w, h in SIZES]
CAMERA = "picam-v2@640x480"
CALIBRATION_BUTTONS = {
    "capture",
    "next_pose",
    "remove_view",
    "clear_views",
    "compute",
    "close",
    "save",
    "use",
}
SIMULATION_BUTTONS = {"Run", "Stop", "Small study", "Default study", "…", "Full size…", "Open folder"}


def out_of_reach(window: QtWidgets.QWidget, widget: QtWidgets.QWidget) -> str:
    """Why ``widget`` cannot be reached at once in ``window`` ("" when it can)."""
    where = QtCore.QRect(widget.mapTo(window, QtCore.QPoint(0, 0)), widget.size())
    if not window.rect().contains(where):
        return f"at {where.getRect()}, outside the window {window.rect().getRect()}"
    if in_scroll_area(widget):
        return "inside a scroll area"
    if clipped_by_parents(widget):
        return "partly hidden by its parents"
    is_button = isinstance(widget, QtWidgets.QPushButton)
    if is_button and widget.fontMetrics().horizontalAdvance(widget.text()) + 8 > widget.width():
        return f"its text is cut ({widget.width()} px wide)"
    return ""


def shown_text(widget: QtWidgets.QWidget) -> str:
    return widget.currentText() if isinstance(widget, QtWidgets.QComboBox) else widget.text()


def shown_buttons(window: QtWidgets.QWidget, under: QtWidgets.QWidget) -> list[QtWidgets.QPushButton]:
    return [b for b in under.findChildren(QtWidgets.QPushButton) if b.window() is window and b.isVisible()]


def problems_on_page(window: QtWidgets.QWidget, under: QtWidgets.QWidget, extra=()) -> list[str]:
    found = [
        f"{shown_text(w)!r} ({name(w)}): {why}"
        for w in [*shown_buttons(window, under), *extra]
        if (why := out_of_reach(window, w))
    ]
    return found + cut_labels(window)


@pytest.fixture
def calibration_dialog(qtbot):
    dialog = CalibrationDialog(lambda: resolve_camera(CAMERA))
    qtbot.addWidget(dialog)
    yield dialog
    dialog.shutdown()


@pytest.mark.parametrize(("width", "height"), SIZES, ids=IDS)
def test_every_calibration_button_is_in_view_without_scrolling(
    calibration_dialog, qtbot, width, height
) -> None:
    dialog = calibration_dialog
    dialog.show()
    dialog.resize(width, height)
    dialog.virtual_check.setChecked(True)
    pages = getattr(dialog, "pages", None)
    for _ in range(3):  # a result on the Result page: its text, Save and Use enabled
        qtbot.waitUntil(dialog.capture_button.isEnabled, timeout=WAIT_MS)
        dialog.capture_button.click()
        assert pages is None or pages.currentIndex() == VIEWS_PAGE  # the view, and where it counts
    dialog.compute_button.click()
    qtbot.waitUntil(lambda: dialog.result is not None, timeout=WAIT_MS)
    assert pages is None or pages.currentIndex() == RESULT_PAGE
    assert (dialog.width(), dialog.height()) == (width, height)
    problems: dict[str, list[str]] = {}
    seen: set[str] = set()
    for k in range(pages.count() if pages is not None else 1):
        if pages is not None:
            pages.setCurrentIndex(k)
        settle(qtbot)
        title = pages.tabText(k) if pages is not None else "the dialog"
        seen |= {b.objectName() for b in shown_buttons(dialog, dialog)}
        if found := problems_on_page(dialog, dialog):
            problems[title] = found
    assert not problems, problems
    assert seen >= CALIBRATION_BUTTONS, CALIBRATION_BUTTONS - seen
    # The preview stays the larger part of the dialog.
    assert dialog.picture.width() >= 0.55 * width and dialog.picture.height() >= 0.8 * height
    qtbot.mouseClick(dialog.close_button, QtCore.Qt.MouseButton.LeftButton)
    assert not dialog.isVisible()


@pytest.mark.parametrize(("width", "height"), SIZES, ids=IDS)
def test_every_simulation_button_is_in_view_without_scrolling(
    make_window, qtbot, tmp_path, width, height
) -> None:
    window = make_window({"source": "virtual"})
    window.resize(width, height)
    tab = window.simulation_tab
    window.work_tabs.setCurrentWidget(tab)
    tab.output_dir.setText(str(tmp_path / "simulations"))
    with qtbot.waitSignal(tab.finished, timeout=60_000):
        tab.run_button.click()  # the small study: its table, heatmap and run folder shown
    assert tab.open_button.isEnabled() and tab.heatmap_shown() is not None
    assert (window.width(), window.height()) == (width, height)
    problems: dict[str, list[str]] = {}
    seen: set[str] = set()
    for k in range(tab.pages.count()):
        tab.pages.setCurrentIndex(k)
        settle(qtbot)
        choosers = [c for c in (tab.combo_choice, tab.z_choice) if c.isVisible()]
        seen |= {b.text() for b in shown_buttons(window, tab)} | {name(c) for c in choosers}
        if found := problems_on_page(window, tab, choosers):
            problems[tab.pages.tabText(k)] = found
    assert not problems, problems
    assert seen >= SIMULATION_BUTTONS | {"heatmap_combination", "heatmap_z"}, seen
    assert tab.table.height() >= 80  # the coverage table stays readable (it scrolls inside itself)
