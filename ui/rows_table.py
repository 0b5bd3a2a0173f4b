"""The session's rows in a table: ground truth, measured, errors and pass, as rows.csv holds them.

The model reads the session's :class:`~qrfield.sessions.LoggedRow` list (CSV texts, mm and
degrees) and shows pass green / fail red, withdrawn rows grey and struck through, and rows still
waiting to be written (not yet on disk) in italics with "pending".
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.geometry import ANGLE_NAMES, POSITION_NAMES
from qrfield.sessions import LoggedRow

PASS_COLOUR = QtGui.QColor("#c8f0c8")
FAIL_COLOUR = QtGui.QColor("#f6c6c6")
WITHDRAWN_COLOUR = QtGui.QColor("#909090")


def _triple(row: LoggedRow, columns: Sequence[str]) -> str:
    return ", ".join(row.values.get(c, "") or "–" for c in columns)


#: (header, text of a row) per table column; a header's second line is its unit.
COLUMNS: tuple[tuple[str, Callable[[LoggedRow], str]], ...] = (
    ("row", lambda r: str(r.number)),
    ("pass", lambda r: ("pass" if r.passed else "fail") + ("" if r.confirmed else " (pending)")),
    ("time", lambda r: r.values.get("time", "")[11:19] or r.values.get("time", "")),
    ("combo", lambda r: r.combo),
    ("truth x, y, z\nmm", lambda r: _triple(r, ("gt_x", "gt_y", "gt_z"))),
    ("truth α, β, γ\ndeg", lambda r: _triple(r, ("gt_alpha", "gt_beta", "gt_gamma"))),
    ("measured x, y, z\nmm", lambda r: _triple(r, POSITION_NAMES)),
    ("measured α, β, γ\ndeg", lambda r: _triple(r, ANGLE_NAMES)),
    ("err pos\nmm", lambda r: r.values.get("err_pos", "") or "–"),
    ("err α, β, γ\ndeg", lambda r: _triple(r, ("err_alpha", "err_beta", "err_gamma"))),
    ("frames", lambda r: f"{r.values.get('n_converged', '')}/{r.values.get('n_frames', '')}"),
    ("note", lambda r: r.values.get("note", "")),
)
DISPLAY = QtCore.Qt.ItemDataRole.DisplayRole
PASS_COLUMN = next(k for k, (header, _) in enumerate(COLUMNS) if header == "pass")


class RowsModel(QtCore.QAbstractTableModel):
    """A read-only view of a list of LoggedRow (the session's ``rows``, updated in place)."""

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self._rows: list[LoggedRow] = []

    def set_rows(self, rows: list[LoggedRow]) -> None:
        """Show ``rows`` (kept by reference: call :meth:`refresh` after the session changed them)."""
        self.beginResetModel()
        self._rows = rows
        self.endResetModel()

    def refresh(self) -> None:
        self.beginResetModel()
        self.endResetModel()

    def row_at(self, index: int) -> LoggedRow:
        return self._rows[index]

    def rowCount(self, parent: Any = QtCore.QModelIndex()) -> int:  # noqa: B008
        return 0 if parent.isValid() else len(self._rows)

    def columnCount(self, parent: Any = QtCore.QModelIndex()) -> int:  # noqa: B008
        return 0 if parent.isValid() else len(COLUMNS)

    def headerData(self, section: int, orientation: Any, role: int = DISPLAY) -> Any:
        if role == QtCore.Qt.ItemDataRole.DisplayRole and orientation == QtCore.Qt.Orientation.Horizontal:
            return COLUMNS[section][0]
        return None

    def data(self, index: QtCore.QModelIndex, role: int = QtCore.Qt.ItemDataRole.DisplayRole) -> Any:
        if not index.isValid():
            return None
        row = self._rows[index.row()]
        column = index.column()
        if role == QtCore.Qt.ItemDataRole.DisplayRole:
            text = COLUMNS[column][1](row)
            if column == PASS_COLUMN and row.withdrawn:
                text += " (withdrawn)"
            return text
        if role == QtCore.Qt.ItemDataRole.BackgroundRole and column == PASS_COLUMN and not row.withdrawn:
            return PASS_COLOUR if row.passed else FAIL_COLOUR
        if role == QtCore.Qt.ItemDataRole.ForegroundRole and row.withdrawn:
            return WITHDRAWN_COLOUR
        if role == QtCore.Qt.ItemDataRole.FontRole and (row.withdrawn or not row.confirmed):
            font = QtGui.QFont()
            font.setStrikeOut(row.withdrawn)
            font.setItalic(not row.confirmed)
            return font
        if role == QtCore.Qt.ItemDataRole.ToolTipRole:
            state = "withdrawn" if row.withdrawn else ("on disk" if row.confirmed else "NOT on disk yet")
            return f"row {row.number} ({state}), logged {row.values.get('time', '')}"
        return None


class RowsTable(QtWidgets.QTableView):
    """The table of rows; scrolls to the newest row when rows are added."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.rows_model = RowsModel(self)
        self.setModel(self.rows_model)
        self.setObjectName("rows_table")
        self.setAlternatingRowColors(True)
        self.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.verticalHeader().hide()
        self.horizontalHeader().setStretchLastSection(True)
        self.horizontalHeader().setTextElideMode(QtCore.Qt.TextElideMode.ElideNone)
        self.horizontalHeader().setDefaultAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self._settle()  # headers as wide as their text before any row (they were cut at both ends)

    def show_rows(self, rows: list[LoggedRow]) -> None:
        self.rows_model.set_rows(rows)
        self._settle()

    def refresh(self) -> None:
        self.rows_model.refresh()
        self._settle()

    def _settle(self) -> None:
        self.resizeColumnsToContents()
        self.scrollToBottom()

    def cell_text(self, row: int, header: str) -> str:
        """The text shown in a cell, by column header (for tests and copy)."""
        column = next(k for k, (name, _) in enumerate(COLUMNS) if name == header)
        return str(self.rows_model.data(self.rows_model.index(row, column)))
