"""Lines of sight of corner pixels: undistortion and normalised image coordinates.

Normalised coordinates (x, y) of a pixel are those of the undistorted point on the image plane at
unit depth: the line of sight is (x, y, 1) in the camera frame (OpenCV: +X right, +Y down, +Z
forward). Without distortion x = (u - cx) / fx, y = (v - cy) / fy exactly; with distortion OpenCV
iterates to qrfield.lens.UNDISTORT_CRITERIA.
"""

from __future__ import annotations

import numpy as np

from qrfield.camera import CameraModel
from qrfield.lens import has_distortion, undistort_points


def undistort(points: np.ndarray, camera: CameraModel, pixels: bool = False) -> np.ndarray:
    """Undistorted (M, 1, 2) normalised coordinates of pixels (M, 1, 2), or ideal pixels if ``pixels``
    (:func:`qrfield.lens.undistort_points`)."""
    return undistort_points(points, camera.K, camera.dist, pixels)


def normalised_single(
    corners: np.ndarray, flat: list[float], camera: CameraModel
) -> tuple[list[float], list[float]]:
    """Normalised undistorted coordinates (x_i, y_i) of the four corners as Python floats."""
    if has_distortion(camera):
        und = undistort(corners.reshape(4, 1, 2), camera).reshape(8).tolist()
        return und[0::2], und[1::2]
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    return [(flat[2 * i] - cx) / fx for i in range(4)], [(flat[2 * i + 1] - cy) / fy for i in range(4)]


def normalised_batch(corners: np.ndarray, camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """Normalised undistorted coordinates, (N, 4) each; the same per-point numbers as the single path."""
    if camera.has_distortion:
        n = corners.shape[0]
        und = undistort(corners.reshape(-1, 1, 2), camera).reshape(n, 4, 2)
        return und[..., 0].copy(), und[..., 1].copy()
    return (corners[..., 0] - camera.cx) / camera.fx, (corners[..., 1] - camera.cy) / camera.fy
