"""Between image pixels and ideal pixels: the camera's lens distortion for the symbol fit.

*Ideal pixels* are where a point would appear through a distortion-free pinhole camera with the
same K (OpenCV's ``undistortPoints(..., P=K)``): a plane maps to them by a homography, so the
symbol fit (:mod:`qrfield.detect.symbol_fit`) works in ideal pixels and goes through the lens only
to compare with the image. Pixels follow OpenCV (top-left pixel centre = (0, 0)); the distortion
model is OpenCV's five coefficients k1, k2, p1, p2, k3 (qrfield.camera), and its maths is
qrfield.lens' (the Brown-Conrady polynomial and its derivative; the undistortion is OpenCV's
iteration on the same model): this module only puts it in pixels, keeps a per-camera table of
the ideal pixel of every pixel centre (one lookup per sample instead of an iterative
undistortion) and maps module coordinates through it.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from qrfield.camera import CameraModel
from qrfield.homography import square_to_quad
from qrfield.lens import distort_normalised, distortion_jacobian_terms

#: Images up to this many pixels keep a whole-frame table of ideal pixels per camera (8 bytes per
#: pixel and coordinate: 5 MB at 640x480); larger ones undistort the pixels each fit needs.
MAX_TABLE_PIXELS = 2_500_000
#: OpenCV's termination of the iterative undistortion (count | eps).
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)


@functools.lru_cache(maxsize=4)
def _ideal_table(camera: CameraModel) -> np.ndarray:
    """(H, W, 2) float64 ideal pixels of every pixel centre of ``camera``'s image (a lookup table of
    :func:`undistort_pixels`, made once per camera)."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    out = undistort_pixels(camera, np.column_stack([u.ravel(), v.ravel()]))
    out = out.reshape(camera.height, camera.width, 2)
    out.setflags(write=False)
    return out


def undistort_pixels(camera: CameraModel, px: np.ndarray) -> np.ndarray:
    """Ideal pixels (k, 2) of image pixels ``px`` (k, 2): OpenCV's iterative undistortion (the
    inverse of qrfield.lens.distort_normalised) to 1e-10 px.

    Not qrfield.lens.undistort_points: its criteria (100 iterations, 1e-15) make the whole-frame
    table 3x as slow (0.53 s against 0.16 s at 640x480, measured; a stream's first frame pays it)
    for a difference of 1e-10 px."""
    src = np.asarray(px, dtype=np.float64).reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x
        out = cv2.undistortPointsIter(src, camera.K, camera.dist, None, camera.K, _CRITERIA)
    else:  # OpenCV 5 folded the iterative variant into undistortPoints(..., criteria)
        out = cv2.undistortPoints(src, camera.K, camera.dist, R=None, P=camera.K, criteria=_CRITERIA)
    return out.reshape(-1, 2)


class Lens:
    """One camera's lens for the fit; ``Lens(None)`` (or a camera without distortion) is a pinhole."""

    def __init__(self, camera: CameraModel | None) -> None:
        self.camera = camera if camera is not None and camera.has_distortion else None

    @property
    def distorted(self) -> bool:
        return self.camera is not None

    def fits(self, shape: tuple[int, int]) -> bool:
        """True when the camera model is for images of ``shape`` (H, W) (always for a pinhole)."""
        return self.camera is None or (self.camera.height, self.camera.width) == tuple(shape)

    def ideal(self, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal pixels (k, 2) of the integer pixels (xs, ys) (k,) and the lens' local scale (k, 2, 2)
        d ideal / d pixel (the identity for a pinhole)."""
        if self.camera is None:
            px = np.column_stack([xs, ys]).astype(np.float64)
            return px, np.broadcast_to(np.eye(2), (len(px), 2, 2))
        cam = self.camera
        if cam.width * cam.height <= MAX_TABLE_PIXELS:
            # One take from the (H * W, 2) table by row-major index (the table is 5 MB: each
            # further lookup, as neighbours for a difference, costs a cache miss per pixel).
            ideal = _ideal_table(cam).reshape(-1, 2).take(ys * cam.width + xs, axis=0)
        else:
            ideal = undistort_pixels(cam, np.column_stack([xs, ys]).astype(np.float64))
        # d ideal / d pixel: the inverse of the model's derivative, 2 x 2 in closed form (numpy's
        # batched inverse calls LAPACK once per pixel: a hundred times as slow here).
        j = self.distort_jacobian(ideal)
        a, b, c, d = j[:, 0, 0], j[:, 0, 1], j[:, 1, 0], j[:, 1, 1]
        inv_det = 1.0 / (a * d - b * c)
        out = np.empty_like(j)
        out[:, 0, 0] = d * inv_det
        out[:, 0, 1] = -b * inv_det
        out[:, 1, 0] = -c * inv_det
        out[:, 1, 1] = a * inv_det
        return ideal, out

    def distort(self, ideal: np.ndarray) -> np.ndarray:
        """Image pixels (k, 2) of ideal pixels (k, 2) (OpenCV's distortion model, qrfield.lens)."""
        ideal = np.asarray(ideal, dtype=np.float64)
        if self.camera is None:
            return ideal.copy()
        cam = self.camera
        x = (ideal[:, 0] - cam.cx) / cam.fx
        y = (ideal[:, 1] - cam.cy) / cam.fy
        xd, yd = distort_normalised(cam.dist, x, y)
        return np.column_stack([xd * cam.fx + cam.cx, yd * cam.fy + cam.cy])

    def distort_jacobian(self, ideal: np.ndarray) -> np.ndarray:
        """(k, 2, 2) d pixel / d ideal pixel at ideal pixels (k, 2) (the model's derivative,
        qrfield.lens.distortion_jacobian_terms, in pixels)."""
        ideal = np.asarray(ideal, dtype=np.float64)
        if self.camera is None:
            return np.broadcast_to(np.eye(2), (len(ideal), 2, 2)).copy()
        cam = self.camera
        x = (ideal[:, 0] - cam.cx) / cam.fx
        y = (ideal[:, 1] - cam.cy) / cam.fy
        d00, d01, d11 = distortion_jacobian_terms(cam.dist, x, y)
        out = np.empty((len(ideal), 2, 2))
        out[:, 0, 0] = d00
        out[:, 0, 1] = d01 * (cam.fx / cam.fy)
        out[:, 1, 0] = d01 * (cam.fy / cam.fx)
        out[:, 1, 1] = d11
        return out


def module_points_px(
    lens: Lens | None, corners_px: np.ndarray, n: int, xy: np.ndarray, offset: tuple[int, int] = (0, 0)
) -> np.ndarray:
    """Pixels (k, 2) of module coordinates ``xy`` (k, 2) for a symbol of ``n`` modules whose corners
    V1..V4 are ``corners_px`` (pixels of an image whose top-left pixel is at ``offset`` in the
    camera's image): the plane's homography in ideal pixels, then the lens."""
    corners = np.asarray(corners_px, dtype=np.float64)
    if lens is None or not lens.distorted:
        h = square_to_quad(corners[:, 0], corners[:, 1], float(n))
        p = xy @ h[:, :2].T + h[:, 2]
        return p[:, :2] / p[:, 2:3]
    shift = np.asarray(offset, dtype=np.float64)
    ideal = undistort_pixels(lens.camera, corners + shift)
    h = square_to_quad(ideal[:, 0], ideal[:, 1], float(n))
    p = xy @ h[:, :2].T + h[:, 2]
    return lens.distort(p[:, :2] / p[:, 2:3]) - shift
