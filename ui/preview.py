"""The camera preview: the image, the detected vertices V1..V4, the code's outline, the pose's axes.

Drawn with pyqtgraph in image pixel coordinates (OpenCV convention: the centre of the top-left
pixel is (0, 0); the y axis points down). The pose axes are the marker frame's X (red), Y (green)
and Z (blue, into the card), one QR side long, projected through the camera model with
:func:`qrfield.geometry.project_points`.

:class:`PreviewPane` holds the view and one empty state (a plain message: no source yet, or the
source failed before any frame came), so the operator never sees a black square with stray labels.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.camera import CameraModel
from qrfield.geometry import VERTEX_NAMES, project_points, transform_points

VERTEX_COLOURS = ("#ff3030", "#30c0ff", "#ffd000", "#40ff60")
AXIS_COLOURS = ("#ff2020", "#20e020", "#3070ff")
SECOND_METHOD_ALPHA = 130


def axes_pixels(
    rotation: np.ndarray, position_mm: np.ndarray, length_mm: float, camera: CameraModel
) -> np.ndarray | None:
    """(4, 2) pixels of the marker origin and the tips of its X, Y, Z axes; None if not drawable."""
    points = np.vstack([np.zeros(3), np.eye(3) * length_mm])
    camera_points = transform_points(rotation, position_mm, points)
    if not np.all(np.isfinite(camera_points)) or np.any(camera_points[:, 2] <= 1.0):
        return None
    return project_points(camera_points, camera)


class PreviewView(pg.GraphicsLayoutWidget):
    """Shows the latest frame with its detection and pose overlays, plus an fps/latency line."""

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setBackground("#202020")
        self.view = self.addViewBox(lockAspect=True, invertY=True, enableMenu=False)
        self.image_item = pg.ImageItem(axisOrder="row-major")
        # pyqtgraph spans pixel (i, j) over [j, j+1] x [i, i+1]; the overlays use OpenCV's pixel
        # convention (pixel centres at integers): shift the image so that both agree.
        self.image_item.setPos(-0.5, -0.5)
        self.view.addItem(self.image_item)
        self._build_detection_overlay()
        self._build_axes()
        self.info = pg.TextItem("", color="#ffffff", anchor=(0, 0), fill=pg.mkBrush(0, 0, 0, 150))
        self.info.setFont(QtGui.QFont("Monospace", 9))
        self.info.setVisible(False)  # until there is something to say
        # Its size is the screen's, not the picture's: it must never move the view's range (with the
        # range following the items, its wrap width and the range fed each other in a loop).
        self.view.addItem(self.info, ignoreBounds=True)
        self._size: tuple[int, int] | None = None
        self.view.sigTransformChanged.connect(self._transform_changed)  # the picture moved or scaled

    def _build_detection_overlay(self) -> None:
        """The code's outline, its four vertices and their V1..V4 labels (hidden until a code is found)."""
        self.outline = pg.PlotDataItem(pen=pg.mkPen("#00ff66", width=2))
        self.view.addItem(self.outline)
        self.vertices = pg.ScatterPlotItem(size=10, pen=pg.mkPen("k"))
        self.view.addItem(self.vertices)
        self.labels = []
        for i, colour in enumerate(VERTEX_COLOURS):
            label = pg.TextItem(VERTEX_NAMES[i], color=colour, anchor=(0.5, 0.5))
            label.setFont(QtGui.QFont("Sans", 11, QtGui.QFont.Weight.Bold))
            label.setVisible(False)  # until a code is found
            self.view.addItem(label)
            self.labels.append(label)

    def _build_axes(self) -> None:
        """Three axis lines per method: the first method's solid, the second's (when both run) dashed."""
        self.axes: list[list[pg.PlotDataItem]] = []
        for k in range(2):
            lines = []
            for colour in AXIS_COLOURS:
                pen = pg.mkPen(colour, width=3 if k == 0 else 2)
                if k:
                    pen.setStyle(QtCore.Qt.PenStyle.DashLine)
                item = pg.PlotDataItem(pen=pen)
                self.view.addItem(item)
                lines.append(item)
            self.axes.append(lines)

    def resizeEvent(self, event: QtGui.QResizeEvent | None) -> None:
        super().resizeEvent(event)
        if getattr(self, "info", None) is not None:  # pyqtgraph calls this from its __init__, before ours
            self._fit_info()

    @QtCore.Slot(object)
    def _transform_changed(self, _view: object = None) -> None:
        self._fit_info()

    def _fit_info(self) -> None:
        """The info line wraps at the picture's right edge (or the widget's, if nearer): it starts at
        the picture's left edge, which is inset when the widget is wider than the picture."""
        room = float(self.width())
        if self._size is not None:
            corners = QtCore.QRectF(-0.5, -0.5, *self._size)
            shown = self.mapFromScene(self.view.mapViewToScene(corners)).boundingRect()
            room = float(min(shown.right(), self.width()) - max(shown.left(), 0))
        width = max(80.0, room - 8.0)
        # Only a change of a pixel or more is set: setting the width moves the item, which may
        # change the view's transform and call this again (a livelock in the event loop once).
        if abs(self.info.textItem.textWidth() - width) >= 1.0:
            self.info.textItem.setTextWidth(width)

    def show_frame(self, image: np.ndarray) -> None:
        """Display a grey (H, W) or BGR (H, W, 3) uint8 image."""
        if image.ndim == 3:
            image = image[..., 2::-1]  # BGR -> RGB for display
        self.image_item.setImage(image, autoLevels=False, levels=(0, 255))
        size = (image.shape[1], image.shape[0])
        if size != self._size:
            self._size = size
            self.view.setRange(QtCore.QRectF(-0.5, -0.5, size[0], size[1]), padding=0.0)
        self.info.setPos(-0.5, -0.5)

    def show_corners(self, corners_px: np.ndarray | None) -> None:
        """Outline and numbered vertices V1..V4, or hide them (None)."""
        if corners_px is None:
            self.outline.setData([], [])
            self.vertices.setData([], [])
            for label in self.labels:
                label.setVisible(False)
            return
        corners = np.asarray(corners_px, float).reshape(4, 2)
        closed = np.vstack([corners, corners[:1]])
        self.outline.setData(closed[:, 0], closed[:, 1])
        self.vertices.setData(corners[:, 0], corners[:, 1], brush=[pg.mkBrush(c) for c in VERTEX_COLOURS])
        centre = corners.mean(axis=0)
        for label, corner in zip(self.labels, corners, strict=True):
            away = corner - centre
            away = away / (np.linalg.norm(away) or 1.0) * 16.0  # labels just outside the code
            x, y = corner + away
            label.setPos(float(x), float(y))  # Python floats: PySide6 mishandles numpy scalars here
            label.setVisible(True)

    def show_axes(
        self, which: int, rotation: np.ndarray | None, position_mm, length_mm: float, camera
    ) -> None:
        """Axes of pose ``which`` (0 = first method, 1 = second), or hide them (rotation None)."""
        tips = None if rotation is None else axes_pixels(rotation, position_mm, length_mm, camera)
        for k, item in enumerate(self.axes[which]):
            if tips is None:
                item.setData([], [])
            else:
                item.setData([tips[0, 0], tips[k + 1, 0]], [tips[0, 1], tips[k + 1, 1]])

    def show_info(self, text: str) -> None:
        self.info.setText(text)
        self.info.setVisible(bool(text))


class PreviewPane(QtWidgets.QStackedWidget):
    """The preview, or one empty state in its place: a message on the preview's dark background."""

    def __init__(self, view: PreviewView, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.view = view
        self.empty = QtWidgets.QLabel("")
        self.empty.setObjectName("preview_empty")
        self.empty.setWordWrap(True)
        self.empty.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self.empty.setMargin(16)
        self.empty.setStyleSheet("background: #202020; color: #d0d0d0; font-size: 12pt;")
        self.empty.setMinimumSize(120, 90)
        self.addWidget(self.empty)
        self.addWidget(view)

    @property
    def is_empty(self) -> bool:
        return self.currentWidget() is self.empty

    def show_empty(self, text: str) -> None:
        """Show ``text`` instead of the picture (no frame to show)."""
        self.empty.setText(text)
        self.setCurrentWidget(self.empty)

    def show_live(self) -> None:
        """Show the picture (a frame has been drawn)."""
        if self.currentWidget() is not self.view:
            self.setCurrentWidget(self.view)
