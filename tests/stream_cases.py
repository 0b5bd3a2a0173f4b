"""Shared cases for the live stream's tests: frames of a known pose whose corners are drawn by
``cv2.projectPoints`` (the truth) plus seeded Gaussian noise of a known covariance, solved by
``qrfield.solvers.solve``, and wrapped as pipeline FrameResults of one stream.

A 30 mm code at 700 mm, tilted about 7 degrees (picam-v2@640x480): with 0.15 px of corner noise
about a third of the frames are ambiguous with the answer on the wrong branch (the mirror nearer
the truth); with 0.005 px none is ambiguous.
"""

from __future__ import annotations

import cv2
import numpy as np

from qrfield.camera import resolve_camera
from qrfield.detect import Detection
from qrfield.geometry import Pose, marker_vertices, rotation_angle_deg
from qrfield.pipeline import OK, FrameResult
from qrfield.solvers import solve
from qrfield.solvers.uncertainty import isotropic_cov

CAMERA = resolve_camera("picam-v2@640x480")
SIDE_MM = 30.0
TRUTH = Pose([10.0, -5.0, 700.0], [6.0, -4.0, 20.0])
TEXT = "stream-case"


def true_corners(pose: Pose = TRUTH, side_mm: float = SIDE_MM) -> np.ndarray:
    """(4, 2) px of V1..V4 by cv2.projectPoints (pinhole: no distortion)."""
    rvec = cv2.Rodrigues(pose.rotation)[0]
    projected, _ = cv2.projectPoints(marker_vertices(side_mm), rvec, pose.position_mm, CAMERA.K, CAMERA.dist)
    return projected.reshape(4, 2)


def noisy_corners(seed: int, noise_px: float, pose: Pose = TRUTH) -> np.ndarray:
    return true_corners(pose) + np.random.default_rng(seed).normal(0.0, noise_px, (4, 2))


def solved(seed: int, noise_px: float, method: str = "numerical", pose: Pose = TRUTH):
    """The solver's result of the noisy corners, solved with their (known) covariance."""
    return solve(
        noisy_corners(seed, noise_px, pose), CAMERA, SIDE_MM, method, corners_cov=isotropic_cov(noise_px)
    )


def wrong_branch_seeds(count: int, method: str = "numerical", noise_px: float = 0.15) -> list[int]:
    """Seeds whose frame is ambiguous with the answer at least 3 degrees further from the truth
    than its mirror candidate, and the mirror within 5 degrees of it (both judged against TRUTH)."""
    out = []
    for seed in range(1000):
        r = solved(seed, noise_px, method)
        if not (r.converged and r.ambiguous and r.alternative is not None and r.alternative.converged):
            continue
        mirror_off = rotation_angle_deg(r.alternative.rotation, TRUTH.rotation)
        if mirror_off < min(rotation_angle_deg(r.rotation, TRUTH.rotation) - 3, 5.0):
            out.append(seed)
            if len(out) == count:
                break
    return out


def frame_result(pose_result, index: int, t_ms: int, text: str | None = TEXT, noise_px: float | None = None):
    """A FrameResult of one method's pose (status OK), its detection carrying the corners, the
    text and the corner covariance (``noise_px`` on each coordinate)."""
    method = pose_result.method
    cov = None if noise_px is None else isotropic_cov(noise_px)
    detection = Detection(
        pose_result.corners_px, text, 1.0, np.full(4, noise_px or 0.1), "track", True, 21, corners_cov=cov
    )
    return FrameResult(
        index, t_ms, OK, detection=detection, poses={method: pose_result}, camera=CAMERA, truth=TRUTH
    )
