"""Live plots of x, y, z (mm) and alpha, beta, gamma (degrees) over the last N seconds, one curve
per method plus the virtual bench's true pose (dashed grey).

The legend is a line of its own above the plots (a legend inside a plot hid the data), the plots
reflow to two columns on a narrow pane (three columns of 150 px stacked their tick labels), and
tick labels never read "-0.00"."""

from __future__ import annotations

from collections import deque

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui

from qrfield.methods import IPPE, NUMERICAL

TITLES = ("x [mm]", "y [mm]", "z [mm]", "α [°]", "β [°]", "γ [°]")
COLOURS = {NUMERICAL: "#ff8c1a", IPPE: "#1a9cff", "true": "#aaaaaa"}
MAX_POINTS = 20_000
#: Below this width (px) the six plots stand in two columns, not three.
NARROW_PX = 640
TICK_FONT_PT = 8


class ZeroSafeAxis(pg.AxisItem):
    """Tick labels as pyqtgraph writes them, but a tick at zero reads "0": never "-0.00", nor
    "-1e-17" (a tick computed as a multiple of the spacing lands a rounding error off zero, and
    pyqtgraph writes values below 0.001 with %g)."""

    def tickStrings(self, values: list[float], scale: float, spacing: float) -> list[str]:
        values = [0.0 if abs(v) < 1e-9 * abs(spacing) else v for v in values]
        strings = super().tickStrings(values, scale, spacing)
        return [s[1:] if s.startswith("-") and _is_zero(s[1:]) else s for s in strings]


def _is_zero(text: str) -> bool:
    try:
        return float(text) == 0.0
    except ValueError:
        return False


class PosePlots(pg.GraphicsLayoutWidget):
    """Six small plots sharing the time axis (seconds before now), with a legend line above them."""

    def __init__(self, window_s: float = 20.0, parent=None) -> None:
        super().__init__(parent)
        self.window_s = float(window_s)
        self._history: dict[str, deque[tuple[float, np.ndarray]]] = {}
        self._curves: dict[str, list[pg.PlotDataItem]] = {}
        self.plots: list[pg.PlotItem] = []
        self.columns = 0
        self.legend = pg.LabelItem("", justify="left", size="9pt")
        font = QtGui.QFont()
        font.setPointSize(TICK_FONT_PT)
        for i, title in enumerate(TITLES):
            axes = {"left": ZeroSafeAxis("left"), "bottom": ZeroSafeAxis("bottom")}
            plot = pg.PlotItem(title=title, axisItems=axes)
            plot.titleLabel.setText(title, size="9pt")
            for name in ("left", "bottom"):
                plot.getAxis(name).setStyle(tickFont=font, tickTextOffset=2)
            plot.getAxis("left").setWidth(44)
            plot.showGrid(x=True, y=True, alpha=0.3)
            plot.setXRange(-self.window_s, 0.0, padding=0)
            if i:
                plot.setXLink(self.plots[0])
            self.plots.append(plot)
        self.set_columns(3)

    def set_columns(self, columns: int) -> None:
        """Lay the six plots out in ``columns`` columns (2 or 3), the legend line above them."""
        if columns == self.columns:
            return
        self.columns = columns
        self.ci.clear()
        self.addItem(self.legend, row=0, col=0, colspan=columns)
        for i, plot in enumerate(self.plots):
            self.addItem(plot, row=1 + i // columns, col=i % columns)

    def resizeEvent(self, event: QtGui.QResizeEvent | None) -> None:
        super().resizeEvent(event)
        if getattr(self, "plots", None):  # pyqtgraph calls this from its own __init__, before ours
            self.set_columns(2 if self.width() < NARROW_PX else 3)

    def set_window(self, window_s: float) -> None:
        self.window_s = float(window_s)
        self.plots[0].setXRange(-self.window_s, 0.0, padding=0)

    def add(self, name: str, t_s: float, values: np.ndarray | None) -> None:
        """Record the six values of ``name`` at time ``t_s`` (NaN values leave a gap)."""
        history = self._history.setdefault(name, deque(maxlen=MAX_POINTS))
        history.append((t_s, np.full(6, np.nan) if values is None else np.asarray(values, float)))
        if name not in self._curves:
            pen = pg.mkPen(COLOURS.get(name, "#ffffff"), width=2)
            if name == "true":
                pen.setStyle(QtCore.Qt.PenStyle.DashLine)
            self._curves[name] = [plot.plot(pen=pen, connect="finite") for plot in self.plots]
            self._update_legend()

    def _update_legend(self) -> None:
        parts = []
        for name in self._curves:
            dash = "- - -" if name == "true" else "———"
            parts.append(f"<span style='color:{COLOURS.get(name, '#ffffff')}'>{dash}</span> {name}")
        self.legend.setText("&nbsp;&nbsp;&nbsp;".join(parts), size="9pt")

    def legend_names(self) -> list[str]:
        """The curves named in the legend line, in order."""
        return list(self._curves)

    def redraw(self, now_s: float) -> None:
        """Redraw every curve over [now - window, now]."""
        for name, history in self._history.items():
            while history and history[0][0] < now_s - self.window_s:
                history.popleft()
            if not history:
                for curve in self._curves[name]:
                    curve.setData([], [])
                continue
            t = np.array([h[0] for h in history]) - now_s
            values = np.array([h[1] for h in history])
            for i, curve in enumerate(self._curves[name]):
                curve.setData(t, values[:, i])

    def clear_history(self) -> None:
        for history in self._history.values():
            history.clear()
