"""The pose panel: x, y, z (mm) and alpha, beta, gamma (degrees) in large type, one column per
method (and the virtual bench's true pose beside them), each value with its standard uncertainty
(+- in small type, when the corners' covariance is known: docs/uncertainty.md), and each solver's
status below (with the flip warning of the core's mirror test, ``PoseResult.ambiguous``).

On a small screen (:meth:`PosePanel.set_compact`) the type is smaller and a solver's status line
is shown only when it warns. "STALE" is said only when a real pose was shown before the source
stopped; without one the panel says there is no source."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.geometry import Pose, angle_difference
from qrfield.sessions.criteria import AcceptanceCriteria
from ui.text import fixed

ROWS = (("x", "mm"), ("y", "mm"), ("z", "mm"), ("α", "°"), ("β", "°"), ("γ", "°"))
#: An ambiguity ratio at or above this counts as "the two mirror poses fit almost equally well".
AMBIGUITY_WARNING = 0.8
TRUTH = "true"
#: Point sizes (values, headline, column headers, the "+- std" beside a value) and the value
#: columns' width (px), by layout (compact: a small screen).
SIZES = {False: (22, 15, 12, 11, 100), True: (13, 11, 9, 7, 56)}
NBSP = "\u00a0"


def format_value(value: float, row: int) -> str:
    """A position (rows 0-2) in mm with 1 decimal, an angle in degrees with 2; "—" when unknown."""
    return fixed(value, 1 if row < 3 else 2)


def format_std(std: float) -> str:
    """ "±0.12" (two decimals, mm or degrees), or "" when the uncertainty is unknown."""
    return f"±{fixed(std, 2)}" if math.isfinite(std) else ""


def std_style(compact: bool) -> str:
    """Style of the "+- std" beside a value: small and grey, so the value stays the thing to read."""
    return f"font-size: {SIZES[compact][3]}pt; font-weight: normal; color: #888;"


def _pose_std(pose: Any) -> np.ndarray:
    """The six standard uncertainties of a PoseResult (NaN where unknown or absent)."""
    if pose is None:
        return np.full(6, np.nan)
    position = getattr(pose, "position_std_mm", None)
    angles = getattr(pose, "angles_std_deg", None)
    if position is None or angles is None:
        return np.full(6, np.nan)
    return np.concatenate([np.asarray(position, float), np.asarray(angles, float)])


def solver_status_text(result: Any) -> tuple[str, bool]:
    """One line about a PoseResult (converged, iterations, reprojection, ambiguity) and whether it warns."""
    if result is None:
        return "no pose", True
    parts = [
        "converged" if result.converged else "NOT converged",
        f"n = {result.iterations}",
        f"reproj {result.reprojection_px:.2f} px" if math.isfinite(result.reprojection_px) else "reproj —",
    ]
    warn = not result.converged
    if result.ambiguous:
        ambiguity = getattr(result, "ambiguity", None)
        ratio = f" (ambiguity {ambiguity:.2f})" if ambiguity is not None and math.isfinite(ambiguity) else ""
        parts.append(f"⚠ the mirror pose also fits the corners{ratio}: flip risk")
        warn = True
    if not result.converged and result.reason:
        parts.append(result.reason)
    return ", ".join(parts), warn


class PosePanel(QtWidgets.QWidget):
    """Large-type pose values per method, the true pose (virtual bench) and the error against it."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self._grid = QtWidgets.QGridLayout(self)
        self._grid.setHorizontalSpacing(18)
        self._columns: list[str] = []
        self._cells: dict[str, list[QtWidgets.QLabel]] = {}
        self._headers: dict[str, QtWidgets.QLabel] = {}
        self._status: dict[str, QtWidgets.QLabel] = {}
        self.headline = QtWidgets.QLabel("waiting for frames…")
        self.headline.setObjectName("headline")
        self.headline.setStyleSheet("font-size: 15pt; font-weight: bold;")
        self.headline.setWordWrap(True)
        self.verdict = QtWidgets.QLabel("")
        self.verdict.setObjectName("verdict")
        self.verdict.setWordWrap(True)
        self.compact = False
        self.has_pose = False  # a real pose has been shown (only then can values be stale)
        self._big = QtGui.QFont()
        self._big.setBold(True)
        self._big.setStyleHint(QtGui.QFont.StyleHint.Monospace)
        self._methods: tuple[str, ...] = ("numerical",)
        #: What the verdict against the true pose judges by (the session's; the seed's by default).
        self.criteria = AcceptanceCriteria()
        self._apply_sizes()
        self.set_columns(self._methods, truth=False)

    def set_criteria(self, criteria: AcceptanceCriteria) -> None:
        """Judge against ``criteria`` from the next result on."""
        self.criteria = criteria

    def set_compact(self, compact: bool) -> None:
        """Smaller type for a small screen (800x480, 1024x600)."""
        if compact == self.compact:
            return
        self.compact = compact
        self._apply_sizes()
        columns, self._columns = self._columns, []
        truth = TRUTH in columns
        self.set_columns(tuple(c for c in columns if c != TRUTH), truth)

    def _apply_sizes(self) -> None:
        big, headline, _header, _std, _width = SIZES[self.compact]
        self._big.setPointSize(big)
        self._headline_pt = headline
        self._grid.setHorizontalSpacing(10 if self.compact else 18)
        self._grid.setVerticalSpacing(0 if self.compact else 6)
        self._style_headline(self.headline.property("colour") or "")
        self.verdict.setStyleSheet("font-size: 8pt;" if self.compact else "")

    def _style_headline(self, colour: str) -> None:
        self.headline.setProperty("colour", colour)
        self.headline.setStyleSheet(
            f"font-size: {self._headline_pt}pt; font-weight: bold;" + (f" color: {colour};" if colour else "")
        )

    def set_columns(self, methods: tuple[str, ...], truth: bool) -> None:
        """One column per method, plus the true pose when ``truth``."""
        columns = [*methods, TRUTH] if truth else list(methods)
        if columns == self._columns:
            return
        while self._grid.count():
            item = self._grid.takeAt(0)
            if item.widget() is not None and item.widget() not in (self.headline, self.verdict):
                item.widget().deleteLater()
        self._columns = columns
        self._methods = tuple(methods)
        self._cells, self._headers, self._status = {}, {}, {}
        _big, _headline, header_pt, _std, width = SIZES[self.compact]
        self._grid.addWidget(self.headline, 0, 0, 1, len(columns) + 2)
        for c, name in enumerate(columns):
            header = QtWidgets.QLabel(name)
            header.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight)
            header.setStyleSheet(f"font-size: {header_pt}pt;" + (" color: #888;" if name == TRUTH else ""))
            self._grid.addWidget(header, 1, c + 1)
            self._headers[name] = header
            cells = []
            for r, _ in enumerate(ROWS):
                cell = QtWidgets.QLabel("—")
                cell.setProperty("value", "—")
                cell.setTextFormat(QtCore.Qt.TextFormat.RichText)
                cell.setFont(self._big)
                cell.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
                cell.setMinimumWidth(width)
                cell.setObjectName(f"{name}_{r}")
                if name == TRUTH:
                    cell.setStyleSheet("color: #888;")
                self._grid.addWidget(cell, r + 2, c + 1)
                cells.append(cell)
            self._cells[name] = cells
        for r, (symbol, unit) in enumerate(ROWS):
            name_label = QtWidgets.QLabel(symbol)
            name_label.setFont(self._big)
            self._grid.addWidget(name_label, r + 2, 0)
            self._grid.addWidget(QtWidgets.QLabel(unit), r + 2, len(columns) + 1)
        row = len(ROWS) + 2
        for name in methods:
            status = QtWidgets.QLabel("")
            status.setWordWrap(True)
            status.setObjectName(f"status_{name}")
            self._grid.addWidget(status, row, 0, 1, len(columns) + 2)
            self._status[name] = status
            row += 1
        self._grid.addWidget(self.verdict, row, 0, 1, len(columns) + 2)

    def show_result(self, result: Any, methods: tuple[str, ...]) -> None:
        """Show a qrfield.pipeline.FrameResult."""
        self.set_columns(methods, truth=result.truth is not None)
        text = f"{result.status}"
        if result.detection is not None and result.detection.text:
            text += f"   “{result.detection.text}”"
        if result.reason:
            text += f"   {result.reason}"
        self.headline.setText(text)
        self._style_headline({"OK": "#2a2", "NOQR": "#c80", "NOCONV": "#c40"}.get(result.status, "#d22"))
        for name in methods:
            pose = result.poses.get(name)
            values = (
                np.concatenate([pose.position_mm, pose.angles_deg])
                if pose is not None
                else np.full(6, np.nan)
            )
            if pose is not None and np.all(np.isfinite(values)):
                self.has_pose = True
            stds = _pose_std(pose)
            for r, cell in enumerate(self._cells[name]):
                self._set_cell(cell, format_value(float(values[r]), r), format_std(float(stds[r])))
            line, warn = solver_status_text(pose) if result.detection is not None else ("no code", False)
            self._status[name].setText(f"{name}: {line}")
            self._status[name].setStyleSheet("color: #d60;" if warn else "")
            self._status[name].setVisible(warn or not self.compact)
        if result.truth is not None:
            truth = np.concatenate([result.truth.position_mm, result.truth.angles_deg])
            for r, cell in enumerate(self._cells[TRUTH]):
                self._set_cell(cell, format_value(float(truth[r]), r), "")
        self.verdict.setText(self._verdict(result, methods))
        self.verdict.setVisible(bool(self.verdict.text()))

    def _set_cell(self, cell: QtWidgets.QLabel, value: str, std: str) -> None:
        """The value in large type, its "±std" (if any) small beside it; the plain value is kept
        in the cell's "value" property for :meth:`displayed`."""
        cell.setProperty("value", value)
        cell.setProperty("std", std)
        cell.setText(value + (f'<span style="{std_style(self.compact)}"> {std}</span>' if std else ""))

    def mark_stale(self, why: str) -> None:
        """The source stopped: "STALE" over the last real pose shown, or, when none was ever shown,
        "no source" and dashes (nothing measured can be stale)."""
        if not self.has_pose:
            self.show_no_source("")  # the banner says why
            return
        self.headline.setText(f"STALE: {why}" if why else "STALE")
        self._style_headline("#888")

    def show_no_source(self, why: str) -> None:
        """No frames: dashes in every value, and why."""
        self.headline.setText(f"NO SOURCE   {why}" if why else "NO SOURCE")
        self._style_headline("#888")
        for cells in self._cells.values():
            for cell in cells:
                self._set_cell(cell, "—", "")
        for status in self._status.values():
            status.setText("")
            status.hide()
        self.verdict.setText("")
        self.verdict.hide()

    def source_opened(self) -> None:
        """A new source: its values are not stale until it has shown a pose of its own."""
        self.has_pose = False

    def _verdict(self, result: Any, methods: tuple[str, ...]) -> str:
        if result.truth is None:
            return ""
        criteria = self.criteria
        lines = [
            f"vs true pose (✔ = within {criteria.max_angle_error_deg:g}° and "
            f"{criteria.max_position_error_mm:g}{NBSP}mm):"
        ]
        for name in methods:
            pose = result.pose_of(name)
            if pose is None:
                lines.append(f"– {name}: no pose")
                continue
            position_error, angle_errors = pose_errors(pose, result.truth)
            ok = bool(criteria.meets(position_error, max(angle_errors)))
            lines.append(
                ("✔" if ok else "✘")
                + f" {name}: Δpos {fixed(position_error, 2)} mm, Δangle ≤ {fixed(max(angle_errors), 2)}°"
            )
        return "\n".join(lines)

    def displayed(self, column: str) -> np.ndarray:
        """The six numbers shown in ``column`` (NaN where a dash is shown), for tests and tools."""
        cells = self._cells.get(column)
        if cells is None:
            return np.full(6, np.nan)
        return np.array([_number(cell.property("value")) for cell in cells])

    def displayed_std(self, column: str) -> np.ndarray:
        """The six "±" uncertainties shown in ``column`` (NaN where none is shown)."""
        cells = self._cells.get(column)
        if cells is None:
            return np.full(6, np.nan)
        return np.array([_number(str(cell.property("std") or "").lstrip("±")) for cell in cells])


def _number(text: object) -> float:
    try:
        return float(str(text))
    except ValueError:
        return math.nan


def pose_errors(measured: Pose, truth: Pose) -> tuple[float, list[float]]:
    """Position error (mm, Euclidean) and the absolute error of each angle (degrees)."""
    position_error = float(np.linalg.norm(measured.position_mm - truth.position_mm))
    angle_errors = [float(abs(d)) for d in angle_difference(measured.angles_deg, truth.angles_deg)]
    return position_error, angle_errors
