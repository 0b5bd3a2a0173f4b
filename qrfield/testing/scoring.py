"""A drawn frame's pose scored against its truth: the criteria of issue 25's stream benchmark and
the stream tests (2 deg / 5 mm; confidently wrong = unflagged and beyond both the criteria and 4 of
its own std). One home, so the benchmark and the tests judge frames alike."""

from __future__ import annotations

from typing import Any

import numpy as np

#: The criteria: every angle within ANGLE_DEG and the position within POSITION_MM of the truth;
#: a miss beyond WRONG_SIGMA of the pose's own std is confidently wrong.
ANGLE_DEG, POSITION_MM, WRONG_SIGMA = 2.0, 5.0, 4.0


def pose_errors(pose: Any, truth: Any) -> tuple[np.ndarray, np.ndarray]:
    """(position error (3,) mm, angle error (3,) deg, wrapped) of ``pose`` against ``truth``, both
    in the camera frame (docs/conventions.md)."""
    from qrfield.geometry import angle_difference

    return pose.position_mm - truth.position_mm, angle_difference(pose.angles_deg, truth.angles_deg)


def meets(pose: Any, truth: Any) -> bool:
    """Every angle within 2 deg and the position within 5 mm of the truth."""
    dp, da = pose_errors(pose, truth)
    return bool(np.all(np.abs(da) <= ANGLE_DEG) and np.linalg.norm(dp) <= POSITION_MM)


def confidently_wrong(pose: Any, truth: Any) -> bool:
    """Not flagged, and an angle more than 2 deg and 4 of its std off, or the position more than
    5 mm off and a coordinate more than 4 of its std off (an unknown std counts as exceeded)."""
    if pose.ambiguous:
        return False
    dp, da = pose_errors(pose, truth)
    with np.errstate(invalid="ignore", divide="ignore"):
        angle = bool(np.any((np.abs(da) > ANGLE_DEG) & ~(np.abs(da) <= WRONG_SIGMA * pose.angles_std_deg)))
        position = bool(
            np.linalg.norm(dp) > POSITION_MM and np.any(~(np.abs(dp) <= WRONG_SIGMA * pose.position_std_mm))
        )
    return angle or position
