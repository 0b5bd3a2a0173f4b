"""Pose helpers on Python floats for the single-solve paths (no numpy call overhead on 4 points).

Rotations are given as rows [[r00, r01, r02], ...] (marker to camera, docs/conventions.md), positions in mm.
"""

from __future__ import annotations

import math

from qrfield.camera import CameraModel
from qrfield.geometry import GIMBAL_EPS
from qrfield.lens import distort_normalised


def angles_single(r: list[list[float]]) -> list[float]:
    """Scalar twin of geometry.angles_from_rotation: (alpha, beta, gamma) in degrees from rows of R."""
    s = min(max(r[0][2], -1.0), 1.0)
    beta = math.asin(s)
    if abs(s) > 1.0 - GIMBAL_EPS:  # the same gimbal-lock threshold as the numpy twin
        alpha = math.atan2(math.copysign(1.0, s) * r[1][0], r[1][1])
        gamma = 0.0
    else:
        alpha = math.atan2(-r[1][2], r[2][2])
        gamma = math.atan2(-r[0][1], r[0][0])
    out = [math.degrees(alpha), math.degrees(beta), math.degrees(gamma)]
    for k in (0, 2):
        if out[k] <= -180.0:
            out[k] += 360.0
    return out


def reprojection_single(
    r: list[list[float]], t: list[float], side: float, camera: CameraModel, flat: list[float]
) -> float:
    """RMS pixel distance between the corners and the projection of the rigid square at pose (R, t)."""
    h = side / 2.0
    dist = camera.dist.tolist()
    distort = dist != [0.0, 0.0, 0.0, 0.0, 0.0]
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    (r00, r01, _), (r10, r11, _), (r20, r21, _) = r
    tx, ty, tz = t
    total = 0.0
    for i, qx, qy in ((0, -h, -h), (2, h, -h), (4, h, h), (6, -h, h)):
        pz = r20 * qx + r21 * qy + tz
        if pz <= 0.0:
            return math.inf
        xn = (r00 * qx + r01 * qy + tx) / pz
        yn = (r10 * qx + r11 * qy + ty) / pz
        if distort:
            xn, yn = distort_normalised(dist, xn, yn)
        du = fx * xn + cx - flat[i]
        dv = fy * yn + cy - flat[i + 1]
        total += du * du + dv * dv
    return math.sqrt(total / 4.0)
