"""Rigid transforms of qrfield.handeye.rigid against hand values and OpenCV (cv2.Rodrigues)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qrfield.geometry import rotation_matrix
from qrfield.handeye import rigid

unit = st.floats(-1.0, 1.0, allow_nan=False)
vectors = st.tuples(unit, unit, unit).filter(lambda v: np.linalg.norm(v) > 1e-3)


def test_quaternion_of_a_quarter_turn_about_z_is_rz_90():
    s = math.sqrt(0.5)
    r = rigid.rotation_from_quaternion([s, 0.0, 0.0, s])
    np.testing.assert_allclose(r, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(rigid.quaternion_from_rotation(r), [s, 0, 0, s], atol=1e-12)


def test_half_turn_about_x_round_trips():
    r = np.diag([1.0, -1.0, -1.0])
    q = rigid.quaternion_from_rotation(r)
    np.testing.assert_allclose(np.abs(q), [0, 1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(np.abs(rigid.rotation_log(r)), [math.pi, 0, 0], atol=1e-12)


def test_a_quaternion_that_is_not_unit_is_refused_naming_its_norm():
    with pytest.raises(ValueError, match=r"unit quaternion.*norm is 2\.0"):
        rigid.rotation_from_quaternion([2.0, 0.0, 0.0, 0.0], "pairs.csv line 3")


@settings(max_examples=60, deadline=None)
@given(vectors, st.floats(0.0, 3.1))
def test_exp_and_log_agree_with_cv2_rodrigues(axis, angle):
    v = np.array(axis) / np.linalg.norm(axis) * angle
    np.testing.assert_allclose(rigid.rotation_exp(v), cv2.Rodrigues(v)[0], atol=1e-12)
    np.testing.assert_allclose(rigid.rotation_log(cv2.Rodrigues(v)[0]), v, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.tuples(unit, unit, unit, unit).filter(lambda q: np.linalg.norm(q) > 0.1))
def test_quaternion_round_trip_and_hamilton_convention(q):
    q = np.array(q) / np.linalg.norm(q)
    r = rigid.rotation_from_quaternion(q)

    # Hamilton: v' = q v q*, by hand with quaternion products.
    def mul(a, b):
        w1, x1, y1, z1 = a
        w2, x2, y2, z2 = b
        return np.array(
            [
                w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            ]
        )

    v = np.array([0.3, -1.2, 2.0])
    turned = mul(mul(q, np.r_[0.0, v]), q * [1, -1, -1, -1])[1:]
    np.testing.assert_allclose(r @ v, turned, atol=1e-12)
    back = rigid.quaternion_from_rotation(r)
    assert back[0] >= 0
    assert min(np.abs(back - q).max(), np.abs(back + q).max()) < 1e-9  # q and -q are one rotation


def test_invert_composes_to_identity_and_pose_transform_round_trips():
    t = rigid.transform_from_pose([10.0, -5.0, 300.0], [15.0, -20.0, 170.0])
    np.testing.assert_allclose(t[:3, :3], rotation_matrix([15.0, -20.0, 170.0]))
    np.testing.assert_allclose(rigid.invert(t) @ t, np.eye(4), atol=1e-12)
    position, angles = rigid.pose_from_transform(t)
    np.testing.assert_allclose(position, [10, -5, 300])
    np.testing.assert_allclose(angles, [15, -20, 170], atol=1e-12)


def test_difference_undoes_perturbed():
    t = rigid.transform_from_pose([1.0, 2.0, 3.0], [30.0, 10.0, -60.0])
    delta = np.array([0.5, -0.2, 1.0, 0.01, -0.02, 0.005])
    np.testing.assert_allclose(rigid.difference(rigid.perturbed(t, delta), t), delta, atol=1e-12)


def test_check_transform_names_what_is_wrong():
    with pytest.raises(ValueError, match="shape"):
        rigid.check_transform(np.eye(3), "camera_to_tool")
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(ValueError, match="camera_to_tool: the upper-left 3x3 is not a rotation"):
        rigid.check_transform(bad, "camera_to_tool")
    bad = np.eye(4)
    bad[3, 0] = 1.0
    with pytest.raises(ValueError, match="last row"):
        rigid.check_transform(bad, "camera_to_tool")
    with pytest.raises(ValueError, match="not a rotation"):
        rigid.check_transform(np.diag([1.0, 1.0, -1.0, 1.0]))
