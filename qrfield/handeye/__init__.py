"""Hand-eye calibration: the code's pose in the gripper's tool frame or the robot's base frame.

docs/conventions.md ("Hand-eye") and docs/handeye.md. Parts:

- :mod:`~qrfield.handeye.setups`: the two set-ups and the frames (names declared once);
- :mod:`~qrfield.handeye.rigid`: 4x4 transforms, quaternions, rotation vectors;
- :mod:`~qrfield.handeye.diversity`: whether the robot's poses turn about enough axes;
- :mod:`~qrfield.handeye.solve`: :func:`solve_handeye` (Park-Martin, then weighted least squares
  over every pair with each pose's covariance; residuals; the transform's covariance).
"""

from __future__ import annotations

from qrfield.handeye.setups import (
    BASE,
    CAMERA,
    EYE_IN_HAND,
    EYE_TO_HAND,
    FRAMES,
    SETUPS,
    TOOL,
    HandEyeError,
)
from qrfield.handeye.solve import HandEyeResult, Pair, solve_handeye

__all__ = [
    "BASE",
    "CAMERA",
    "EYE_IN_HAND",
    "EYE_TO_HAND",
    "FRAMES",
    "SETUPS",
    "TOOL",
    "HandEyeError",
    "HandEyeResult",
    "Pair",
    "solve_handeye",
]
