"""Geometry: seeded round trips of angles, projection against OpenCV, the IPPE frame."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from qrfield.camera import CameraModel
from qrfield.geometry import (
    Pose,
    angle_difference,
    angles_from_rotation,
    ippe_object_points,
    marker_vertices,
    project_points,
    rotation_from_ippe,
    rotation_matrix,
    rotation_to_ippe,
    wrap_degrees,
)


def _rx(a):
    c, s = np.cos(np.radians(a)), np.sin(np.radians(a))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(b):
    c, s = np.cos(np.radians(b)), np.sin(np.radians(b))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(g):
    c, s = np.cos(np.radians(g)), np.sin(np.radians(g))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_rotation_is_rx_ry_rz_product():
    rng = np.random.default_rng(1)
    for a, b, g in rng.uniform(-180, 180, (50, 3)):
        np.testing.assert_allclose(rotation_matrix([a, b, g]), _rx(a) @ _ry(b) @ _rz(g), atol=1e-12)


def test_angles_round_trip_seeded():
    rng = np.random.default_rng(2)
    angles = np.column_stack(
        [rng.uniform(-180, 180, 2000), rng.uniform(-89.9, 89.9, 2000), rng.uniform(-180, 180, 2000)]
    )
    back = angles_from_rotation(rotation_matrix(angles))
    assert np.abs(angle_difference(back, angles)).max() < 1e-9
    assert np.all(back[:, 1] >= -90) and np.all(back[:, 1] <= 90)
    assert np.all(back[:, [0, 2]] > -180) and np.all(back[:, [0, 2]] <= 180)


def test_extraction_formulas_by_hand():
    # alpha = 30 about X only: R[1,2] = -sin 30, R[2,2] = cos 30
    np.testing.assert_allclose(angles_from_rotation(_rx(30)), [30, 0, 0], atol=1e-12)
    np.testing.assert_allclose(angles_from_rotation(_ry(-40)), [0, -40, 0], atol=1e-12)
    np.testing.assert_allclose(angles_from_rotation(_rz(180)), [0, 0, 180], atol=1e-12)


@pytest.mark.parametrize("beta", [90.0, -90.0])
def test_gimbal_lock_fixes_gamma_to_zero(beta):
    rng = np.random.default_rng(3)
    for a, g in rng.uniform(-170, 170, (20, 2)):
        r = rotation_matrix([a, beta, g])
        out = angles_from_rotation(r)
        assert out[1] == pytest.approx(beta)
        assert out[2] == 0.0
        # Same rotation, whatever the split between alpha and gamma.
        np.testing.assert_allclose(rotation_matrix(out), r, atol=1e-9)


def test_wrap_degrees_range():
    np.testing.assert_allclose(wrap_degrees([-180, 180, 190, -190, 540, 0]), [180, 180, -170, 170, 180, 0])


def test_projection_matches_opencv_with_distortion():
    cam = CameraModel(
        fx=600, fy=590, cx=330, cy=235, width=640, height=480, dist=[-0.28, 0.09, 0.001, -0.0015, -0.01]
    )
    rng = np.random.default_rng(4)
    pts = np.column_stack(
        [rng.uniform(-150, 150, 200), rng.uniform(-100, 100, 200), rng.uniform(200, 900, 200)]
    )
    ours = project_points(pts, cam)
    theirs = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, cam.dist)[0].reshape(-1, 2)
    np.testing.assert_allclose(ours, theirs, atol=1e-9)


def test_upright_card_facing_camera_has_zero_angles():
    # docs/conventions.md: V1 top-left, V2 top-right on screen for an upright card at rotation identity.
    cam = CameraModel.from_focal(500, 640, 480)
    corners = Pose([0, 0, 300], [0, 0, 0]).corners_px(cam, 60)
    (u1, v1), (u2, v2), _, (u4, v4) = corners
    assert u1 < u2 and v1 == pytest.approx(v2) and v4 > v1 and u4 == pytest.approx(u1)
    assert (u1, v1) == pytest.approx((319.5 - 50, 239.5 - 50))  # 30 mm * 500 / 300 = 50 px


def test_ippe_frame_conversion_matches_opencv_solvepnp():
    cam = CameraModel.from_focal(620, 640, 480)
    rng = np.random.default_rng(5)
    for _ in range(30):
        angles = [rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(-180, 180)]
        pose = Pose([rng.uniform(-60, 60), rng.uniform(-40, 40), rng.uniform(250, 700)], angles)
        corners = pose.corners_px(cam, 50.0)
        ok, rvec, tvec = cv2.solvePnP(
            ippe_object_points(50.0), corners, cam.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        assert ok
        r_cv = cv2.Rodrigues(rvec)[0]
        np.testing.assert_allclose(rotation_from_ippe(r_cv), pose.rotation, atol=1e-6)
        np.testing.assert_allclose(tvec.ravel(), pose.position_mm, atol=1e-4)
        np.testing.assert_allclose(rotation_to_ippe(pose.rotation), r_cv, atol=1e-6)
    # The IPPE object points are V1..V4 with Y and Z flipped.
    np.testing.assert_allclose(ippe_object_points(2.0), [[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]])


def test_shape_errors_say_what_is_wrong():
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        rotation_matrix([1.0, 2.0])
    with pytest.raises(ValueError, match="positive"):
        marker_vertices(0.0)
    with pytest.raises(ValueError, match="6 comma-separated"):
        Pose.parse("1,2,3")


def test_shortest_module_px_is_the_shortest_side_over_the_modules():
    # A 30 x 12 px parallelogram-like quad of 25 modules: the short side 12 px, so 0.48 px a module.
    corners = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 12.0], [0.0, 12.0]])
    from qrfield.geometry import shortest_module_px

    assert shortest_module_px(corners, 25) == pytest.approx(12.0 / 25)
    with pytest.raises(ValueError, match=r"\(4, 2\)"):
        shortest_module_px(corners[:3], 25)
