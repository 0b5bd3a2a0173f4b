"""Seeded random poses in the workspace, for tests, benchmarks and the simulation.

Tilt is the angle between the card's normal and the camera's optical axis (``tilt_from="axis"``,
the angles' own reference) or the line of sight to the card's centre (``"line_of_sight"``, what a
detector sees: foreshortening); the in-plane rotation about the normal is uniform over the full turn.
"""

from __future__ import annotations

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, angles_from_rotation, rotation_matrix
from qrfield.visibility import view_of


def _axis_angle(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    kx, ky, kz = axis / np.linalg.norm(axis)
    k = np.array([[0, -kz, ky], [kz, 0, -kx], [-ky, kx, 0]])
    return np.eye(3) + np.sin(angle_rad) * k + (1 - np.cos(angle_rad)) * (k @ k)


def _align_z(direction: np.ndarray) -> np.ndarray:
    """The smallest rotation taking +Z to ``direction``."""
    d = direction / np.linalg.norm(direction)
    axis = np.cross([0.0, 0.0, 1.0], d)
    if np.linalg.norm(axis) < 1e-12:
        return np.eye(3)
    return _axis_angle(axis, float(np.arccos(np.clip(d[2], -1.0, 1.0))))


def random_tilted_rotation(rng: np.random.Generator, max_tilt_deg: float) -> np.ndarray:
    """A rotation whose card normal lies within ``max_tilt_deg`` of the optical axis, any in-plane turn."""
    gamma = rng.uniform(-180.0, 180.0)
    tilt = np.radians(rng.uniform(0.0, max_tilt_deg))
    phi = rng.uniform(0.0, 2 * np.pi)
    return _axis_angle(np.array([np.cos(phi), np.sin(phi), 0.0]), tilt) @ rotation_matrix([0.0, 0.0, gamma])


def random_visible_poses(
    camera: CameraModel,
    side_mm: float,
    count: int,
    seed: int = 0,
    z_range_mm: tuple[float, float] = (150.0, 800.0),
    max_tilt_deg: float = 50.0,
    margin_px: float = 8.0,
    tilt_from: str = "axis",
) -> list[Pose]:
    """``count`` seeded poses in view (:mod:`qrfield.visibility`), vertices ``margin_px`` inside the image.

    Raises ValueError when the workspace cannot hold the code (e.g. a 300 mm code at 150 mm).
    """
    if tilt_from not in ("axis", "line_of_sight"):
        raise ValueError(f"tilt_from must be 'axis' or 'line_of_sight', got {tilt_from!r}")
    rng = np.random.default_rng(seed)
    poses: list[Pose] = []
    attempts = 0
    while len(poses) < count:
        attempts += 1
        if attempts > 200 * count + 1000:
            raise ValueError(
                f"could not place {count} visible {side_mm} mm codes in z {z_range_mm} mm "
                f"for camera {camera.name}; widen the range or shrink the code"
            )
        z = rng.uniform(*z_range_mm)
        half_w = (camera.width / 2) * z / camera.fx
        half_h = (camera.height / 2) * z / camera.fy
        x = rng.uniform(-half_w, half_w) + (camera.width / 2 - 0.5 - camera.cx) * z / camera.fx
        y = rng.uniform(-half_h, half_h) + (camera.height / 2 - 0.5 - camera.cy) * z / camera.fy
        rotation = random_tilted_rotation(rng, max_tilt_deg)
        if tilt_from == "line_of_sight":
            rotation = _align_z(np.array([x, y, z])) @ rotation
        pose = Pose(np.array([x, y, z]), angles_from_rotation(rotation))
        if view_of(camera, side_mm, pose.rotation, pose.position_mm, margin_px=margin_px).in_view:
            poses.append(pose)
    return poses
