"""Hand-eye calibration: the code's pose in the gripper's tool frame or the robot's base frame.

docs/conventions.md ("Hand-eye") and docs/handeye.md. Parts:

- :mod:`~qrfield.handeye.setups`: the two set-ups and the frames (names declared once);
- :mod:`~qrfield.handeye.rigid`: 4x4 transforms, quaternions, rotation vectors;
- :mod:`~qrfield.handeye.diversity`: whether the robot's poses turn about enough axes;
- :mod:`~qrfield.handeye.solve`: :func:`solve_handeye` (Park-Martin, then weighted least squares
  over every pair with each pose's covariance; residuals; the transform's covariance);
- :mod:`~qrfield.handeye.store`: ``handeye.json`` (:class:`HandEyeCalibration`);
- :mod:`~qrfield.handeye.frames`: poses and their covariance in the tool or base frame
  (:class:`PoseFrame`; :class:`InFrame`, :class:`InFrameEvents` in front of a frame loop's sink or events);
- :mod:`~qrfield.handeye.measure`: the code's pose in one image, judged fit for a pair;
- :mod:`~qrfield.handeye.pairs`: ``pairs.csv`` and :class:`PairCollector` (pairs from a frame loop);
- :mod:`~qrfield.handeye.settings`: the ``frame`` and ``handeye_file`` settings;
- :mod:`~qrfield.handeye.robot`: :class:`SimulatedRobot`, a known transform driving the virtual bench.
"""

from __future__ import annotations

from qrfield.handeye.frames import InFrame, InFrameEvents, PoseFrame
from qrfield.handeye.pairs import PairCollector, read_pairs_csv
from qrfield.handeye.robot import SimulatedRobot
from qrfield.handeye.settings import HandEyeSettings
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
from qrfield.handeye.store import FILE_NAME, HandEyeCalibration

__all__ = [
    "BASE",
    "CAMERA",
    "EYE_IN_HAND",
    "EYE_TO_HAND",
    "FILE_NAME",
    "FRAMES",
    "SETUPS",
    "TOOL",
    "HandEyeCalibration",
    "HandEyeError",
    "HandEyeResult",
    "HandEyeSettings",
    "InFrame",
    "InFrameEvents",
    "Pair",
    "PairCollector",
    "PoseFrame",
    "SimulatedRobot",
    "read_pairs_csv",
    "solve_handeye",
]
