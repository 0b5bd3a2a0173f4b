"""Bench app entry point.

Foundation stage: a window that shows the virtual bench's view with its true vertices, so that
``./run.sh`` opens something real; the full bench app (live detection, solvers, plots, sources)
replaces it.
"""

from __future__ import annotations

import argparse
import sys


def main(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np
    from PySide6 import QtGui, QtWidgets

    from qrfield.camera import resolve_camera
    from qrfield.geometry import Pose
    from qrfield.render import render_view

    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    camera = resolve_camera(args.camera or "picam-v2@640x480")
    side = args.side_mm or 50.0
    view = render_view(camera, side, Pose([10.0, -5.0, 300.0], [15.0, -20.0, 10.0]), noise_sigma=2.0, seed=0)
    bgr = cv2.cvtColor(view.image, cv2.COLOR_GRAY2BGR)
    for i, (u, v) in enumerate(view.corners_px):
        cv2.circle(bgr, (round(u), round(v)), 4, (0, 0, 255), 1, cv2.LINE_AA)
        cv2.putText(
            bgr, f"V{i + 1}", (round(u) + 6, round(v) - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1
        )
    rgb = np.ascontiguousarray(bgr[..., ::-1])
    image = QtGui.QImage(
        rgb.data, rgb.shape[1], rgb.shape[0], rgb.strides[0], QtGui.QImage.Format.Format_RGB888
    )
    window = QtWidgets.QLabel()
    window.setWindowTitle("qrfield: virtual bench (foundation preview)")
    window.setPixmap(QtGui.QPixmap.fromImage(image.copy()))
    window.show()
    return app.exec()
