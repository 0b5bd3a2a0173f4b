"""The window fits a Raspberry Pi Touch Display (800x480), 1024x600 and a desktop: on every tab no
label's text is cut (a label at least as wide as its text, or tall enough for its wrapped lines),
no two widgets of a layout overlap, every tab title shows, and the Session tab's buttons are all
in view without scrolling.

Touch targets (:func:`touch_problems`): at 800x480 every control of every tab, Setup page and
dialog an operator can tap (buttons, tool buttons, check boxes over their whole tappable area,
text fields, combo boxes and the rows of their lists, spin boxes and each of their step buttons,
tabs, the rows of lists) is at least TOUCH_PX (44 px) high and wide, and can be reached: inside
its window, or inside the page of the scroll area that holds it. Measured on the Session tab with
and without a plan, the Analysis tab with its plots, every Setup page, the New session, Resume and
calibration dialogs, every kind of message box and file dialog the app opens, and the full-size
picture windows. Not counted: tables (they show rows, no action is a tap on one) and scroll bars
(a list is scrolled by its rows; noted in docs/app.md)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from ui.touch import TOUCH_PX, TouchCheckBox

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
    if label.buddy() is not None:  # "&type" is drawn "type", its letter underlined
        text = text.replace("&&", "\0").replace("&", "").replace("\0", "&")
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


# ------------------------------------------------------------------------------------ touch targets
#: What a finger taps (tables and scroll bars are left out: see the module docstring).
CONTROLS = (QtWidgets.QAbstractButton, QtWidgets.QComboBox, QtWidgets.QLineEdit, QtWidgets.QAbstractSpinBox)


def part_of_a_control(widget: QtWidgets.QWidget) -> bool:
    """The line edit inside a spin box or an editable combo box (measured as that control)."""
    parent = widget.parentWidget()
    return isinstance(widget, QtWidgets.QLineEdit) and isinstance(
        parent, (QtWidgets.QAbstractSpinBox, QtWidgets.QComboBox)
    )


def reach_problem(top: QtWidgets.QWidget, widget: QtWidgets.QWidget) -> str:
    """Why ``widget`` cannot be reached in ``top`` ("" when it can: in view, or in the page of the
    scroll area around it, which scrolls to it)."""
    area = widget.parentWidget()
    while area is not None and not isinstance(area, QtWidgets.QScrollArea):
        area = area.parentWidget()
    if area is not None and area.widget() is not None:
        page = area.widget()
        where = QtCore.QRect(widget.mapTo(page, QtCore.QPoint(0, 0)), widget.size())
        return (
            "" if page.rect().contains(where) else f"outside its scroll area's page {page.rect().getRect()}"
        )
    where = QtCore.QRect(widget.mapTo(top, QtCore.QPoint(0, 0)), widget.size())
    if not top.rect().contains(where):
        return f"at {where.getRect()}, outside {top.rect().getRect()}"
    if not in_scroll_area(widget) and clipped_by_parents(widget):
        return "partly hidden by its parents"
    return ""


def small(width: int, height: int) -> str:
    return f"{width}x{height} px" if min(width, height) < TOUCH_PX else ""


def control_problem(widget: QtWidgets.QWidget) -> str:
    """Why ``widget`` is too small for a finger ("" when it is not)."""
    if isinstance(widget, QtWidgets.QCheckBox) and not isinstance(widget, TouchCheckBox):
        option = QtWidgets.QStyleOptionButton()
        widget.initStyleOption(option)
        rect = widget.style().subElementRect(QtWidgets.QStyle.SubElement.SE_CheckBoxClickRect, option, widget)
        if problem := small(rect.width(), rect.height()):
            return f"its tappable area is {problem}"
    if isinstance(widget, QtWidgets.QAbstractSpinBox):
        option = QtWidgets.QStyleOptionSpinBox()
        option.initFrom(widget)
        option.frame = widget.hasFrame()
        option.subControls = QtWidgets.QStyle.SubControl.SC_All
        for part in (QtWidgets.QStyle.SubControl.SC_SpinBoxUp, QtWidgets.QStyle.SubControl.SC_SpinBoxDown):
            rect = widget.style().subControlRect(
                QtWidgets.QStyle.ComplexControl.CC_SpinBox, option, part, widget
            )
            if problem := small(rect.width(), rect.height()):
                return f"its {part.name} step button is {problem}"
    if isinstance(widget, QtWidgets.QComboBox) and widget.count():
        row = widget.view().sizeHintForRow(0)
        if row < TOUCH_PX:
            return f"the rows of its list are {row} px high"
    return small(widget.width(), widget.height())


def row_problem(view: QtWidgets.QAbstractItemView) -> str:
    """The first row of a list or tree view is finger-sized ("" when it is, or there is none)."""
    model = view.model()
    if (
        model is None
        or isinstance(view, QtWidgets.QTableView)
        or view.objectName() == "qt_scrollarea_viewport"
    ):
        return ""
    index = model.index(0, 0, view.rootIndex())
    if not index.isValid():
        return ""
    rect = view.visualRect(index)
    return f"its rows are {rect.height()} px high" if 0 < rect.height() < TOUCH_PX else ""


def touch_problems(top: QtWidgets.QWidget) -> list[str]:
    """Every visible tap target of ``top`` (a window or dialog) too small or out of reach."""
    found = []
    for widget in top.findChildren(QtWidgets.QWidget):
        if not widget.isVisible() or widget.window() is not top:
            continue
        text = widget.text() if isinstance(widget, (QtWidgets.QAbstractButton, QtWidgets.QLineEdit)) else ""
        label = f"{name(widget)} {text!r}"
        if isinstance(widget, QtWidgets.QTabBar):
            for k in range(widget.count()):
                rect = widget.tabRect(k)
                if problem := small(rect.width(), rect.height()):
                    found.append(f"tab {widget.tabText(k)!r} of {name(widget.parentWidget())}: {problem}")
            continue
        if isinstance(widget, QtWidgets.QAbstractItemView):
            if problem := row_problem(widget):
                found.append(f"{label}: {problem}")
            continue
        if not isinstance(widget, CONTROLS) or part_of_a_control(widget):
            continue
        if isinstance(widget.parentWidget(), (QtWidgets.QTabBar, QtWidgets.QAbstractItemView)):
            continue  # a tab bar's arrows (shown when its tabs do not fit: tested above), a table's corner
        problem = control_problem(widget) or reach_problem(top, widget)
        if problem:
            found.append(f"{label}: {problem}")
    return found


def each_page(tabs: QtWidgets.QTabWidget) -> Iterator[str]:
    for k in range(tabs.count()):
        tabs.setCurrentIndex(k)
        yield tabs.tabText(k)


def show_plots(window, tmp_path) -> None:
    """An analysis result on the Analysis tab (its two plots: PNGs larger than the tab)."""
    import cv2
    import numpy as np

    plots = []
    for k, (w, h) in enumerate(((1000, 700), (900, 900))):
        path = tmp_path / f"plot{k}.png"
        cv2.imwrite(str(path), np.full((h, w, 3), 90 + 60 * k, np.uint8))
        plots.append(str(path))
    errors = {"pos_mm": 0.1, "alpha_deg": 0.1, "beta_deg": 0.1, "gamma_deg": 0.1}
    window.analysis_tab.job.finished.emit(
        {
            "session": str(tmp_path),
            "out_dir": str(tmp_path),
            "out_note": "",
            "pass_rate": 1.0,
            "passed": 1,
            "rows": 1,
            "no_pose": 0,
            "report": "pass rate 100.00%",
            "per_combination": [],
            "mean_abs_error": errors,
            "max_abs_error": errors,
            "plots": plots,
        }
    )


def window_with_a_session(make_window, qtbot, tmp_path, monkeypatch, size=(800, 480)):
    """A window of ``size`` on the virtual bench with a session open, frames coming."""
    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "sessions"))
    window = make_window({"source": "virtual", "method": "both"})
    window.resize(*size)
    panel = window.session_panel
    panel.name_edit.setText("touch")
    assert panel.create_from_form() is not None
    qtbot.waitUntil(
        lambda: panel.log_button.isEnabled() and panel.form.follow_box.isVisible(), timeout=WAIT_MS
    )
    return window


def test_every_control_of_every_tab_is_finger_sized_at_800x480(
    make_window, qtbot, tmp_path, monkeypatch
) -> None:
    from qrfield.sessions.plan import generate_plan, write_plan

    window = window_with_a_session(make_window, qtbot, tmp_path, monkeypatch)
    panel = window.session_panel
    panel.banner.show()  # the pending-rows banner's buttons too
    show_plots(window, tmp_path)
    problems: dict[str, list[str]] = {}
    for page in pages(window):
        inner = {"Analysis": window.analysis_tab.pages, "Simulation": window.simulation_tab.pages}.get(page)
        for sub in each_page(inner) if inner is not None else [""]:
            settle(qtbot)
            if found := touch_problems(window):
                problems[f"{page} {sub}".strip()] = found
    # With a plan: the guide strip's chooser, "log when still" and Skip.
    plan = tmp_path / "plan.csv"
    write_plan(plan, generate_plan("alpha,beta", [10, 25], z_mm=300, x_mm=10, y_mm=-5))
    window.work_tabs.setCurrentWidget(panel)
    assert panel.load_plan(plan) is not None
    settle(qtbot)
    if found := touch_problems(window):
        problems["Session with a plan"] = found
    assert (window.width(), window.height()) == (800, 480)
    assert not problems, problems


def test_every_control_not_on_screen_is_finger_sized_too(make_window, qtbot, tmp_path, monkeypatch) -> None:
    """The tests above measure what is shown; controls that appear only in some states (Retry and
    Save pending… after a failed write, Reopen source, Cancel while a row is collected, the guide's
    Skip, the dialogs' buttons) are measured here by the height their style gives them."""
    window = window_with_a_session(make_window, qtbot, tmp_path, monkeypatch)
    hidden, small_ones = 0, []
    for widget in window.findChildren(QtWidgets.QWidget):
        if widget.isVisible() or not isinstance(widget, CONTROLS) or part_of_a_control(widget):
            continue
        if isinstance(widget.parentWidget(), (QtWidgets.QTabBar, QtWidgets.QAbstractItemView)):
            continue
        widget.ensurePolished()
        hidden += 1
        height = max(widget.sizeHint().height(), widget.minimumHeight())
        if height < TOUCH_PX:
            text = (
                widget.text() if isinstance(widget, (QtWidgets.QAbstractButton, QtWidgets.QLineEdit)) else ""
            )
            small_ones.append(f"{name(widget)} {text!r}: {height} px")
    assert hidden > 50  # the other tabs' controls, the banners' buttons, the dialogs' fields
    assert not small_ones, small_ones


def test_every_dialog_and_message_box_is_finger_sized_at_800x480(
    make_window, qtbot, tmp_path, monkeypatch
) -> None:
    from qrfield.sessions import Session
    from ui import touch

    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "sessions"))
    window = make_window({"source": "virtual", "method": "both"})
    window.resize(800, 480)
    panel = window.session_panel
    for name_ in ("first", "second"):  # sessions for Resume's list
        Session.create(
            tmp_path / "sessions", name_, camera=window.camera_model, side_mm=50.0, solver="numerical"
        ).close()
    problems: dict[str, list[str]] = {}

    def measure(title: str, dialog: QtWidgets.QWidget) -> None:
        """On an 800x480 screen (the offscreen one is larger: the dialog is held to 800x480)."""
        dialog.show()
        settle(qtbot)
        dialog.resize(min(dialog.width(), 800), min(dialog.height(), 480))
        settle(qtbot)
        if dialog.width() > 800 or dialog.height() > 480:
            problems.setdefault(title, []).append(f"{dialog.width()}x{dialog.height()}: larger than 800x480")
        if found := touch_problems(dialog) + cut_labels(dialog):
            problems.setdefault(title, []).extend(found)

    measure("New session", panel.show_new_dialog())
    panel.new_dialog.reject()
    measure("Resume", panel.show_resume_dialog())
    assert panel.resume_dialog.list.count() == 2
    panel.resume_dialog.reject()
    calibration = window.open_calibration()
    calibration.resize(800, 480)
    for page in each_page(calibration.pages):
        measure(f"calibration › {page}", calibration)
    calibration.close()
    boxes = {
        "Yes / No": touch.yes_no(panel, "Withdraw row", "Withdraw row 3? Its line stays in rows.csv."),
        "rows not written": panel.pending_choice_box("2 record(s) of session x are not written."),
        "combination": panel.combo_choice_box("'alpha' means α+ β0 γ0, the angles are (0, 40, 0)", "beta"),
    }
    for title, (box, _buttons) in boxes.items():
        measure(f"message box {title}", box)
        box.done(0)
    (tmp_path / "files").mkdir()
    for k in range(3):
        (tmp_path / "files" / f"rows-{k}.csv").write_text("row\n", encoding="utf-8")
    for mode in (touch.OPEN, touch.SAVE, touch.FOLDER):
        dialog = touch.file_dialog(
            panel, f"a file dialog ({mode})", tmp_path / "files", mode=mode, name_filter="CSV (*.csv)"
        )
        dialog.show()
        qtbot.waitUntil(lambda d=dialog: any(v.model() is not None and v.model().rowCount(v.rootIndex()) > 0
                                             for v in d.findChildren(QtWidgets.QListView) if v.isVisible()),
                        timeout=WAIT_MS)  # fmt: skip
        measure(f"file dialog ({mode})", dialog)
        dialog.reject()
    show_plots(window, tmp_path)
    for k in range(2):
        measure(f"plot {k} full size", window.analysis_tab.show_full_size(k))
    for title in problems:
        problems[title] = sorted(set(problems[title]))
    assert not problems, problems


def control_places(panel: QtWidgets.QWidget) -> dict[str, QtCore.QRect]:
    """Where each visible control of the Session tab is, in the tab's coordinates."""
    return {
        f"{name(w)}:{k}": QtCore.QRect(w.mapTo(panel, QtCore.QPoint(0, 0)), w.size())
        for k, w in enumerate(panel.findChildren(QtWidgets.QWidget))
        if w.isVisible() and isinstance(w, CONTROLS) and not part_of_a_control(w)
    }


@pytest.mark.parametrize(("width", "height"), SIZES[:2], ids=[f"{w}x{h}" for w, h in SIZES[:2]])
def test_messages_come_and_go_in_one_place_and_never_move_a_button(
    make_window, qtbot, tmp_path, monkeypatch, width, height
) -> None:
    """The issue's trap: a validation message pushed Log row down 17 px as the finger landed. Every
    message of the Session tab (the field's error, the combination's note, the status, why Log row
    is blocked, the session's warnings) now comes and goes below the buttons."""
    window = window_with_a_session(make_window, qtbot, tmp_path, monkeypatch, (width, height))
    panel = window.session_panel
    panel.form.follow_box.setChecked(False)
    panel.form.set_fields({"x": "10", "y": "-5", "z": "300", "alpha": "15", "beta": "0", "gamma": "0"})
    combo = panel.form.combo
    combo.setCurrentIndex(combo.findText("alpha"))
    combo.activated.emit(combo.currentIndex())  # picked from its list: the note beside it goes
    panel.status.setText("")
    settle(qtbot)
    before = control_places(panel)
    assert (
        not panel.form.problems.isVisible() and not panel.why.text() and not panel.form.combo_note.isVisible()
    )
    edit = panel.form.edits["z"]
    edit.selectAll()
    qtbot.keyClicks(edit, "3OO")  # a bad value: its message, and why Log row is blocked
    qtbot.keyClick(edit, QtCore.Qt.Key.Key_Return)  # "cannot log: fix z first"
    panel.form.set_fields({"beta": "40"})  # the combination's note: from the angles' signs
    panel._add_warning("the session's folder was moved")
    settle(qtbot)
    assert panel.form.problems.isVisible() and panel.why.isVisible() and panel.status.text()
    assert panel.form.combo_note.isVisible() and panel.warnings.isVisible()
    after = control_places(panel)
    moved = {k: (before[k].getRect(), after[k].getRect()) for k in before if after.get(k) != before[k]}
    assert not moved, moved
    assert not cut_labels(window) and (window.width(), window.height()) == (width, height)


def test_a_source_that_ended_after_poses_cuts_no_text_at_800x480(
    make_window, qtbot, tmp_path, monkeypatch, camera_vga
) -> None:
    """(audit-ui) A folder of three photos ends after its poses were shown: the red banner takes
    its rows, the pose panel turns STALE over the last values, and at 800x480 the STALE headline
    is whole (it wrapped onto a second line the panel had no room for, half behind the preview)."""
    import cv2

    from qrfield.geometry import Pose
    from qrfield.render import render_view

    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "sessions"))
    folder = tmp_path / "photos"
    folder.mkdir()
    pose = Pose([-20.0, 15.0, 350.0], [-10.0, 25.0, -30.0])
    for i in range(3):
        image = render_view(camera_vga, 50.0, pose, noise_sigma=2.0, seed=i).image
        cv2.imwrite(str(folder / f"img{i}.png"), image)
    window = make_window({"source": str(folder), "camera": "picam-v2@640x480", "method": "both"})
    window.resize(800, 480)
    panel = window.session_panel
    panel.name_edit.setText("ended")
    assert panel.create_from_form() is not None
    qtbot.waitUntil(window.banner_row.isVisible, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: window.pose_panel.headline.text().startswith("STALE"), timeout=WAIT_MS)
    settle(qtbot)
    assert (window.width(), window.height()) == (800, 480)
    headline = window.pose_panel.headline
    assert not clipped_by_parents(headline), headline.visibleRegion().boundingRect()
    assert not cut_labels(window) and not overlaps(window), (cut_labels(window), overlaps(window))
