"""Seeded workspace cases for the solver tests: exact corners from known poses (independent truth)."""

from __future__ import annotations

import functools

import cv2
import numpy as np

from qrfield.camera import CameraModel, resolve_camera
from qrfield.geometry import Pose, angle_difference, angles_from_rotation, marker_vertices
from qrfield.sampling import random_visible_poses
from qrfield.testing.hardset import DISTORTED_CAMERA

SIDE_MM = 50.0
#: A lens with visible barrel distortion (k1, k2, p1, p2, k3), typical of a wide Pi camera (declared
#: once, with the hard benchmark set that uses it too).
DISTORTED = DISTORTED_CAMERA


@functools.lru_cache(maxsize=8)
def cases(count: int, seed: int, camera_name: str = "picam-v2@640x480", max_tilt_deg: float = 60.0):
    """(camera, poses, corners (N, 4, 2), positions (N, 3), angles (N, 3)) over z 150-800 mm."""
    camera = DISTORTED if camera_name == DISTORTED.name else resolve_camera(camera_name)
    poses = random_visible_poses(
        camera, SIDE_MM, count, seed=seed, z_range_mm=(150.0, 800.0), max_tilt_deg=max_tilt_deg
    )
    corners = np.array([p.corners_px(camera, SIDE_MM) for p in poses])
    positions = np.array([p.position_mm for p in poses])
    angles = np.array([p.angles_deg for p in poses])
    for array in (corners, positions, angles):
        array.setflags(write=False)  # cached and shared by tests: a test that edits it must copy
    return camera, poses, corners, positions, angles


def errors(position_mm, angles_deg, true_position_mm, true_angles_deg) -> tuple[np.ndarray, np.ndarray]:
    """Euclidean position error (mm) and largest wrapped angle error (degrees), per row."""
    pos = np.linalg.norm(np.asarray(position_mm) - true_position_mm, axis=-1)
    ang = np.max(np.abs(angle_difference(np.asarray(angles_deg), true_angles_deg)), axis=-1)
    return pos, ang


def opencv_pose(corners_px: np.ndarray, camera: CameraModel) -> tuple[Pose, np.ndarray, np.ndarray]:
    """OpenCV's own pose of a code of SIDE_MM whose V1..V4 are seen at ``corners_px`` (4, 2) px
    through ``camera`` (pinhole): cv2.solvePnP, iterative from its planar homography start (no
    IPPE, no mirror), on our marker-frame vertices. (pose, rvec, tvec), the last two as OpenCV
    gives them."""
    ok, rvec, tvec = cv2.solvePnP(
        marker_vertices(SIDE_MM), corners_px, camera.K, None, flags=cv2.SOLVEPNP_ITERATIVE
    )
    assert ok, "cv2.solvePnP found no pose"
    return Pose(tvec.ravel(), angles_from_rotation(cv2.Rodrigues(rvec)[0])), rvec, tvec
