"""The frame poses are reported in, and the hand-eye file that takes them there: settings declared once.

Section ``handeye`` of the run configuration (:mod:`qrfield.runconfig`): ``--frame`` and
``--handeye-file`` on ``qrfield run`` and ``qrfield session new``. docs/handeye.md.
"""

from __future__ import annotations

from dataclasses import dataclass

from qrfield.handeye.setups import CAMERA, FRAMES
from qrfield.handeye.store import FILE_NAME
from qrfield.settings import setting


@dataclass(frozen=True)
class HandEyeSettings:
    """Which frame poses are reported in (camera, tool or base) and the calibration that gets them there."""

    frame: str = setting(
        CAMERA,
        label="pose frame",
        choices=FRAMES,
        help="camera: as measured; tool: the gripper's tool frame (an eye-in-hand calibration); base: "
        "the robot's base frame (an eye-to-hand calibration)",
    )
    handeye_file: str = setting(
        "",
        label="hand-eye file",
        help=f"the calibration of `qrfield handeye` for --frame tool or base (empty: {FILE_NAME} in the "
        "config folder)",
    )
