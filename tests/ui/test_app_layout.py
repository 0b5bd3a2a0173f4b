"""The window fits a Raspberry Pi Touch Display (800x480), 1024x600 and a desktop: on every tab no
label's text is cut (a label at least as wide as its text, or tall enough for its wrapped lines),
no two widgets of a layout overlap, every tab title shows, and the Session tab's buttons are all
in view without scrolling, finger-sized for a session's actions."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from ui.session_dialogs import TOUCH_PX

pytestmark = [pytest.mark.gui, pytest.mark.slow]
WAIT_MS = 15000
SIZES = [(800, 480), (1024, 600), (1300, 820)]
#: The Session tab's buttons for a session's actions (finger-sized).
ACTION_BUTTONS = ("new_session", "resume", "export_rows", "log_row", "cancel_row", "undo_row")


def text_width(label: QtWidgets.QLabel, text: str) -> float:
    """Width (px) of ``text`` as ``label`` draws it on one line."""
    if label.textFormat() != QtCore.Qt.TextFormat.PlainText and QtGui.Qt.mightBeRichText(text):
        doc = QtGui.QTextDocument()
        doc.setDefaultFont(label.font())
        doc.setDocumentMargin(0)
        doc.setHtml(text)
        return doc.idealWidth()
    metrics = label.fontMetrics()
    return max(metrics.horizontalAdvance(line) for line in text.split("\n"))


def widest_line(label: QtWidgets.QLabel, text: str, room: int) -> float:
    """The widest line of ``text`` word-wrapped at ``room`` px as QLabel wraps it (at word
    boundaries and wherever Unicode allows a break, e.g. after a slash): an unbreakable run
    wider than ``room`` sticks out."""
    plain = (
        QtGui.QTextDocumentFragment.fromHtml(text).toPlainText() if QtGui.Qt.mightBeRichText(text) else text
    )
    layout = QtGui.QTextLayout(plain.replace("\n", "\u2028"), label.font())
    option = QtGui.QTextOption()
    option.setWrapMode(QtGui.QTextOption.WrapMode.WordWrap)
    layout.setTextOption(option)
    layout.beginLayout()
    widest = 0.0
    while True:
        line = layout.createLine()
        if not line.isValid():
            break
        line.setLineWidth(room)
        widest = max(widest, line.naturalTextWidth())
    layout.endLayout()
    return widest


def label_problem(label: QtWidgets.QLabel) -> str:
    """Why ``label``'s text is cut, or "" when it is shown whole."""
    text = label.text()
    room = label.contentsRect().width() - 2 * label.margin()
    if label.wordWrap():
        widest = widest_line(label, text, room)
        if widest > room + 1:
            return f"a word is {widest:.0f} px wide, the label {room} px"
        need = label.heightForWidth(label.width())
        if need > label.height() + 1:
            return f"its wrapped lines need {need} px, the label is {label.height()} px high"
        return ""
    width = text_width(label, text)
    if width > room + 1:
        return f"its text is {width:.0f} px wide, the label {room} px"
    return ""


def name(widget: QtWidgets.QWidget) -> str:
    """The widget's object name, else its class and its parent's."""
    parent = widget.parentWidget()
    return widget.objectName() or f"{type(widget).__name__} in {type(parent).__name__ if parent else '-'}"


def in_scroll_area(widget: QtWidgets.QWidget) -> bool:
    parent = widget.parentWidget()
    while parent is not None:
        if isinstance(parent, QtWidgets.QAbstractScrollArea):
            return True
        parent = parent.parentWidget()
    return False


def clipped_by_parents(widget: QtWidgets.QWidget) -> bool:
    """Part of the widget lies outside its parents (outside a scroll area, where that is a cut)."""
    return widget.visibleRegion().boundingRect().size() != widget.size()


def cut_labels(window: QtWidgets.QWidget) -> list[str]:
    out = []
    for label in window.findChildren(QtWidgets.QLabel):
        if not label.isVisible() or not label.text() or label.window() is not window:
            continue
        pixmap = label.pixmap()
        if pixmap is not None and not pixmap.isNull():
            continue
        problem = label_problem(label)
        if not problem and not in_scroll_area(label) and clipped_by_parents(label):
            problem = "its parents cut it off"
        if problem:
            out.append(f"{name(label)}: {label.text()!r}: {problem}")
    return out


def layout_widgets(layout: QtWidgets.QLayout) -> Iterator[QtWidgets.QWidget]:
    for k in range(layout.count()):
        item = layout.itemAt(k)
        if item.widget() is not None:
            yield item.widget()
        elif item.layout() is not None:
            yield from layout_widgets(item.layout())


def overlaps(window: QtWidgets.QWidget) -> list[str]:
    """Pairs of visible widgets of one layout whose areas intersect (a layout squeezed too far)."""
    out = []
    for parent in [window, *window.findChildren(QtWidgets.QWidget)]:
        layout = parent.layout()
        if layout is None or not parent.isVisible() or isinstance(layout, QtWidgets.QStackedLayout):
            continue
        shown = [w for w in layout_widgets(layout) if w.isVisible()]
        for i, a in enumerate(shown):
            for b in shown[i + 1 :]:
                if a.geometry().intersected(b.geometry()).isValid():
                    out.append(f"{name(a)} over {name(b)} in {name(parent)}")
    return out


def pages(window) -> Iterator[str]:
    """Show each tab (and each Setup page) in turn; yields its name."""
    tabs = window.work_tabs
    for i in range(tabs.count()):
        tabs.setCurrentIndex(i)
        if tabs.widget(i) is window.tabs:
            for k in range(window.tabs.count()):
                window.tabs.setCurrentIndex(k)
                yield f"Setup › {window.tabs.tabText(k)}"
        else:
            yield tabs.tabText(i)


def settle(qtbot) -> None:
    """Let layouts, word-wrapped heights and the redraw timer settle, then apply the layout
    requests still queued (a label whose text just changed is measured after its relayout)."""
    qtbot.wait(150)
    for _ in range(3):  # a relayout may ask for the next one (nested layouts)
        QtWidgets.QApplication.sendPostedEvents(None, QtCore.QEvent.Type.LayoutRequest)


@pytest.mark.parametrize(("width", "height"), SIZES, ids=[f"{w}x{h}" for w, h in SIZES])
def test_every_tab_fits_the_screen_with_no_cut_text(
    make_window, qtbot, tmp_path, monkeypatch, width, height
) -> None:
    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "sessions"))
    window = make_window({"source": "virtual", "method": "both"})
    window.resize(width, height)
    qtbot.waitUntil(lambda: window.frames_shown >= 3, timeout=WAIT_MS)
    panel = window.session_panel
    panel.name_edit.setText("layout-check")
    assert panel.create_from_form() is not None
    qtbot.waitUntil(lambda: panel.log_button.isEnabled(), timeout=WAIT_MS)
    assert (window.width(), window.height()) == (width, height)
    minimum = window.minimumSizeHint()
    assert minimum.width() <= width and minimum.height() <= height, minimum
    problems = {}
    for page in pages(window):
        settle(qtbot)
        found = cut_labels(window) + overlaps(window)
        if (window.width(), window.height()) != (width, height):  # a page wider than the screen
            found.append(f"the window grew to {window.width()}x{window.height()}")
        for tabs in (window.work_tabs, window.tabs):
            if tabs.isVisible() and tabs.tabBar().sizeHint().width() > tabs.width():
                found.append(f"the tab titles of {tabs.objectName()} need scrolling")
        if found:
            problems[page] = found
    assert not problems, problems


@pytest.mark.parametrize(("width", "height"), SIZES[:2], ids=[f"{w}x{h}" for w, h in SIZES[:2]])
def test_every_session_button_is_in_view_without_scrolling(
    make_window, qtbot, tmp_path, monkeypatch, width, height
) -> None:
    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "sessions"))
    window = make_window({"source": "virtual"})
    window.resize(width, height)
    panel = window.session_panel
    window.work_tabs.setCurrentWidget(panel)
    panel.name_edit.setText("buttons")
    assert panel.create_from_form() is not None
    qtbot.waitUntil(lambda: panel.log_button.isEnabled(), timeout=WAIT_MS)
    panel.banner.show()  # the pending-rows banner, as after a failed write: its buttons too
    settle(qtbot)
    assert not in_scroll_area(panel)  # the Session page itself never scrolls
    inside = window.rect()
    buttons = [b for b in panel.findChildren(QtWidgets.QPushButton) if b.window() is window and b.isVisible()]
    names = {b.objectName() for b in buttons}
    assert set(ACTION_BUTTONS) | {"retry_pending", "export_pending"} <= names, names
    for button in buttons:
        where = QtCore.QRect(button.mapTo(window, QtCore.QPoint(0, 0)), button.size())
        assert inside.contains(where), (button.text(), where, inside)
        assert not clipped_by_parents(button), button.text()
        assert button.fontMetrics().horizontalAdvance(button.text()) + 8 <= button.width(), button.text()
        if button.objectName() in ACTION_BUTTONS:
            assert button.height() >= TOUCH_PX, (button.text(), button.height())
    # The table of rows is in view too (it scrolls inside itself).
    table = panel.table
    assert inside.contains(QtCore.QRect(table.mapTo(window, QtCore.QPoint(0, 0)), table.size()))
    assert table.height() >= 60


def test_a_source_that_failed_cuts_no_text_at_800x480(make_window, qtbot, tmp_path, monkeypatch) -> None:
    """The red banner with a long reason, the empty preview and NO SOURCE still fit the screen."""
    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "sessions"))
    missing = tmp_path / "a-folder-with-a-long-name" / "and-another-one" / "camera-unplugged-recording.avi"
    window = make_window({"source": str(missing)})
    window.resize(800, 480)
    qtbot.waitUntil(window.banner_row.isVisible, timeout=WAIT_MS)
    panel = window.session_panel
    panel.name_edit.setText("no-source")
    assert panel.create_from_form() is not None
    settle(qtbot)
    assert (window.width(), window.height()) == (800, 480)
    assert window.preview_pane.is_empty and window.pose_panel.headline.text().startswith("NOSRC")
    assert not cut_labels(window) and not overlaps(window), (cut_labels(window), overlaps(window))
    assert window.preview_pane.height() >= 100  # the empty state stays readable under the banner
