"""The vectorised view check against the renderer's own check, and the 89-degree edge-on case."""

from __future__ import annotations

import math

import numpy as np
import pytest

from qrfield.geometry import Pose, rotation_matrix
from qrfield.render import RenderError, check_view
from qrfield.simulation.view import poses_in_view


def _seen_by_renderer(camera, side, pose, max_view_deg):
    """Independent truth: render.check_view, plus the obliquity limit computed from the pose."""
    try:
        check_view(camera, side, pose)
    except RenderError:
        return False
    normal = pose.rotation[:, 2]
    t = pose.position_mm
    cos_view = float(normal @ t) / float(np.linalg.norm(t))
    return math.degrees(math.acos(min(1.0, cos_view))) <= max_view_deg


@pytest.mark.slow
@pytest.mark.parametrize("max_view_deg", [90.0, 70.0])
def test_view_mask_matches_the_renderers_check(camera_vga, max_view_deg):
    rng = np.random.default_rng(5)
    angles = rng.uniform(-95, 95, size=(40, 3))
    positions = np.column_stack(
        [rng.uniform(-250, 250, 30), rng.uniform(-200, 200, 30), rng.uniform(20, 600, 30)]
    )
    in_view, corners = poses_in_view(camera_vga, 50.0, rotation_matrix(angles), positions, max_view_deg)
    expected = np.array(
        [[_seen_by_renderer(camera_vga, 50.0, Pose(p, a), max_view_deg) for a in angles] for p in positions]
    )
    assert 0.05 < expected.mean() < 0.95  # both kinds present
    np.testing.assert_array_equal(in_view, expected)
    g, a = np.argwhere(in_view)[0]
    np.testing.assert_allclose(corners[g, a], Pose(positions[g], angles[a]).corners_px(camera_vga, 50.0))


def test_tilt_of_89_degrees_is_out_of_view(camera_vga):
    # Every tilting combination at t = 89 deg in front of the camera: seen edge-on (89 deg from the
    # card's normal, beyond the 85 deg limit) or facing away.
    multipliers = [(1, 0, 0), (0, 1, 0), (1, 1, 0), (1, -1, 0), (1, 0, 1), (0, 1, -1), (1, 1, 1), (1, -1, 1)]
    angles = 89.0 * np.array(multipliers, float)
    positions = np.array([[0, 0, 200], [0, 0, 300], [0, 0, 450]], float)
    in_view, _ = poses_in_view(camera_vga, 50.0, rotation_matrix(angles), positions, 85.0)
    assert not in_view.any()
    # ...while the same poses at 60 deg are seen (the check does not just reject everything).
    in_view_60, _ = poses_in_view(camera_vga, 50.0, rotation_matrix(angles * 60 / 89), positions, 85.0)
    assert in_view_60.all()
    # Off the axis, where the line of sight meets the card 89 deg from its normal or more, too.
    pose = Pose([0.0, 60.0, 300.0], [89.0, 0.0, 0.0])  # normal points to -y; the camera sees its back
    assert not poses_in_view(camera_vga, 50.0, pose.rotation[None], pose.position_mm[None], 85.0)[0][0, 0]


def test_a_card_beyond_the_lens_field_of_view_is_out_of_view():
    # OpenCV's 5-coefficient model folds back far off the axis: with this wide lens (k1 = -0.28) a
    # card 67 degrees off the axis of a 62-degree-wide view projects inside the image, mirrored.
    from solver_cases import DISTORTED

    from qrfield.geometry import project_points

    pose = Pose([720.0, 0.0, 300.0], [0.0, 50.0, 0.0])
    folded = project_points(pose.vertices_mm(20.0), DISTORTED)
    assert np.all((folded >= 0) & (folded <= [639, 479]))  # the model's pixels are inside the image
    with pytest.raises(RenderError, match="beyond the lens' field of view"):
        check_view(DISTORTED, 20.0, pose)
    in_view, _ = poses_in_view(DISTORTED, 20.0, pose.rotation[None], pose.position_mm[None])
    assert not in_view[0, 0]
    # A card inside the field of view, near the image's edge, stays in view.
    near_edge = Pose([165.0, 0.0, 300.0], [0.0, 20.0, 0.0])
    check_view(DISTORTED, 20.0, near_edge)
    assert poses_in_view(DISTORTED, 20.0, near_edge.rotation[None], near_edge.position_mm[None])[0][0, 0]
