"""The app's one wheel filter: a wheel turn over a control without focus changes nothing and
scrolls the page instead; once the control has focus, the wheel changes it as usual."""

from __future__ import annotations

import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from ui.wheel_guard import install_wheel_guard

pytestmark = pytest.mark.gui
WAIT_MS = 15000


def wheel(widget: QtWidgets.QWidget, notches: int = -1) -> None:
    """``notches`` clicks of a mouse wheel over the middle of ``widget`` (negative: towards the user)."""
    local = QtCore.QPointF(widget.width() / 2, widget.height() / 2)
    event = QtGui.QWheelEvent(
        local,
        QtCore.QPointF(widget.mapToGlobal(local.toPoint())),
        QtCore.QPoint(),
        QtCore.QPoint(0, 120 * notches),
        QtCore.Qt.MouseButton.NoButton,
        QtCore.Qt.KeyboardModifier.NoModifier,
        QtCore.Qt.ScrollPhase.NoScrollPhase,
        False,
    )
    QtWidgets.QApplication.sendEvent(widget, event)


@pytest.fixture
def page(qtbot):
    """A scrolled page: a line edit, a spin box, a combo box, a slider, a tab bar, then filler."""
    install_wheel_guard()
    area = QtWidgets.QScrollArea()
    content = QtWidgets.QWidget()
    layout = QtWidgets.QVBoxLayout(content)
    widgets = {
        "edit": QtWidgets.QLineEdit(),
        "spin": QtWidgets.QSpinBox(),
        "double": QtWidgets.QDoubleSpinBox(),
        "combo": QtWidgets.QComboBox(),
        "slider": QtWidgets.QSlider(QtCore.Qt.Orientation.Horizontal),
        "tabs": QtWidgets.QTabBar(),
    }
    widgets["spin"].setRange(0, 100)
    widgets["spin"].setValue(50)
    widgets["double"].setValue(5.0)
    widgets["combo"].addItems(["numerical", "ippe", "both"])
    widgets["slider"].setRange(0, 100)
    widgets["slider"].setValue(50)
    for title in ("one", "two", "three"):
        widgets["tabs"].addTab(title)
    for widget in widgets.values():
        layout.addWidget(widget)
    for k in range(60):
        layout.addWidget(QtWidgets.QLabel(f"line {k}"))
    area.setWidget(content)
    area.setWidgetResizable(True)
    area.resize(300, 220)
    qtbot.addWidget(area)
    area.show()
    qtbot.waitExposed(area)
    widgets["edit"].setFocus()
    qtbot.waitUntil(lambda: widgets["edit"].hasFocus())
    return area, widgets


def values(widgets) -> tuple:
    return (
        widgets["spin"].value(),
        widgets["double"].value(),
        widgets["combo"].currentText(),
        widgets["slider"].value(),
        widgets["tabs"].currentIndex(),
    )


def test_a_control_without_focus_keeps_its_value_and_the_page_scrolls(page) -> None:
    area, widgets = page
    before = values(widgets)
    bar = area.verticalScrollBar()
    for name in ("spin", "double", "combo", "slider", "tabs"):
        position = bar.value()
        wheel(widgets[name])
        assert values(widgets) == before, name
        assert bar.value() > position, f"the page did not scroll over the {name}"
    assert all(not widgets[n].hasFocus() for n in ("spin", "double", "combo", "slider"))  # no focus by wheel


def test_a_focused_control_takes_the_wheel(page, qtbot) -> None:
    area, widgets = page
    spin, combo = widgets["spin"], widgets["combo"]
    spin.setFocus()
    qtbot.waitUntil(spin.hasFocus)
    position = area.verticalScrollBar().value()
    wheel(spin)  # towards the user: one step down
    assert spin.value() == 49 and area.verticalScrollBar().value() == position
    combo.setFocus()
    qtbot.waitUntil(combo.hasFocus)
    wheel(combo)
    assert combo.currentText() == "ippe"


@pytest.mark.slow
def test_the_app_installs_one_guard(make_window, qtbot) -> None:
    from ui.wheel_guard import WheelGuard

    make_window({"source": "virtual"})
    make_window({"source": "virtual"})
    app = QtWidgets.QApplication.instance()
    assert len(app.findChildren(WheelGuard)) == 1


@pytest.mark.slow
def test_scrolling_the_solver_page_does_not_switch_the_solver(make_window, qtbot) -> None:
    """The bug as reported: the wheel over the method box switched numerical to ippe."""
    window = make_window({"source": "virtual", "method": "numerical"})
    window.resize(800, 480)
    window.work_tabs.setCurrentWidget(window.tabs)
    window.tabs.setCurrentIndex(1)  # Detect & solve, a page that scrolls at 800x480
    method = window.solver_controls.method
    qtbot.waitUntil(method.isVisible, timeout=WAIT_MS)
    n_max = window.solver_controls.forms["numerical"].widgets["n_max"]
    before = n_max.value()
    window.session_panel.form.note.setFocus()
    for _ in range(5):
        wheel(method)
        wheel(n_max)
    assert method.currentText() == "numerical" and window.app_settings.method == "numerical"
    assert n_max.value() == before
