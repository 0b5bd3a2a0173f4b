"""The hand-eye set-ups and the frames a pose can be reported in: names declared once.

docs/conventions.md, "Hand-eye":

- eye-in-hand: the camera rides on the gripper, the code is fixed in the cell. The calibration
  finds ``camera_to_tool`` (T_tool_camera: camera coordinates into the tool frame); poses can then
  be reported in the tool frame.
- eye-to-hand: the camera is fixed, the gripper holds the code. The calibration finds
  ``camera_to_base`` (T_base_camera); poses can then be reported in the robot's base frame.

The tool pose the robot gives is T_base_tool (the tool frame in the base frame).
"""

from __future__ import annotations


class HandEyeError(ValueError):
    """Pairs that cannot be solved, a hand-eye file that cannot be used, a frame that does not fit
    the loaded calibration: the message (one line) says what is wrong and what to do.

    ``short``: the same in at most 40 bytes without commas, for a serial answer's reason
    (``$QRA,HANDEYE,ERR,<reason>``, docs/serial.md); empty when none was given."""

    def __init__(self, message: str, short: str = "") -> None:
        super().__init__(message)
        self.short = short


EYE_IN_HAND, EYE_TO_HAND = "eye-in-hand", "eye-to-hand"
#: The set-ups, as the CLI, handeye.json and the settings spell them.
SETUPS = (EYE_IN_HAND, EYE_TO_HAND)
CAMERA, TOOL, BASE = "camera", "tool", "base"
#: The frames a pose can be reported in (the ``frame`` setting).
FRAMES = (CAMERA, TOOL, BASE)
#: The frame each set-up's calibration maps camera coordinates into.
TARGET_FRAME = {EYE_IN_HAND: TOOL, EYE_TO_HAND: BASE}
#: The key of handeye.json that holds each set-up's transform.
TRANSFORM_KEY = {EYE_IN_HAND: "camera_to_tool", EYE_TO_HAND: "camera_to_base"}


def check_setup(setup: str) -> str:
    """``setup`` if it is one of SETUPS, else HandEyeError naming them."""
    if setup not in SETUPS:
        raise HandEyeError(f"hand-eye set-up {setup!r} is not one of {', '.join(SETUPS)}", "unknown set-up")
    return setup


def setup_for_frame(frame: str) -> str:
    """The set-up whose calibration reports poses in ``frame`` (tool or base); HandEyeError otherwise."""
    for setup, target in TARGET_FRAME.items():
        if target == frame:
            return setup
    raise HandEyeError(f"frame {frame!r} needs no hand-eye calibration or is not one of {', '.join(FRAMES)}")
