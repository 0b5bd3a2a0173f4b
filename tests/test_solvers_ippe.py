"""IPPE solver: exact round trips, the IPPE frame conversion, both candidates, agreement with OpenCV."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from solver_cases import DISTORTED, SIDE_MM, cases, errors, opencv_pose

from qrfield.geometry import (
    IPPE_FLIP,
    Pose,
    ippe_object_points,
    marker_vertices,
    rotation_matrix,
)
from qrfield.solvers import IppeSettings, solve, solve_batch


@pytest.mark.slow
def test_exact_round_trip_within_a_micrometre_and_a_microdegree():
    camera, _, corners, positions, angles = cases(150, seed=21)
    for c, p, a in zip(corners, positions, angles, strict=True):
        r = solve(c, camera, SIDE_MM, "ippe")
        assert r.converged and r.reason == ""
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, p, a)
        assert pos_err < 1e-6, (p, a, r.position_mm)
        assert ang_err < 1e-6, (p, a, r.angles_deg)
        assert r.reprojection_px < 1e-6
        # Vertices are the rigid square at the pose (independent: marker_vertices + true pose).
        truth = Pose(p, a).vertices_mm(SIDE_MM)
        np.testing.assert_allclose(r.vertices_mm, truth, atol=1e-6)


@pytest.mark.parametrize("refine", ["vvs", "none"])
def test_other_refinements_also_recover_exact_poses(refine):
    camera, _, corners, positions, angles = cases(150, seed=21)
    for c, p, a in list(zip(corners, positions, angles, strict=True))[:40]:
        r = solve(c, camera, SIDE_MM, "ippe", IppeSettings(refine=refine))
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, p, a)
        assert pos_err < 1e-5 and ang_err < 1e-5


def test_ippe_frame_conversion():
    # OpenCV's IPPE_SQUARE frame: +Y up, +Z towards the camera; ours: +Y down (V1 -> V4), +Z into the card.
    np.testing.assert_array_equal(IPPE_FLIP, np.diag([1.0, -1.0, -1.0]))
    obj = ippe_object_points(SIDE_MM)
    # OpenCV documents IPPE_SQUARE's points: (-L/2, L/2, 0), (L/2, L/2, 0), (L/2, -L/2, 0), (-L/2, -L/2, 0).
    h = SIDE_MM / 2
    np.testing.assert_array_equal(obj, [[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]])
    camera, _, corners, positions, angles = cases(150, seed=21)
    c, p, a = corners[3], positions[3], angles[3]
    ok, rvec, tvec = cv2.solvePnP(obj, c, camera.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    assert ok
    rot_cv = cv2.Rodrigues(rvec)[0]
    # The same camera-frame vertices from OpenCV's frame and from ours with the converted rotation.
    ours = solve(c, camera, SIDE_MM, "ippe")
    np.testing.assert_allclose(
        obj @ rot_cv.T + tvec.ravel(), marker_vertices(SIDE_MM) @ ours.rotation.T + p, atol=1e-6
    )
    np.testing.assert_allclose(ours.rotation, rotation_matrix(a), atol=1e-9)
    np.testing.assert_allclose(ours.rotation, rot_cv @ IPPE_FLIP, atol=1e-9)
    assert np.linalg.det(ours.rotation) == pytest.approx(1.0)


def test_upright_card_facing_the_camera_is_identity():
    camera, *_ = cases(10, seed=21)
    corners = Pose([0.0, 0.0, 400.0], [0.0, 0.0, 0.0]).corners_px(camera, SIDE_MM)
    r = solve(corners, camera, SIDE_MM, "ippe")
    np.testing.assert_allclose(r.rotation, np.eye(3), atol=1e-9)
    np.testing.assert_allclose(r.position_mm, [0, 0, 400], atol=1e-6)


@pytest.mark.slow
def test_agrees_with_a_direct_opencv_solvepnp_in_our_frame_exact():
    # cv2.solvePnP (iterative, planar homography start) on our marker-frame points: no IPPE, no flip.
    camera, _, corners, _, _ = cases(150, seed=22)
    for c in corners[:60]:
        theirs, _, _ = opencv_pose(c, camera)
        r = solve(c, camera, SIDE_MM, "ippe")
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, theirs.position_mm, theirs.angles_deg)
        # OpenCV's iterative solver stops its LM at about 1e-5 mm; ours is within 1e-6 of the truth.
        assert pos_err < 1e-4 and ang_err < 1e-4


@pytest.mark.slow
def test_agrees_with_a_direct_opencv_solvepnp_in_our_frame_noisy():
    camera, _, corners, _, _ = cases(150, seed=22)
    rng = np.random.default_rng(5)
    for c in corners[:60]:
        noisy = c + rng.normal(0.0, 0.3, c.shape)
        theirs, rvec, tvec = opencv_pose(noisy, camera)
        r = solve(noisy, camera, SIDE_MM, "ippe")
        direct_err = np.sqrt(
            np.mean(
                np.sum(
                    (
                        cv2.projectPoints(marker_vertices(SIDE_MM), rvec, tvec, camera.K, None)[0].reshape(
                            4, 2
                        )
                        - noisy
                    )
                    ** 2,
                    axis=1,
                )
            )
        )
        # Both minimise the same reprojection error; ours picks the better of two local minima.
        assert r.reprojection_px <= direct_err + 1e-6
        if abs(r.reprojection_px - direct_err) < 1e-6:
            pos_err, ang_err = errors(r.position_mm, r.angles_deg, theirs.position_mm, theirs.angles_deg)
            # Same minimum, two LM implementations with their own stopping rules.
            assert pos_err < 0.01 and ang_err < 0.01


@pytest.mark.slow
def test_two_candidates_ranked_with_ambiguity_ratio():
    camera, _, corners, _, _ = cases(150, seed=23)
    rng = np.random.default_rng(9)
    for c in corners[:120]:
        noisy = c + rng.normal(0.0, 0.5, c.shape)
        r = solve(noisy, camera, SIDE_MM, "ippe")
        alt = r.alternative
        assert alt is not None and alt.alternative is None
        assert r.reprojection_px <= alt.reprojection_px
        assert r.ambiguity == pytest.approx(r.reprojection_px / alt.reprojection_px)
        assert 0.0 <= r.ambiguity <= 1.0
        # The two candidates are mirror images: their card normals differ, their centres nearly agree.
        assert np.linalg.norm(r.position_mm - alt.position_mm) < 0.1 * np.linalg.norm(r.position_mm)
        assert np.degrees(np.arccos(min(1.0, r.rotation[:, 2] @ alt.rotation[:, 2]))) > 0.01
        # Independent check of each candidate's reprojection error with OpenCV.
        for cand in (r, alt):
            rvec = cv2.Rodrigues(cand.rotation)[0]
            proj = cv2.projectPoints(marker_vertices(SIDE_MM), rvec, cand.position_mm, camera.K, None)[
                0
            ].reshape(4, 2)
            assert cand.reprojection_px == pytest.approx(
                np.sqrt(np.mean(np.sum((proj - noisy) ** 2, axis=1))), rel=1e-9
            )


def test_distortion_is_undone_before_solving():
    camera, _, corners, positions, angles = cases(80, seed=24, camera_name=DISTORTED.name)
    assert camera.has_distortion
    for c, p, a in zip(corners, positions, angles, strict=True):
        r = solve(c, camera, SIDE_MM, "ippe")
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, p, a)
        assert pos_err < 1e-6 and ang_err < 1e-6
        assert r.reprojection_px < 1e-6


def test_batch_agrees_with_the_single_path():
    # The batch is the vectorised IPPE (tests/test_solvers_ippe_batch.py has the full comparison).
    camera, _, corners, _, _ = cases(150, seed=21)
    b = solve_batch(corners[:20], camera, SIDE_MM, method="ippe")
    for i, c in enumerate(corners[:20]):
        r = solve(c, camera, SIDE_MM, "ippe")
        np.testing.assert_allclose(b.position_mm[i], r.position_mm, atol=1e-6)
        np.testing.assert_allclose(b.angles_deg[i], r.angles_deg, atol=1e-6)
        assert b.converged[i] and b.iterations[i] == 0


@pytest.mark.slow
def test_rendered_view_through_a_distorted_lens():
    from qrfield.render import render_view

    view = render_view(DISTORTED, SIDE_MM, Pose([40.0, -30.0, 280.0], [-25.0, 35.0, 160.0]))
    for method in ("numerical", "ippe"):
        r = solve(view.corners_px, DISTORTED, SIDE_MM, method)
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, view.pose.position_mm, view.pose.angles_deg)
        assert r.converged and pos_err < 1e-6 and ang_err < 1e-6


@pytest.mark.parametrize("position", [(0.0, 0.0, 300.0), (40.0, -25.0, 450.0)])
def test_exactly_square_on_card_is_not_flipped(position):
    # OpenCV 5.0's IPPE_SQUARE degenerates here (both candidates flipped 180 degrees, 70 px error);
    # the answer must still be the pose the corners were made from, worked out by hand:
    # f = 500 px, L = 60 mm -> the code spans 100 px at 300 mm, centred on the principal point.
    from qrfield.camera import CameraModel
    from qrfield.geometry import Pose
    from qrfield.solvers import solve

    camera = CameraModel.from_focal(500.0, 640, 480)
    corners = Pose(position, [0.0, 0.0, 0.0]).corners_px(camera, 60.0)
    if position == (0.0, 0.0, 300.0):
        assert corners.tolist() == [[269.5, 189.5], [369.5, 189.5], [369.5, 289.5], [269.5, 289.5]]
    result = solve(corners, camera, 60.0, method="ippe")
    assert result.converged
    np.testing.assert_allclose(result.position_mm, position, atol=1e-6)
    np.testing.assert_allclose(result.angles_deg, [0.0, 0.0, 0.0], atol=1e-6)
    assert result.reprojection_px < 1e-6


@pytest.mark.parametrize(
    "angles",
    [[0, 22, 0], [0, -35, 0], [30, 0, 0], [0, 0, 35], [0, 0, 180], [0, 0, 90], [20, 0, 180], [0, 40, -90]],
)
def test_poses_set_up_on_purpose_are_exact(angles):
    # Single-axis tilts and in-plane turns are where OpenCV 5.0's IPPE converts a 180-degree
    # rotation through sin(pi) and returns a wrong pose (e.g. beta = 22 alone: 3.3 px, 8 deg off).
    from qrfield.camera import resolve_camera
    from qrfield.geometry import Pose, angle_difference
    from qrfield.solvers import solve

    camera = resolve_camera("picam-v2@640x480")
    for position in ([-30.0, -60.0, 300.0], [0.0, 0.0, 250.0], [45.0, 20.0, 500.0]):
        pose = Pose(position, angles)
        result = solve(pose.corners_px(camera, 50.0), camera, 50.0, method="ippe")
        assert result.converged
        np.testing.assert_allclose(result.position_mm, position, atol=1e-6)
        assert np.abs(angle_difference(result.angles_deg, pose.angles_deg)).max() < 1e-6


@pytest.mark.slow
def test_the_alternative_is_always_the_other_branch_of_the_ambiguity():
    """LM refinement may slide the mirror candidate onto the answer's branch and stop short of it
    (0.1-2 degrees away), or the closed-form third start may replace one candidate only nearly:
    then the "mirror" was the answer again and the flip warning fired on good views (25 of these
    600 seeded noisy views before the fix, 16 of them with ambiguity >= 0.8). The alternative must
    be the other branch: its card normal well away from the answer's."""
    from qrfield.testing.corner_noise import draw_noise, random_corner_cov
    from qrfield.testing.pose_views import corner_set

    views = corner_set(600, seed=9)
    rng = np.random.default_rng(2)
    close = 0
    for view in views:
        noise = draw_noise(rng, random_corner_cov(rng) * 0.1)
        r = solve(view.corners_px + noise, view.camera, view.side_mm, "ippe")
        if r.alternative is not None:
            dot = np.clip(r.rotation[:, 2] @ r.alternative.rotation[:, 2], -1.0, 1.0)
            close += np.degrees(np.arccos(dot)) < 1.0
    assert close == 0
