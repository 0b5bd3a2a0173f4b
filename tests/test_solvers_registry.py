"""The pose-method registry: one contract every registered method meets, single and batch, on seeded
poses projected exactly (the truth is the pose itself, not a solver's answer)."""

from __future__ import annotations

import numpy as np
import pytest

from qrfield import methods
from qrfield.geometry import angle_difference, marker_vertices, project_points, rotation_matrix
from qrfield.sampling import random_visible_poses
from qrfield.solvers import POSE_METHODS, SolverError, pose_method, settings_class, solve, solve_batch

SIDE = 50.0


def _corners(camera, pose) -> np.ndarray:
    points = marker_vertices(SIDE) @ rotation_matrix(pose.angles_deg).T + pose.position_mm
    return project_points(points, camera)


def test_the_light_name_list_and_the_registry_agree() -> None:
    assert tuple(POSE_METHODS) == methods.METHODS
    assert (*methods.METHODS, methods.BOTH) == methods.METHOD_CHOICES
    for name, spec in POSE_METHODS.items():
        assert spec.name == name
        assert settings_class(name) is spec.settings_class
        spec.checked_settings(None)  # the defaults are valid


def test_an_unknown_method_is_refused_with_the_known_names() -> None:
    with pytest.raises(SolverError, match="numerical, ippe"):
        pose_method("pnp")


@pytest.mark.parametrize("name", methods.METHODS)
def test_every_method_solves_exact_corners_single_and_batch(name: str, camera_vga) -> None:
    poses = random_visible_poses(camera_vga, SIDE, 12, seed=41, z_range_mm=(200.0, 600.0), max_tilt_deg=40.0)
    corners = np.stack([_corners(camera_vga, p) for p in poses])
    batch = solve_batch(corners, camera_vga, SIDE, method=name)
    for i, pose in enumerate(poses):
        one = solve(corners[i], camera_vga, SIDE, method=name)
        assert one.method == name and one.converged
        for result_pos, result_ang in (
            (one.position_mm, one.angles_deg),
            (batch.position_mm[i], batch.angles_deg[i]),
        ):
            assert np.linalg.norm(result_pos - pose.position_mm) < 0.05
            assert np.max(np.abs(angle_difference(result_ang, pose.angles_deg))) < 0.05
