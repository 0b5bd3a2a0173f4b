"""The pose panel: x, y, z (mm) and alpha, beta, gamma (degrees) in large type, one column per
method (and the virtual bench's true pose beside them), with each solver's status below."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.geometry import Pose, angle_difference
from qrfield.sessions.criteria import AcceptanceCriteria

ROWS = (("x", "mm"), ("y", "mm"), ("z", "mm"), ("α", "°"), ("β", "°"), ("γ", "°"))
#: An ambiguity ratio at or above this counts as "the two mirror poses fit almost equally well".
AMBIGUITY_WARNING = 0.8
TRUTH = "true"


def format_value(value: float, row: int) -> str:
    if not math.isfinite(value):
        return "—"
    return f"{value:.1f}" if row < 3 else f"{value:.2f}"


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
        self._big = QtGui.QFont()
        self._big.setPointSize(22)
        self._big.setBold(True)
        self._big.setStyleHint(QtGui.QFont.StyleHint.Monospace)
        #: What the verdict against the true pose judges by (the session's; the seed's by default).
        self.criteria = AcceptanceCriteria()
        self.set_columns(("numerical",), truth=False)

    def set_criteria(self, criteria: AcceptanceCriteria) -> None:
        """Judge against ``criteria`` from the next result on."""
        self.criteria = criteria

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
        self._cells, self._headers, self._status = {}, {}, {}
        self._grid.addWidget(self.headline, 0, 0, 1, len(columns) + 2)
        for c, name in enumerate(columns):
            header = QtWidgets.QLabel(name)
            header.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight)
            header.setStyleSheet("font-size: 12pt; color: #888;" if name == TRUTH else "font-size: 12pt;")
            self._grid.addWidget(header, 1, c + 1)
            self._headers[name] = header
            cells = []
            for r, _ in enumerate(ROWS):
                cell = QtWidgets.QLabel("—")
                cell.setFont(self._big)
                cell.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
                cell.setMinimumWidth(100)
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
        colour = {"OK": "#2a2", "NOQR": "#c80", "NOCONV": "#c40"}.get(result.status, "#d22")
        self.headline.setStyleSheet(f"font-size: 15pt; font-weight: bold; color: {colour};")
        for name in methods:
            pose = result.poses.get(name)
            values = (
                np.concatenate([pose.position_mm, pose.angles_deg])
                if pose is not None
                else np.full(6, np.nan)
            )
            for r, cell in enumerate(self._cells[name]):
                cell.setText(format_value(float(values[r]), r))
            line, warn = solver_status_text(pose) if result.detection is not None else ("no code", False)
            self._status[name].setText(f"{name}: {line}")
            self._status[name].setStyleSheet("color: #d60;" if warn else "")
        if result.truth is not None:
            truth = np.concatenate([result.truth.position_mm, result.truth.angles_deg])
            for r, cell in enumerate(self._cells[TRUTH]):
                cell.setText(format_value(float(truth[r]), r))
        self.verdict.setText(self._verdict(result, methods))

    def mark_stale(self, why: str) -> None:
        """Say that the numbers shown are old (the source stopped)."""
        self.headline.setText(f"STALE   {why}")
        self.headline.setStyleSheet("font-size: 15pt; font-weight: bold; color: #888;")

    def _verdict(self, result: Any, methods: tuple[str, ...]) -> str:
        if result.truth is None:
            return ""
        parts = []
        for name in methods:
            pose = result.pose_of(name)
            if pose is None:
                parts.append(f"{name}: —")
                continue
            position_error, angle_errors = pose_errors(pose, result.truth)
            ok = bool(self.criteria.meets(position_error, max(angle_errors)))
            label = self.criteria.label()
            parts.append(
                f"{name}: Δpos {position_error:.2f} mm, Δangle ≤ {max(angle_errors):.2f}° "
                + (f"✔ meets {label}" if ok else f"✘ fails {label}")
            )
        return "vs true pose — " + "; ".join(parts)

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
