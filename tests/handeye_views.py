"""An independent renderer for the hand-eye tests: views of a QR card drawn without qrfield's
renderer (qrfield.render) or the hard set's rasteriser.

The symbol is encoded by segno (not OpenCV's encoder). Each camera pixel is the mean of a regular
4 x 4 grid of point samples, each traced as a ray from the camera (OpenCV's undistortPoints for a
lens with distortion) to the card's plane and looked up in the module matrix: dark modules, the
light card (a 4-module quiet zone and a 2-module margin), the background beyond. Then a Gaussian
blur, Gaussian noise and rounding to uint8. The truth is the pose it was drawn at.
"""

from __future__ import annotations

import cv2
import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose

QUIET, MARGIN = 4, 2


def symbol(text: str = "qrfield hand-eye 28") -> np.ndarray:
    """(n, n) bool, True = dark, no quiet zone (segno, error level M)."""
    import segno

    return np.array(segno.make(text, error="m", micro=False).matrix, dtype=bool)


def _rays(camera: CameraModel, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(k, 3) ray directions (x/z, y/z, 1) of pixels (u, v)."""
    if camera.has_distortion:
        pts = np.column_stack([u, v]).reshape(-1, 1, 2).astype(np.float64)
        xy = cv2.undistortPoints(pts, camera.K, camera.dist).reshape(-1, 2)
    else:
        xy = np.column_stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy])
    return np.column_stack([xy, np.ones(len(xy))])


def draw(
    camera: CameraModel,
    pose: Pose,
    side_mm: float,
    matrix: np.ndarray,
    *,
    light: float = 215.0,
    dark: float = 35.0,
    background: float = 120.0,
    blur_px: float = 0.6,
    noise: float = 2.0,
    seed: int = 0,
    grid: int = 4,
) -> np.ndarray:
    """(H, W) uint8: the card at ``pose`` (marker to camera, mm, degrees) seen by ``camera``."""
    n = matrix.shape[0]
    pitch = side_mm / n
    r, t = pose.rotation, pose.position_mm
    half = side_mm / 2 + (QUIET + MARGIN) * pitch
    # The card's outline in pixels (through the lens) bounds the region to trace.
    edge = np.linspace(-half, half, 41)
    sides = [np.column_stack([edge, np.full_like(edge, s)]) for s in (-half, half)]
    sides += [np.column_stack([np.full_like(edge, s), edge]) for s in (-half, half)]
    ring = np.concatenate(sides)
    points = ring @ r[:, :2].T + t
    px, _ = cv2.projectPoints(points, cv2.Rodrigues(np.eye(3))[0], np.zeros(3), camera.K, camera.dist)
    px = px.reshape(-1, 2)
    w, h = camera.size
    x0, y0 = max(int(px[:, 0].min()) - 3, 0), max(int(px[:, 1].min()) - 3, 0)
    x1, y1 = min(int(px[:, 0].max()) + 4, w), min(int(px[:, 1].max()) + 4, h)
    image = np.full((h, w), background)
    offsets = (np.arange(grid) + 0.5) / grid - 0.5
    ys, xs = np.mgrid[y0:y1, x0:x1]
    su = (xs[..., None, None] + offsets[None, None, None, :]).repeat(grid, axis=2)
    sv = (ys[..., None, None] + offsets[None, None, :, None]).repeat(grid, axis=3)
    rays = _rays(camera, su.ravel(), sv.ravel())
    # The plane z = 0 of the marker: camera point s * ray = R (X, Y, 0) + t, solved for (X, Y, s).
    plane = np.linalg.inv(np.column_stack([r[:, 0], r[:, 1], t]))
    q = rays @ plane.T
    card = q[:, :2] / q[:, 2:3]
    col = np.floor(card[:, 0] / pitch + n / 2).astype(int)
    row = np.floor(card[:, 1] / pitch + n / 2).astype(int)
    inside = (col >= 0) & (col < n) & (row >= 0) & (row < n)
    on_card = (np.abs(card[:, 0]) <= half) & (np.abs(card[:, 1]) <= half) & (q[:, 2] > 0)
    value = np.where(on_card, light, background)
    value[inside] = np.where(matrix[row[inside], col[inside]], dark, light)
    image[y0:y1, x0:x1] = value.reshape(y1 - y0, x1 - x0, grid * grid).mean(axis=2)
    if blur_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_px, borderType=cv2.BORDER_REPLICATE)
    rng = np.random.default_rng(seed)
    return np.clip(np.round(image + rng.normal(0.0, noise, image.shape)), 0, 255).astype(np.uint8)
