"""The acceptance rule's one home (qrfield.sessions.criteria): errors and verdicts by hand.

docs/conventions.md: each of alpha, beta, gamma within 2 degrees (inclusive, wrapped) and the
position within 5 mm (Euclidean, strict).
"""

from __future__ import annotations

import numpy as np
import pytest

from qrfield.sessions.criteria import AcceptanceCriteria, pose_errors

TRUTH_POS, TRUTH_ANG = [10.0, -20.0, 300.0], [179.0, 0.0, -30.0]


def test_pose_errors_by_hand() -> None:
    # 3-4-5 triangle; -179 is 2 degrees past 179 (wrapped, not 358); beta and gamma signed.
    err_pos, err_ang = pose_errors([13.0, -16.0, 300.0], [-179.0, -1.5, -28.0], TRUTH_POS, TRUTH_ANG)
    assert float(err_pos) == pytest.approx(5.0)
    np.testing.assert_allclose(err_ang, [2.0, -1.5, 2.0], atol=1e-12)


@pytest.mark.parametrize(
    ("position", "angles", "passed"),
    [
        ([13.0, -16.0, 300.0], [179.0, 0.0, -30.0], False),  # exactly 5 mm: strict, fails
        ([12.9, -16.0, 300.0], [179.0, 0.0, -30.0], True),  # 4.94 mm
        ([10.0, -20.0, 300.0], [-179.0, 2.0, -32.0], True),  # every angle exactly 2 deg: inclusive
        ([10.0, -20.0, 300.0], [179.0, 2.01, -30.0], False),
        ([np.nan, -20.0, 300.0], [179.0, 0.0, -30.0], False),  # no pose never passes
    ],
)
def test_judge_one_pose(position, angles, passed) -> None:
    ok, _, _ = AcceptanceCriteria().judge(position, angles, TRUTH_POS, TRUTH_ANG)
    assert bool(ok) is passed


def test_judge_a_batch_against_one_truth_and_against_many() -> None:
    positions = np.array([[13.0, -16.0, 300.0], [10.0, -20.0, 301.0], [10.0, -20.0, 300.0]])
    angles = np.array([[179.0, 0.0, -30.0], [-179.5, 0.0, -30.0], [179.0, 0.0, -27.0]])
    ok, err_pos, worst = AcceptanceCriteria().judge(positions, angles, TRUTH_POS, TRUTH_ANG)
    assert ok.tolist() == [False, True, False]
    np.testing.assert_allclose(err_pos, [5.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(worst, [0.0, 1.5, 3.0], atol=1e-12)
    per_row = AcceptanceCriteria().judge(
        positions, angles, np.tile(TRUTH_POS, (3, 1)), np.tile(TRUTH_ANG, (3, 1))
    )
    assert per_row[0].tolist() == ok.tolist()
    loose = AcceptanceCriteria(max_angle_error_deg=5.0, max_position_error_mm=6.0)
    assert loose.judge(positions, angles, TRUTH_POS, TRUTH_ANG)[0].tolist() == [True, True, True]


def test_pose_errors_say_what_shape_was_wrong() -> None:
    with pytest.raises(ValueError, match=r"position_mm: \(3,\) or \(N, 3\) expected, got shape \(2,\)"):
        pose_errors([1.0, 2.0], [0.0, 0.0, 0.0], TRUTH_POS, TRUTH_ANG)
