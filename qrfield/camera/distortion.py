"""Whether a lens model can be used: OpenCV must invert it over the image (qrfield.limits).

The check undistorts points of the image's border with the solvers' own iteration
(:func:`qrfield.lens.undistort_points`) and distorts them back with cv2.projectPoints.
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from qrfield.camera.fields import CameraModelError
from qrfield.lens import undistort_points
from qrfield.limits import DISTORTION_ROUND_TRIP_PX, DISTORTION_SCALE

if TYPE_CHECKING:
    from qrfield.camera.model import CameraModel


def check_distortion(camera: CameraModel, where: str) -> None:
    """CameraModelError naming ``where`` and 'dist' when the lens model cannot be inverted over the image.

    Usable means (qrfield.limits.DISTORTION_ROUND_TRIP_PX): every point of the ellipse inscribed in
    the image (through the middles of its four edges), undistorted by the solvers' own iteration and
    distorted back by cv2.projectPoints, lands within that many pixels of itself, and the radial
    factor r (1 + k1 r^2 + k2 r^4 + k3 r^6) keeps growing out to there (the model does not fold back
    inside it). k1 = 1e6 fails the first (OpenCV's iteration oscillates); k1 = -1 on a wide lens both.
    The image's corners beyond the ellipse are not required: a real calibration with k3 often folds
    there, where its chessboard views never reached (:func:`distortion_note` says so).
    """
    if not camera.has_distortion:
        return
    problem = _distortion_problem(*_distortion_key(camera), corners=False)
    if problem:
        coefficients = ", ".join(f"{d:g}" for d in camera.dist)
        raise CameraModelError(f"{where}: field 'dist' ({coefficients}) {problem}")


def distortion_note(camera: CameraModel) -> str:
    """ "" when the lens model can be inverted over the whole image, corners included; else one line
    saying that poses from codes in the corners are unreliable (for calibrate's advice)."""
    if not camera.has_distortion:
        return ""
    problem = _distortion_problem(*_distortion_key(camera), corners=True)
    if not problem:
        return ""
    return (
        f"the lens model {problem.replace('over the', 'in the corners of the')}: poses from codes "
        "near the corners are unreliable; take views that reach the corners, or calibrate with --fix-k3"
    )


def _distortion_key(camera: CameraModel) -> tuple[Any, ...]:
    return (
        camera.fx,
        camera.fy,
        camera.cx,
        camera.cy,
        camera.width,
        camera.height,
        tuple(camera.dist.tolist()),
    )


@functools.lru_cache(maxsize=64)
def _distortion_problem(
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    width: int,
    height: int,
    dist: tuple[float, ...],
    corners: bool,
) -> str:
    """Why the model cannot be inverted over the inscribed ellipse (or, ``corners``, the whole
    image's border at its pixel edges), or ""."""
    import cv2

    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    D = np.asarray(dist, dtype=float)
    if corners:
        n = 64  # points per side of the border (pixel edges), corners included
        u = np.linspace(-0.5, width - 0.5, n + 1)
        v = np.linspace(-0.5, height - 0.5, n + 1)
        outline = np.concatenate(
            [
                np.column_stack([u, np.full_like(u, -0.5)]),
                np.column_stack([u, np.full_like(u, height - 0.5)]),
                np.column_stack([np.full_like(v, -0.5), v]),
                np.column_stack([np.full_like(v, width - 0.5), v]),
            ]
        )
    else:
        t = np.linspace(0.0, 2.0 * np.pi, 256, endpoint=False)
        outline = np.column_stack(
            [(width - 1) / 2.0 + width / 2.0 * np.cos(t), (height - 1) / 2.0 + height / 2.0 * np.sin(t)]
        )
    pts = outline.reshape(-1, 1, 2)
    with np.errstate(all="ignore"):
        # The solvers' iteration (qrfield.lens) is what must work.
        ideal = undistort_points(pts, K, D).reshape(-1, 2)
        if not np.all(np.isfinite(ideal)):
            return f"cannot be inverted over the {width}x{height} image (OpenCV's undistortion diverges)"
        rays = np.column_stack([ideal, np.ones(len(ideal))])
        back, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, D)
        miss = float(np.nanmax(np.abs(back.reshape(-1, 2) - outline)))
    if not math.isfinite(miss) or miss > DISTORTION_ROUND_TRIP_PX:
        return (
            f"cannot be inverted over the {width}x{height} image: undistorting points of the image and "
            f"distorting them back misses by {miss:.3g} px (at most {DISTORTION_ROUND_TRIP_PX:g} px)"
        )
    distorted = np.column_stack([(outline[:, 0] - cx) / fx, (outline[:, 1] - cy) / fy])
    with np.errstate(all="ignore"):
        scale = np.hypot(distorted[:, 0], distorted[:, 1]) / np.hypot(ideal[:, 0], ideal[:, 1])
    scale = scale[np.isfinite(scale)]
    for extreme in (float(scale.min()), float(scale.max())) if scale.size else ():
        if not DISTORTION_SCALE.minimum <= extreme <= DISTORTION_SCALE.maximum:
            return (
                f"{'stretches' if extreme > 1 else 'shrinks'} the {width}x{height} image's edge "
                f"{extreme:.3g} times (a real lens: {DISTORTION_SCALE.minimum:.2g}.."
                f"{DISTORTION_SCALE.maximum:g}); is it a calibration of this camera?"
            )
    k1, k2, k3 = D[0], D[1] if D.size > 1 else 0.0, D[4] if D.size > 4 else 0.0
    r = np.linspace(0.0, float(np.hypot(ideal[:, 0], ideal[:, 1]).max()), 2001)
    growth = 1.0 + 3.0 * k1 * r**2 + 5.0 * k2 * r**4 + 7.0 * k3 * r**6  # d/dr of r * radial factor
    if np.any(growth <= 0.0):
        fold = float(r[np.argmax(growth <= 0.0)])
        return (
            f"folds back over the {width}x{height} image: its radial distortion stops growing "
            f"{math.degrees(math.atan(fold)):.1f} degrees off the axis, inside the field of view"
        )
    return ""
