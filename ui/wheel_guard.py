"""One event filter for the whole app: the mouse wheel never changes a control that lacks focus.

Without it, scrolling a page with the wheel changes every spin box, combo box, slider or tab bar
that passes under the pointer (the solver switched from numerical to ippe that way). With it, a
wheel event over such a control without keyboard focus goes on to the control's parents, so the
page scrolls; once the operator has clicked (or tabbed) into the control, the wheel changes it.

How: the filter takes the event away from the control and sends a copy to the viewport of the
nearest scroll area around it (the page, a list, a table), which scrolls as if the pointer were
over empty space. Qt would propagate an *ignored* wheel event to the parents by itself, but only
a spontaneous one (``QApplication::notify``, case QEvent::Wheel: synthesized wheel events are not
propagated), so the filter forwards it itself: the same path for a real wheel and for a test's.
Controls that Qt gives focus *by* wheel (``Qt::WheelFocus``: spin boxes and combo boxes) are
polished to ``Qt::StrongFocus``, so a wheel turn cannot focus them first.
"""

from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

#: Controls whose value the wheel changes.
GUARDED = (QtWidgets.QAbstractSpinBox, QtWidgets.QComboBox, QtWidgets.QAbstractSlider, QtWidgets.QTabBar)
#: Scroll bars are sliders too, but scrolling them is what the wheel is for.
UNGUARDED = (QtWidgets.QScrollBar,)


def guarded(widget: QtCore.QObject) -> bool:
    """True for a control whose value the wheel would change."""
    return isinstance(widget, GUARDED) and not isinstance(widget, UNGUARDED)


class WheelGuard(QtCore.QObject):
    """The filter; install it once with :func:`install_wheel_guard`."""

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.passed_on = 0  # wheel events sent on to a parent (for tests and curiosity)

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:
        kind = event.type()
        if kind == QtCore.QEvent.Type.Polish and guarded(watched):
            if watched.focusPolicy() == QtCore.Qt.FocusPolicy.WheelFocus:
                watched.setFocusPolicy(QtCore.Qt.FocusPolicy.StrongFocus)
        elif kind == QtCore.QEvent.Type.Wheel and guarded(watched) and not _focused(watched):
            self.passed_on += 1
            _forward(watched, event)
            return True  # the control never sees it
        return False


def _forward(widget: QtWidgets.QWidget, event: QtGui.QWheelEvent) -> None:
    """Send ``event`` on to the viewport of the nearest scroll area around ``widget`` (if any)."""
    parent = widget.parentWidget()
    while parent is not None and not isinstance(parent, QtWidgets.QAbstractScrollArea):
        parent = parent.parentWidget()
    if parent is None:
        return
    viewport = parent.viewport()
    position = QtCore.QPointF(viewport.mapFromGlobal(event.globalPosition().toPoint()))
    copy = QtGui.QWheelEvent(
        position,
        event.globalPosition(),
        event.pixelDelta(),
        event.angleDelta(),
        event.buttons(),
        event.modifiers(),
        event.phase(),
        event.inverted(),
    )
    QtWidgets.QApplication.sendEvent(viewport, copy)


def _focused(widget: QtWidgets.QWidget) -> bool:
    """The widget or a part of it (a combo box's line edit, a spin box's editor) has focus."""
    focus = QtWidgets.QApplication.focusWidget()
    return focus is not None and (focus is widget or widget.isAncestorOf(focus))


def install_wheel_guard(app: QtWidgets.QApplication | None = None) -> WheelGuard:
    """Install the app's one :class:`WheelGuard` (again: returns the one installed)."""
    app = app or QtWidgets.QApplication.instance()
    assert app is not None, "make the QApplication first"
    existing = app.findChild(WheelGuard, "wheel_guard")
    if existing is not None:
        return existing
    guard = WheelGuard(app)
    guard.setObjectName("wheel_guard")
    app.installEventFilter(guard)
    return guard
