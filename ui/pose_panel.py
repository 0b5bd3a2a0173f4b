"""The pose panel: x, y, z (mm) and alpha, beta, gamma (degrees) in large type, one column per
method (and the virtual bench's true pose beside them), with each solver's status below.

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
#: The seed's acceptance criteria (docs/conventions.md), declared in qrfield.sessions.criteria.
MAX_ANGLE_ERROR_DEG = AcceptanceCriteria().max_angle_error_deg
MAX_POSITION_ERROR_MM = AcceptanceCriteria().max_position_error_mm
TRUTH = "true"
#: Point sizes (values, headline, column headers) and the value columns' width (px), by layout.
SIZES = {False: (22, 15, 12, 100), True: (13, 11, 9, 56)}
NBSP = "\u00a0"


def format_value(value: float, row: int) -> str:
    """A position (rows 0-2) in mm with 1 decimal, an angle in degrees with 2; "—" when unknown."""
    return fixed(value, 1 if row < 3 else 2)


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
    ambiguity = getattr(result, "ambiguity", None)
    if ambiguity is not None and math.isfinite(ambiguity) and ambiguity >= AMBIGUITY_WARNING:
        parts.append(f"⚠ mirror pose fits almost as well (ambiguity {ambiguity:.2f}): flip risk")
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
        self._apply_sizes()
        self.set_columns(self._methods, truth=False)

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
        big, headline, _header, _width = SIZES[self.compact]
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
        _big, _headline, header_pt, width = SIZES[self.compact]
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
            for r, cell in enumerate(self._cells[name]):
                cell.setText(format_value(float(values[r]), r))
            line, warn = solver_status_text(pose) if result.detection is not None else ("no code", False)
            self._status[name].setText(f"{name}: {line}")
            self._status[name].setStyleSheet("color: #d60;" if warn else "")
            self._status[name].setVisible(warn or not self.compact)
        if result.truth is not None:
            truth = np.concatenate([result.truth.position_mm, result.truth.angles_deg])
            for r, cell in enumerate(self._cells[TRUTH]):
                cell.setText(format_value(float(truth[r]), r))
        self.verdict.setText(self._verdict(result, methods))
        self.verdict.setVisible(bool(self.verdict.text()))

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
                cell.setText("—")
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
        lines = [f"vs true pose (✔ = within {MAX_ANGLE_ERROR_DEG:g}° and {MAX_POSITION_ERROR_MM:g}{NBSP}mm):"]
        for name in methods:
            pose = result.pose_of(name)
            if pose is None:
                lines.append(f"– {name}: no pose")
                continue
            position_error, angle_errors = pose_errors(pose, result.truth)
            ok = position_error < MAX_POSITION_ERROR_MM and max(angle_errors) <= MAX_ANGLE_ERROR_DEG
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
        out = []
        for cell in cells:
            try:
                out.append(float(cell.text()))
            except ValueError:
                out.append(math.nan)
        return np.array(out)


def pose_errors(measured: Pose, truth: Pose) -> tuple[float, list[float]]:
    """Position error (mm, Euclidean) and the absolute error of each angle (degrees)."""
    position_error = float(np.linalg.norm(measured.position_mm - truth.position_mm))
    angle_errors = [float(abs(d)) for d in angle_difference(measured.angles_deg, truth.angles_deg)]
    return position_error, angle_errors
