"""The frame poses are reported in, the hand-eye file that takes them there and the set-up a serial
calibration solves for: settings declared once.

Section ``handeye`` of the run configuration (:mod:`qrfield.runconfig`): ``--frame``,
``--handeye-file`` and ``--handeye-setup`` on ``qrfield run`` (``--frame`` and ``--handeye-file``
on ``qrfield session new`` too). docs/handeye.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from qrfield.handeye.setups import CAMERA, FRAMES, SETUPS, TARGET_FRAME, HandEyeError, setup_for_frame
from qrfield.handeye.store import FILE_NAME
from qrfield.settings import setting

#: ``handeye_setup``: the set-up follows from ``frame`` (tool: eye-in-hand, base: eye-to-hand).
AUTO_SETUP = "auto"


@dataclass(frozen=True)
class HandEyeSettings:
    """Which frame poses are reported in (camera, tool or base), the calibration that gets them
    there, and the set-up ``$QRC,HANDEYE`` solves for (it carries no argument)."""

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
        "config folder); $QRC,HANDEYE saves its calibration there",
    )
    handeye_setup: str = setting(
        AUTO_SETUP,
        label="hand-eye set-up",
        choices=(AUTO_SETUP, *SETUPS),
        help="what $QRC,HANDEYE solves for: eye-in-hand (camera on the gripper), eye-to-hand (camera "
        "fixed); auto: from the pose frame (tool: eye-in-hand, base: eye-to-hand; camera: none, "
        "HANDEYE answers an error)",
    )


def calibration_setup(settings: Any) -> str | None:
    """The set-up a serial calibration solves for: ``handeye_setup``, or for ``auto`` the one of
    ``frame`` (None for the camera frame). HandEyeError (one line) when the set-up given does not
    fit the frame (an eye-to-hand calibration cannot report poses in the tool frame)."""
    frame = str(getattr(settings, "frame", CAMERA))
    setup = str(getattr(settings, "handeye_setup", AUTO_SETUP))
    if setup == AUTO_SETUP:
        return None if frame == CAMERA else setup_for_frame(frame)
    if frame != CAMERA and TARGET_FRAME.get(setup) != frame:
        raise HandEyeError(
            f"hand-eye set-up {setup} gives poses in the {TARGET_FRAME.get(setup, '?')} frame, not the "
            f"{frame} frame: --handeye-setup {setup_for_frame(frame)} (or auto) with --frame {frame}"
        )
    return setup
