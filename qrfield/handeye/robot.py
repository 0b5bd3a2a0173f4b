"""A simulated robot: a camera and a code at known places, and what the camera sees at a tool pose.

The twin of a real arm for tests and demos (docs/handeye.md): it knows the true hand-eye transform
X and the code's place Y, and gives for any tool pose T_base_tool the code's true pose in the
camera, C = X^-1 M Y (the model of :mod:`qrfield.handeye.solve`: M = T_base_tool^-1 eye-in-hand,
T_base_tool eye-to-hand), and back: the tool pose at which the camera sees the code at a chosen
pose. :meth:`SimulatedRobot.move` drives the virtual bench (:class:`qrfield.sources.VirtualBenchSource`)
to the view of a tool pose, so the frame loop measures it as it would a real camera's.
Transforms are (4, 4) row-major, mm (:mod:`qrfield.handeye.rigid`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, rotation_matrix
from qrfield.handeye.rigid import (
    check_transform,
    invert,
    make_transform,
    pose_from_transform,
    transform_from_pose,
)
from qrfield.handeye.setups import EYE_IN_HAND, check_setup


@dataclass(frozen=True)
class SimulatedRobot:
    """A robot cell with a known hand-eye transform.

    Attributes:
        setup: "eye-in-hand" or "eye-to-hand".
        transform: (4, 4) the true X: camera_to_tool (eye-in-hand) or camera_to_base (eye-to-hand).
        code: (4, 4) the true Y: the code in the base frame (eye-in-hand: fixed in the cell) or in
            the tool frame (eye-to-hand: held by the gripper).
    """

    setup: str
    transform: np.ndarray
    code: np.ndarray

    def __post_init__(self) -> None:
        check_setup(self.setup)
        object.__setattr__(self, "transform", check_transform(self.transform, "transform"))
        object.__setattr__(self, "code", check_transform(self.code, "code"))

    def code_in_camera(self, tool_in_base: np.ndarray) -> np.ndarray:
        """(..., 4, 4) T_camera_marker at tool poses T_base_tool (..., 4, 4)."""
        tool = np.asarray(tool_in_base, dtype=float)
        m = invert(tool) if self.setup == EYE_IN_HAND else tool
        return invert(self.transform) @ m @ self.code

    def code_pose(self, tool_in_base: np.ndarray) -> Pose:
        """The code's true pose (mm, degrees; docs/conventions.md) at one tool pose."""
        position, angles = pose_from_transform(self.code_in_camera(tool_in_base))
        return Pose(position, angles)

    def tool_for_view(self, code_in_camera: np.ndarray) -> np.ndarray:
        """(..., 4, 4) the tool pose at which the camera sees the code at T_camera_marker (..., 4, 4)."""
        c = np.asarray(code_in_camera, dtype=float)
        if self.setup == EYE_IN_HAND:  # C = X^-1 T^-1 Y  ->  T = Y C^-1 X^-1
            return self.code @ invert(c) @ invert(self.transform)
        return self.transform @ c @ invert(self.code)  # C = X^-1 T Y  ->  T = X C Y^-1

    def viewing_tool_poses(
        self,
        camera: CameraModel,
        side_mm: float,
        count: int,
        *,
        seed: int = 0,
        z_range_mm: tuple[float, float] = (250.0, 380.0),
        max_tilt_deg: float = 32.0,
        max_turn_deg: float = 90.0,
    ) -> np.ndarray:
        """(count, 4, 4) seeded tool poses at which the code is in view: at z in ``z_range_mm``, its
        normal within ``max_tilt_deg`` of the line of sight, turned about its normal by up to
        ``max_turn_deg`` (:func:`qrfield.sampling.random_visible_poses`)."""
        from qrfield.sampling import random_visible_poses
        from qrfield.visibility import view_of

        rng = np.random.default_rng([seed, 17])
        views: list[np.ndarray] = []
        for batch in range(100):
            poses = random_visible_poses(
                camera,
                side_mm,
                2 * count,
                seed=seed + 7919 * batch,
                z_range_mm=z_range_mm,
                max_tilt_deg=max_tilt_deg,
                tilt_from="line_of_sight",
            )
            for pose in poses:
                # random_visible_poses turns the code about its normal over the whole turn; a
                # robot's wrist need not: the turn is drawn again, the normal kept, the view checked.
                rotation = _with_normal_turn(pose.rotation, rng.uniform(-max_turn_deg, max_turn_deg))
                if view_of(camera, side_mm, rotation, pose.position_mm, margin_px=8.0).in_view:
                    views.append(make_transform(rotation, pose.position_mm))
                if len(views) == count:
                    return self.tool_for_view(np.array(views))
        raise ValueError(f"could not place {count} views of a {side_mm:g} mm code in view of {camera.name}")

    def move(self, tool_in_base: np.ndarray, bench: Any) -> Pose:
        """Put the virtual bench's card where the camera sees the code at ``tool_in_base``; returns
        that true pose. ``bench``: a VirtualBenchSource (its settings are replaced, thread-safe)."""
        pose = self.code_pose(tool_in_base)
        bench.set_settings(bench.settings.with_pose(pose))
        return pose

    @classmethod
    def example(cls, setup: str) -> SimulatedRobot:
        """A plausible cell: eye-in-hand, a camera 60 mm beside the flange and 40 mm down its axis,
        looking along the tool's Z, and a code on the table 450 mm in front of the base; eye-to-hand,
        a camera 900 mm above the table looking down, and the code 80 mm out of the gripper."""
        check_setup(setup)
        if setup == EYE_IN_HAND:
            x = transform_from_pose([60.0, -15.0, 40.0], [2.0, -3.0, 90.0])
            y = transform_from_pose([450.0, 30.0, 0.0], [180.0, 0.0, 0.0])
        else:
            x = transform_from_pose([420.0, 20.0, 900.0], [180.0, 0.0, 90.0])
            y = transform_from_pose([0.0, 10.0, 80.0], [0.0, 0.0, 30.0])
        return cls(setup, x, y)


def _with_normal_turn(rotation: np.ndarray, turn_deg: float) -> np.ndarray:
    """A rotation with the card's normal (third column) of ``rotation`` and the turn ``turn_deg``
    about it: the shortest rotation taking +Z to the normal (the sampler's own), after Rz(turn)."""
    from qrfield.sampling import _align_z

    return _align_z(rotation[:, 2]) @ rotation_matrix([0.0, 0.0, turn_deg])
