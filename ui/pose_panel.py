"""The pose panel: x, y, z (mm) and alpha, beta, gamma (degrees) in large type, one column per
method (and the virtual bench's true pose beside them), each value with its standard uncertainty
(+- in small type, when the corners' covariance is known: docs/uncertainty.md), and each solver's
status below (with the flip warning of the core's mirror test, ``PoseResult.ambiguous``, after the
stream's history) and what the live stream did to it: "flip resolved by history" when the frame
alone was ambiguous and the recent resolved pose decided it, "filtered" when the value is the
stream filter's (``FrameResult.stream``; docs/conventions.md, "The live stream").

The headline shows the engine's state, in the serial link's words (docs/conventions.md): the
pipeline's status (NOQR, NOCONV, ERROR), OK only for an unambiguous pose from a live camera, AMBIG for an
ambiguous one (qrfield.status.reported_status), and SIM for one from
anything else (the virtual bench, a recording, a stand-in: ``simulated``), with a badge beside the
values that cannot be missed ("SIMULATED — virtual bench, not a camera"). While no frames come
(:meth:`PosePanel.show_source_down`) it says NOSRC with dashes, or, when a real pose was shown
before, STALE over the last values (their +- kept). On a small screen
(:meth:`PosePanel.set_compact`) the type is smaller and a solver's status line is shown only when
it warns."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.methods import NUMERICAL
from qrfield.sessions.criteria import AcceptanceCriteria
from qrfield.sources.kinds import FOLDER, PICAMERA2_SIM, VIDEO, VIRTUAL
from qrfield.status import Reported, WireStatus
from ui.text import fixed

ROWS = (("x", "mm"), ("y", "mm"), ("z", "mm"), ("α", "°"), ("β", "°"), ("γ", "°"))
TRUTH = "true"
#: Point sizes (values, headline, column headers, the "+- std" beside a value) and the value
#: columns' width (px), by layout (compact: a small screen).
SIZES = {False: (22, 15, 12, 11, 100), True: (13, 11, 9, 7, 56)}
#: Grid rows: the column headers, then the six values (the headline and the simulated-source
#: badge are above the grid, the status lines and the verdict under it).
FIRST_VALUE_ROW = 1
NBSP = "\u00a0"
#: The states the headline shows besides the pipeline's reported statuses: the link's own.
NOSRC, STALE = WireStatus.NOSRC, WireStatus.STALE
#: Headline colours by state (SIM is not green: a made-up pose never looks like a measured one;
#: AMBIG is not green either: a pose whose flip is unresolved is not to be acted on).
SIM_COLOUR = "#7b3fc4"
STATE_COLOURS = {
    Reported.OK: "#2a2",
    Reported.AMBIG: "#c60",
    Reported.SIM: SIM_COLOUR,
    Reported.NOQR: "#c80",
    Reported.NOCONV: "#c40",
    NOSRC: "#888",
    STALE: "#888",
}
#: The simulated-source badge: white on the SIM colour.
BADGE_STYLE = f"color: white; background: {SIM_COLOUR}; font-weight: bold; padding: 1px 6px;"


#: What the simulated-source badge calls a source, by the start of its name (FrameSource.name).
SIMULATED_SOURCE_NAMES = {
    VIRTUAL: "virtual bench",
    PICAMERA2_SIM: "picamera2 stand-in",
    VIDEO: "video file",
    FOLDER: "image folder",
}


def simulated_source_name(source_name: str) -> str:
    """The badge's words for an opened source's ``name`` ("virtual" -> "virtual bench")."""
    return SIMULATED_SOURCE_NAMES.get(source_name.partition(":")[0], "this source")


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


def stream_text(mark: Any) -> str:
    """What the live stream did to a pose (a qrfield.stream.StreamMark, or None): "" when nothing."""
    if mark is None:
        return ""
    parts = []
    if mark.resolved_by == "history":
        parts.append("flip resolved by history" + (" (the mirror branch)" if mark.flipped else ""))
    if mark.filtered:
        parts.append("filtered")
    return ", ".join(parts)


def solver_status_text(result: Any, mark: Any = None) -> tuple[str, bool]:
    """One line about a PoseResult (converged, iterations, reprojection, ambiguity, what the live
    stream did: ``mark``, its qrfield.stream.StreamMark) and whether it warns."""
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
    if getattr(result, "misfit", False):  # PoseResult.misfit: chi2 above the core's FIT_CHI2
        from qrfield.solvers.uncertainty import FIT_CHI2

        parts.append(
            f"⚠ the corners do not fit the pose (chi² {result.chi2:.3g} > {FIT_CHI2}): "
            "check the camera model and the QR side"
        )
        warn = True
    streamed = stream_text(mark)
    if streamed:
        parts.append(streamed)
    if not result.converged and result.reason:
        parts.append(result.reason)
    return ", ".join(parts), warn


class PosePanel(QtWidgets.QWidget):
    """Large-type pose values per method, the true pose (virtual bench) and the error against it."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        # The labels across the panel (headline, badge, status lines, verdict) are in a box layout
        # around the values' grid, not grid cells spanning its columns: a grid gives a spanning
        # word-wrapped label one line's height, and at 800x480 under the red banner "STALE: no
        # frames; the values are the last measured" lost its second line behind the values.
        self._outer = QtWidgets.QVBoxLayout(self)
        self._grid = QtWidgets.QGridLayout()
        self._status_box = QtWidgets.QVBoxLayout()
        self._status_box.setContentsMargins(0, 0, 0, 0)
        self._status_box.setSpacing(0)
        self._columns: list[str] = []
        self._cells: dict[str, list[QtWidgets.QLabel]] = {}
        self._headers: dict[str, QtWidgets.QLabel] = {}
        self._status: dict[str, QtWidgets.QLabel] = {}
        #: What the badge calls a simulated source (:meth:`set_source_name`).
        self.source_name = "this source"
        #: The state the headline shows: a status of the pipeline or the link, NOSRC or STALE.
        self.state = NOSRC
        self.compact = False
        self.has_pose = False  # a real pose has been shown (only then can values be stale)
        self._methods: tuple[str, ...] = (NUMERICAL,)
        #: What the verdict against the true pose judges by (the session's; the seed's by default).
        self.criteria = AcceptanceCriteria()
        self._build_labels()
        self._apply_sizes()
        self.set_columns(self._methods, truth=False)

    def _build_labels(self) -> None:
        """The labels that stay while the columns change: headline, badge, verdict; the values' font."""
        self.headline = QtWidgets.QLabel("waiting for frames…")
        self.headline.setObjectName("headline")
        self.headline.setWordWrap(True)
        self.badge = QtWidgets.QLabel("")
        self.badge.setObjectName("sim_badge")
        self.badge.setWordWrap(True)
        self.badge.hide()
        self.verdict = QtWidgets.QLabel("")
        self.verdict.setObjectName("verdict")
        self.verdict.setWordWrap(True)
        self._outer.addWidget(self.headline)
        self._outer.addWidget(self.badge)
        self._outer.addLayout(self._grid)
        self._outer.addLayout(self._status_box)
        self._outer.addWidget(self.verdict)
        self._big = QtGui.QFont()
        self._big.setBold(True)
        self._big.setStyleHint(QtGui.QFont.StyleHint.Monospace)

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
        self._outer.setSpacing(0 if self.compact else 6)
        self._style_headline(self.headline.property("colour") or "")
        self.verdict.setStyleSheet("font-size: 8pt;" if self.compact else "")
        self.badge.setStyleSheet(BADGE_STYLE + (" font-size: 8pt;" if self.compact else ""))

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
        for layout in (self._grid, self._status_box):
            while layout.count():
                item = layout.takeAt(0)
                if item.widget() is not None:
                    item.widget().deleteLater()
        self._columns = columns
        self._methods = tuple(methods)
        self._cells, self._headers, self._status = {}, {}, {}
        span = len(columns) + 2  # the row names, the columns, the units
        for c, name in enumerate(columns):
            self._add_column(c + 1, name)
        for r, (symbol, unit) in enumerate(ROWS):
            name_label = QtWidgets.QLabel(symbol)
            name_label.setFont(self._big)
            self._grid.addWidget(name_label, r + FIRST_VALUE_ROW, 0)
            self._grid.addWidget(QtWidgets.QLabel(unit), r + FIRST_VALUE_ROW, span - 1)
        for name in methods:  # each solver's status line across the panel (the verdict under them)
            status = QtWidgets.QLabel("")
            status.setWordWrap(True)
            status.setObjectName(f"status_{name}")
            self._status_box.addWidget(status)
            self._status[name] = status

    def _add_column(self, column: int, name: str) -> None:
        """The header and the six value cells of method (or true pose) ``name`` in grid ``column``."""
        _big, _headline, header_pt, _std, width = SIZES[self.compact]
        header = QtWidgets.QLabel(name)
        header.setAlignment(QtCore.Qt.AlignmentFlag.AlignRight)
        header.setStyleSheet(f"font-size: {header_pt}pt;" + (" color: #888;" if name == TRUTH else ""))
        self._grid.addWidget(header, FIRST_VALUE_ROW - 1, column)
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
            self._grid.addWidget(cell, r + FIRST_VALUE_ROW, column)
            cells.append(cell)
        self._cells[name] = cells

    def set_source_name(self, name: str) -> None:
        """What the badge calls the source when its frames are simulated ("virtual bench")."""
        self.source_name = name

    def show_result(self, result: Any, methods: tuple[str, ...], simulated: bool = False) -> None:
        """Show a qrfield.pipeline.FrameResult; ``simulated``: its frame is not from a live camera
        (``ui.worker.Processed.simulated``), so a pose is SIM, never OK, and the badge shows."""
        self.set_columns(methods, truth=result.truth is not None)
        self.state = result.reported_status(simulated)
        text = str(self.state)
        if result.detection is not None and result.detection.text:
            text += f"   “{result.detection.text}”"
        if result.reason:
            text += f"   {result.reason}"
        streamed = stream_text(getattr(result, "stream", {}).get(methods[0]) if methods else None)
        if streamed:
            text += f"   ({streamed})"
        self.headline.setText(text)
        self._style_headline(STATE_COLOURS.get(self.state, "#d22"))
        self.badge.setText(f"SIMULATED — {self.source_name}, not a camera")
        self.badge.setVisible(simulated)
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
            mark = getattr(result, "stream", {}).get(name)
            line, warn = (
                solver_status_text(pose, mark) if result.detection is not None else ("no code", False)
            )
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

    def show_source_down(self, why: str = "") -> None:
        """No frames come (``why``: "" when a banner says it): STALE over the last real pose shown
        (the values and their +- stay, the badge too if they were simulated), or, when none was
        ever shown, NOSRC and dashes (nothing measured can be stale)."""
        if not self.has_pose:
            self.show_no_source(why)
            return
        self.state = STALE
        self.headline.setText(
            "STALE: no frames" + (f" ({why})" if why else "") + "; the values are the last measured"
        )
        self._style_headline(STATE_COLOURS[STALE])

    def show_no_source(self, why: str = "") -> None:
        """No frames and no values: NOSRC (the serial link's word), why, and dashes everywhere."""
        self.state = NOSRC
        self.headline.setText("NOSRC: no frames" + (f" ({why})" if why else " from the source"))
        self._style_headline(STATE_COLOURS[NOSRC])
        self.badge.hide()
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
            pose = result.converged_pose(name)
            if pose is None:
                lines.append(f"– {name}: no pose")
                continue
            ok, position_error, angle_error = criteria.judge(
                pose.position_mm, pose.angles_deg, result.truth.position_mm, result.truth.angles_deg
            )
            lines.append(
                ("✔" if ok else "✘") + f" {name}: Δpos {fixed(float(position_error), 2)} mm, "
                f"Δangle ≤ {fixed(float(angle_error), 2)}°"
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
