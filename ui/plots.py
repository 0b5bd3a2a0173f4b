"""Live plots of x, y, z (mm) and alpha, beta, gamma (degrees) over the last N seconds, one curve
per method plus the virtual bench's true pose (dashed grey)."""

from __future__ import annotations

from collections import deque

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore

TITLES = ("x [mm]", "y [mm]", "z [mm]", "α [°]", "β [°]", "γ [°]")
COLOURS = {"numerical": "#ff8c1a", "ippe": "#1a9cff", "true": "#aaaaaa"}
MAX_POINTS = 20_000


class PosePlots(pg.GraphicsLayoutWidget):
    """Six small plots sharing the time axis (seconds before now)."""

    def __init__(self, window_s: float = 20.0, parent=None) -> None:
        super().__init__(parent)
        self.window_s = float(window_s)
        self._history: dict[str, deque[tuple[float, np.ndarray]]] = {}
        self._curves: dict[str, list[pg.PlotDataItem]] = {}
        self.plots: list[pg.PlotItem] = []
        for i, title in enumerate(TITLES):
            plot = self.addPlot(row=i // 3, col=i % 3, title=title)
            plot.showGrid(x=True, y=True, alpha=0.3)
            plot.setXRange(-self.window_s, 0.0, padding=0)
            if i:
                plot.setXLink(self.plots[0])
            self.plots.append(plot)
        self.plots[0].addLegend(offset=(5, 5))

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
            self._curves[name] = [
                plot.plot(pen=pen, name=name if i == 0 else None, connect="finite")
                for i, plot in enumerate(self.plots)
            ]

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
