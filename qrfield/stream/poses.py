"""A pose's covariance in the coordinates a stream works in, and a pose result moved to a new pose.

The solvers report ``pose_cov`` over (x, y, z mm, alpha, beta, gamma deg) (docs/uncertainty.md). A
stream compares and filters rotations as small rotation vectors w (radians) of the camera frame,
R -> exp([w]x) R, the solvers' own omega: :func:`vector_cov` converts one to the other through
the Euler-rate matrix (``qrfield.solvers.uncertainty.euler_jacobian``, d angles / d w), and
:func:`angles_cov` back. :func:`moved_result` is a solver's PoseResult with its pose replaced by
another (a filtered one): position, rotation, angles, the rigid square's vertices, the reprojection
against the frame's own corners and the std fields, all of the new pose, so that the result stays
consistent. Conventions: docs/conventions.md (camera frame, V1..V4, mm and degrees).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import angles_from_rotation, marker_vertices, transform_points
from qrfield.solvers.floats import reprojection_single
from qrfield.solvers.result import PoseResult
from qrfield.solvers.uncertainty import euler_jacobian, pose_std


def _euler(angles_deg: np.ndarray) -> np.ndarray | None:
    """d(alpha, beta, gamma deg) / d w (rad) at ``angles_deg`` (3,), None at gimbal lock."""
    jac = euler_jacobian(np.asarray(angles_deg, dtype=float))
    return jac if np.all(np.isfinite(jac)) else None


def vector_cov(pose: PoseResult) -> np.ndarray | None:
    """(6, 6) covariance of (x, y, z mm, w rad) of a pose result (its ``pose_cov`` converted), or
    None when the pose has no finite covariance or sits at gimbal lock (beta = +-90 degrees)."""
    cov = np.asarray(pose.pose_cov, dtype=float)
    if cov.shape != (6, 6) or not np.all(np.isfinite(cov)):
        return None
    jac = _euler(pose.angles_deg)
    if jac is None:
        return None
    to_vector = np.eye(6)
    to_vector[3:, 3:] = np.linalg.inv(jac)  # d w / d angles, rad per degree
    return to_vector @ cov @ to_vector.T


def angles_cov(cov: np.ndarray, angles_deg: np.ndarray) -> np.ndarray:
    """(6, 6) covariance of (x, y, z mm, alpha, beta, gamma deg) from one of (x, y, z mm, w rad)
    at the pose's angles (3,); NaN at gimbal lock."""
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (6, 6):
        raise ValueError(f"a pose covariance over (x, y, z, w) must be (6, 6), got {cov.shape}")
    jac = _euler(angles_deg)
    if jac is None:
        return np.full((6, 6), np.nan)
    to_angles = np.eye(6)
    to_angles[3:, 3:] = jac
    return to_angles @ cov @ to_angles.T


def moved_result(
    base: PoseResult,
    rotation: np.ndarray,
    position_mm: np.ndarray,
    cov: np.ndarray,
    camera: CameraModel,
    side_mm: float,
) -> PoseResult:
    """``base`` (a converged solver result of one frame) at another pose (R (3, 3) marker to
    camera, t (3,) mm) with covariance ``cov`` (6, 6) over (x, y, z mm, w rad): the pose fields,
    the rigid square's vertices V1..V4, the RMS reprojection against ``base.corners_px`` through
    ``camera`` and the std fields all follow the new pose; the rest (method, corners, convergence,
    the frame's mirror test) stays the frame's."""
    rotation = np.array(rotation, dtype=float)
    position = np.array(position_mm, dtype=float).reshape(3)
    if rotation.shape != (3, 3):
        raise ValueError(f"rotation must be (3, 3), got {rotation.shape}")
    angles = angles_from_rotation(rotation)
    pose_cov = angles_cov(cov, angles)
    position_std, angles_std = pose_std(pose_cov)
    flat = np.asarray(base.corners_px, dtype=float).reshape(8).tolist()
    return replace(
        base,
        position_mm=position,
        angles_deg=angles,
        rotation=rotation,
        vertices_mm=transform_points(rotation, position, marker_vertices(side_mm)),
        reprojection_px=reprojection_single(rotation.tolist(), position.tolist(), side_mm, camera, flat),
        pose_cov=pose_cov,
        position_std_mm=position_std,
        angles_std_deg=angles_std,
    )
