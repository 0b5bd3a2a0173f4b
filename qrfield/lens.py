"""The lens: OpenCV's five-coefficient distortion model, forwards and backwards, in one place.

docs/conventions.md (pixels: OpenCV's, the top-left pixel's centre is (0, 0)); docs/cameras.md.
*Normalised* coordinates (x, y) are those of a point on the image plane at unit depth (the line of
sight is (x, y, 1) in the camera frame: +X right, +Y down, +Z forward). *Ideal pixels* are where a
point would appear through a distortion-free pinhole with the same K. The distortion coefficients
(k1, k2, p1, p2, k3) act on normalised coordinates (Brown-Conrady, as ``cv2.projectPoints``):

    r2 = x^2 + y^2,  radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
    xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2),   yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y

:func:`distort_normalised` and :func:`distortion_jacobian_terms` take Python floats or numpy arrays
alike (the per-frame single path passes floats; batches pass arrays). :func:`undistort_points` is
the one call into OpenCV's iterative undistortion (its name differs between OpenCV 4 and 5), with
one criterion, :data:`UNDISTORT_CRITERIA`.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

#: The iteration of OpenCV's undistortion, (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
#: count, eps): exact to far below a micro-pixel for usual lenses (OpenCV's default of 5 iterations
#: leaves errors of 1e-3 px and more near the image corners). cv2 is imported lazily (a fast CLI).
UNDISTORT_CRITERIA = (1 | 2, 100, 1e-15)
_NO_DISTORTION = [0.0, 0.0, 0.0, 0.0, 0.0]


class HasLens(Protocol):
    """What the lens functions need of a camera (qrfield.camera.CameraModel has it)."""

    K: np.ndarray  # (3, 3) intrinsics, px
    dist: np.ndarray  # (5,) k1, k2, p1, p2, k3


def has_distortion(camera: HasLens) -> bool:
    """True when any of the camera's five coefficients is non-zero (no numpy call: the per-frame
    single path asks on every solve)."""
    return camera.dist.tolist() != _NO_DISTORTION


def distort_normalised(dist: Any, x: Any, y: Any) -> tuple[Any, Any]:
    """Distorted normalised coordinates (xd, yd) of undistorted ones (x, y).

    ``dist``: the five coefficients (k1, k2, p1, p2, k3), a sequence or (5,) array; x, y: floats or
    arrays of one shape. The module doc gives the model."""
    k1, k2, p1, p2, k3 = dist
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def distortion_jacobian_terms(dist: Any, x: Any, y: Any) -> tuple[Any, Any, Any]:
    """The entries (d00, d01 = d10, d11) of d(xd, yd) / d(x, y) at undistorted normalised (x, y):
    floats or arrays alike (the Jacobian of :func:`distort_normalised`, written out)."""
    k1, k2, p1, p2, k3 = dist
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    g = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))  # 2 d radial / d r2
    cross = x * y * g + 2.0 * p1 * x + 2.0 * p2 * y
    return (
        radial + x * x * g + 2.0 * p1 * y + 6.0 * p2 * x,
        cross,
        radial + y * y * g + 6.0 * p1 * y + 2.0 * p2 * x,
    )


def undistort_points(
    points_px: np.ndarray, K: np.ndarray, dist: np.ndarray, pixels: bool = False
) -> np.ndarray:
    """Undistorted normalised coordinates of image pixels, or ideal pixels when ``pixels``.

    ``points_px``: (..., 2) pixels (any leading shape, e.g. (k, 2) or OpenCV's (M, 1, 2)); ``K``
    (3, 3) and ``dist`` (5,): the camera's intrinsics and coefficients (``camera.K``,
    ``camera.dist``). The result has the shape of ``points_px``, float64: OpenCV's iterative
    undistortion to :data:`UNDISTORT_CRITERIA`."""
    import cv2

    pts = np.ascontiguousarray(points_px, dtype=np.float64)
    if pts.shape[-1:] != (2,):
        raise ValueError(f"points must have shape (..., 2) in pixels, got {pts.shape}")
    shape = pts.shape
    pts = pts.reshape(-1, 1, 2)
    target = K if pixels else None
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x
        out = cv2.undistortPointsIter(pts, K, dist, None, target, UNDISTORT_CRITERIA)
    else:  # OpenCV 5 folded the iterative variant into undistortPoints(..., criteria)
        out = cv2.undistortPoints(pts, K, dist, R=None, P=target, criteria=UNDISTORT_CRITERIA)
    return out.reshape(shape)
