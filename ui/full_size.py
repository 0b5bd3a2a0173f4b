"""A picture at its own size in a window of its own: the Analysis plots and the simulation heatmap.

:func:`full_size_window` opens (non-modal, deleted when closed) a dialog that shows the pixmap
unscaled in a scroll area (drag or the scroll bars to pan), sized to the picture and never larger
than the screen's free area (an 800x480 display gets the whole screen), with a Close button a
finger can hit.
"""

from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

from ui.touch import fit_to_screen, touch_button

#: Room around the picture for the frame, the scroll bars and the Close row (px).
MARGIN_PX = QtCore.QSize(40, 100)


def full_size_window(
    parent: QtWidgets.QWidget | None, pixmap: QtGui.QPixmap, title: str, name: str = "full_size"
) -> QtWidgets.QDialog:
    """Show ``pixmap`` at its own size in a new window titled ``title``; returns the window."""
    dialog = QtWidgets.QDialog(parent)
    dialog.setObjectName(name)
    dialog.setWindowTitle(f"qrfield — {title}")
    dialog.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose)
    picture = QtWidgets.QLabel()
    picture.setObjectName(f"{name}_picture")
    picture.setPixmap(pixmap)
    area = QtWidgets.QScrollArea()
    area.setWidget(picture)
    area.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
    close = touch_button("Close", f"{name}_close")
    close.clicked.connect(dialog.close)
    row = QtWidgets.QHBoxLayout()
    row.addStretch(1)
    row.addWidget(close)
    layout = QtWidgets.QVBoxLayout(dialog)
    layout.setContentsMargins(4, 4, 4, 4)
    layout.addWidget(area, 1)
    layout.addLayout(row)
    fit_to_screen(dialog, parent, pixmap.size() + MARGIN_PX)
    dialog.show()
    return dialog
