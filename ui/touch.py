"""Finger-sized controls: every touch target of the app at least :data:`TOUCH_PX` high.

The Raspberry Pi Touch Display is 800x480 on 7" (about 130 px per inch), so a 9 mm fingertip is
about 47 px; 44 px (8.6 mm) is the floor. One style sheet, set on the application by
:func:`install_touch_style` (the window calls it, so every dialog and message box opened over it
follows), makes buttons, tool buttons, text fields, combo boxes and their lists, tabs, list rows
and menu items that high, and gives spin boxes two step buttons of 44x44 px, down on the left and
up on the right, in place of the two small arrows stacked in 20 px. The same filter that polishes
them gives combo boxes a delegate that obeys the style sheet (Qt's default one ignores it).

Check boxes are :class:`TouchCheckBox`: 44 px high and toggled by a tap anywhere on them (a plain
QCheckBox answers only on its indicator and text, 17 px). Message boxes and file dialogs are made by
:func:`message_box` and :func:`file_dialog` (Qt's own dialog, not the desktop's, which no style
sheet reaches), sized to the screen; the ``ask_*`` methods of the tabs run them, and tests measure
them unrun. ``tests/ui/test_app_layout.py`` measures every one at 800x480.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from PySide6 import QtCore, QtGui, QtWidgets

#: Height of every touch target (px): 8.6 mm on a 7" 800x480 display.
TOUCH_PX = 44

#: The app's style sheet. Heights are the content's, so that with Fusion's 1 px borders and
#: paddings each control comes out at exactly TOUCH_PX (tests/ui/test_app_layout.py measures
#: them): no higher, so that the Session tab keeps room for its rows at 800x480.
TOUCH_STYLE = f"""
QPushButton, QToolButton, QComboBox, QLineEdit {{
    min-height: {TOUCH_PX - 2}px; max-height: {TOUCH_PX - 2}px;
}}
QAbstractSpinBox {{
    min-height: {TOUCH_PX - 6}px; max-height: {TOUCH_PX - 6}px;
    padding-left: {TOUCH_PX + 2}px; padding-right: {TOUCH_PX + 2}px;
}}
QAbstractSpinBox::up-button {{
    subcontrol-origin: border; subcontrol-position: center right; width: {TOUCH_PX}px; height: {TOUCH_PX}px;
}}
QAbstractSpinBox::down-button {{
    subcontrol-origin: border; subcontrol-position: center left; width: {TOUCH_PX}px; height: {TOUCH_PX}px;
}}
QTabBar::tab {{ min-height: {TOUCH_PX}px; }}
QCheckBox, QRadioButton {{ min-height: {TOUCH_PX}px; }}
QCheckBox::indicator, QRadioButton::indicator {{ width: 24px; height: 24px; }}
QListView::item, QTreeView::item {{ min-height: {TOUCH_PX}px; }}
QComboBox QAbstractItemView::item {{ min-height: {TOUCH_PX}px; }}
QMenu::item {{ padding: 13px 24px 13px 24px; }}
"""


class TouchPolish(QtCore.QObject):
    """As each widget is polished: a combo box gets a delegate that draws its list rows as the
    style sheet says (TOUCH_PX high); a form's label gets the height of its 44 px field, its text
    centred beside it (a QFormLayout puts it at the top). Install it once with
    :func:`install_touch_style`."""

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:
        if event.type() != QtCore.QEvent.Type.Polish:
            return False
        if isinstance(watched, QtWidgets.QComboBox):
            if not isinstance(watched.itemDelegate(), QtWidgets.QStyledItemDelegate):
                watched.setItemDelegate(QtWidgets.QStyledItemDelegate(watched))
        elif isinstance(watched, QtWidgets.QLabel) and _form_label(watched):
            watched.setMinimumHeight(max(watched.minimumHeight(), TOUCH_PX))
            align = QtCore.Qt.AlignmentFlag
            horizontal = watched.alignment() & align.AlignHorizontal_Mask
            watched.setAlignment(horizontal | align.AlignVCenter)
        return False


def _form_label(label: QtWidgets.QLabel) -> bool:
    """``label`` is the label of a row of a QFormLayout."""
    parent = label.parentWidget()
    layout = parent.layout() if parent is not None else None
    forms = [layout, *(layout.findChildren(QtWidgets.QFormLayout) if layout is not None else [])]
    for form in forms:
        if isinstance(form, QtWidgets.QFormLayout):
            _row, role = form.getWidgetPosition(label)
            if role == QtWidgets.QFormLayout.ItemRole.LabelRole:
                return True
    return False


def install_touch_style(app: QtWidgets.QApplication | None = None) -> None:
    """Set :data:`TOUCH_STYLE` on the application (once; an app's own style sheet is kept after it)
    and install the :class:`TouchPolish` filter."""
    app = app or QtWidgets.QApplication.instance()
    assert app is not None, "make the QApplication first"
    if app.findChild(TouchPolish, "touch_polish") is not None:
        return
    polish = TouchPolish(app)
    polish.setObjectName("touch_polish")
    app.installEventFilter(polish)
    app.setStyleSheet(TOUCH_STYLE + app.styleSheet())


def touch_button(text: str, name: str = "") -> QtWidgets.QPushButton:
    """A push button a finger can hit (:data:`TOUCH_PX` high)."""
    button = QtWidgets.QPushButton(text)
    button.setMinimumHeight(TOUCH_PX)
    if name:
        button.setObjectName(name)
    return button


class TouchCheckBox(QtWidgets.QCheckBox):
    """A check box :data:`TOUCH_PX` high that a tap anywhere on it toggles (its row, not only the
    small square and its text)."""

    def __init__(self, text: str = "", parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(text, parent)
        self.setMinimumHeight(TOUCH_PX)

    def hitButton(self, pos: QtCore.QPoint) -> bool:
        return self.rect().contains(pos)


def fit_to_screen(dialog: QtWidgets.QWidget, parent: QtWidgets.QWidget | None, wanted: QtCore.QSize) -> None:
    """Resize ``dialog`` to ``wanted``, never larger than the free area of the screen it opens on."""
    screen = (parent.screen() if parent is not None else None) or QtGui.QGuiApplication.primaryScreen()
    if screen is None:
        dialog.resize(wanted)
        return
    free = screen.availableGeometry()
    frame = dialog.frameGeometry().size() - dialog.geometry().size()  # the title bar, once shown
    room = QtCore.QSize(free.width() - max(0, frame.width()), free.height() - max(0, frame.height()))
    dialog.resize(min(wanted.width(), room.width()), min(wanted.height(), room.height()))


def message_box(
    parent: QtWidgets.QWidget | None,
    title: str,
    text: str,
    buttons: Sequence[tuple[str, str, QtWidgets.QMessageBox.ButtonRole]],
    icon: QtWidgets.QMessageBox.Icon = QtWidgets.QMessageBox.Icon.Question,
) -> tuple[QtWidgets.QMessageBox, dict[str, QtWidgets.QAbstractButton]]:
    """A message box, not run: ``buttons`` are (name, text, role); returns the box and its buttons
    by name (:func:`answer` runs it)."""
    box = QtWidgets.QMessageBox(parent)
    box.setIcon(icon)
    box.setWindowTitle(title)
    box.setText(text)
    made = {}
    for name, label, role in buttons:
        button = box.addButton(label, role)
        button.setMinimumHeight(TOUCH_PX)
        made[name] = button
    return box, made


def answer(box: QtWidgets.QMessageBox, buttons: dict[str, QtWidgets.QAbstractButton], default: str) -> str:
    """Run ``box``; the name of the button pressed (``default`` when it was closed otherwise)."""
    box.exec()
    clicked = box.clickedButton()
    return next((name for name, button in buttons.items() if button is clicked), default)


def yes_no(parent: QtWidgets.QWidget | None, title: str, text: str) -> tuple[QtWidgets.QMessageBox, dict]:
    """A Yes / No question (No is the default button), not run."""
    role = QtWidgets.QMessageBox.ButtonRole
    box, buttons = message_box(parent, title, text, [("yes", "Yes", role.YesRole), ("no", "No", role.NoRole)])
    box.setDefaultButton(buttons["no"])  # type: ignore[arg-type]
    return box, buttons


#: What a file dialog chooses: an existing file, a file to write, an existing folder.
OPEN, SAVE, FOLDER = "open", "save", "folder"
#: A file dialog's size when the screen allows (px).
FILE_DIALOG_SIZE = QtCore.QSize(760, 520)


def file_dialog(
    parent: QtWidgets.QWidget | None,
    caption: str,
    directory: str | Path = "",
    *,
    mode: str = OPEN,
    name_filter: str = "",
) -> QtWidgets.QFileDialog:
    """Qt's own file dialog (the desktop's is beyond the style sheet: 20 px rows), not run: ``mode``
    OPEN, SAVE or FOLDER; ``directory`` may name the file offered; sized to the screen."""
    dialog = QtWidgets.QFileDialog(parent, caption, str(directory), name_filter)
    dialog.setOption(QtWidgets.QFileDialog.Option.DontUseNativeDialog, True)
    if mode == SAVE:
        dialog.setAcceptMode(QtWidgets.QFileDialog.AcceptMode.AcceptSave)
        dialog.setFileMode(QtWidgets.QFileDialog.FileMode.AnyFile)
    elif mode == FOLDER:
        dialog.setFileMode(QtWidgets.QFileDialog.FileMode.Directory)
        dialog.setOption(QtWidgets.QFileDialog.Option.ShowDirsOnly, True)
    elif mode == OPEN:
        dialog.setFileMode(QtWidgets.QFileDialog.FileMode.ExistingFile)
    else:
        raise ValueError(f"file dialog mode {mode!r}: one of {OPEN}, {SAVE}, {FOLDER}")
    fit_to_screen(dialog, parent, FILE_DIALOG_SIZE)
    return dialog


def chosen_path(dialog: QtWidgets.QFileDialog) -> str:
    """Run ``dialog``; the path chosen, "" when cancelled."""
    if dialog.exec() != QtWidgets.QDialog.DialogCode.Accepted:
        return ""
    files = dialog.selectedFiles()
    return files[0] if files else ""


def ask_path(
    parent: QtWidgets.QWidget | None, caption: str, directory: str | Path = "", **options: str
) -> str:
    """:func:`file_dialog` (``mode``, ``name_filter``) run: the path chosen, "" when cancelled."""
    return chosen_path(file_dialog(parent, caption, directory, **options))
