"""Poses in the frame the user chose: the camera's, or the tool's / base's through a hand-eye file.

docs/conventions.md ("Hand-eye"): with a calibration X (camera_to_tool or camera_to_base), the
code's pose in the camera frame (p, R) becomes (X_R p + X_t, X_R R) in the tool or base frame; its
angles are again alpha, beta, gamma with R = Rx Ry Rz (now of R' = X_R R), its position the code's
centre in that frame, mm. The covariance of (x, y, z, alpha, beta, gamma) is carried by the
Jacobian of that map (central differences for the angles), and the calibration's own covariance
(of its (dt mm, dtheta deg), :mod:`qrfield.handeye.store`) is added through its Jacobian, so the
std fields of a pose in the tool frame include the calibration's uncertainty.

:class:`PoseFrame` does that for a :class:`~qrfield.solvers.PoseResult`, a true
:class:`~qrfield.geometry.Pose` and a whole :class:`~qrfield.pipeline.FrameResult`;
:class:`InFrame` puts it in front of a frame-loop sink (``on_result``) and :class:`InFrameEvents`
in front of an events handler (``processed``), so the frame loop and the pipeline are untouched: the
step sits where a result is handed on (``qrfield run``'s stdout, a session's recorder).
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.geometry import Pose, angle_difference, angles_from_rotation, rotation_matrix
from qrfield.handeye.rigid import rotation_exp, skew
from qrfield.handeye.setups import CAMERA, FRAMES, HandEyeError, setup_for_frame
from qrfield.handeye.store import FILE_NAME, HandEyeCalibration
from qrfield.seams import BaseSink, LoopEvents, LoopEventsBase, Sink

#: Central-difference step for the angles' Jacobian, degrees.
_STEP_DEG = 1e-5


def transform_pose(
    position_mm: np.ndarray,
    angles_deg: np.ndarray,
    cov: np.ndarray | None,
    transform: np.ndarray,
    transform_cov: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """One pose (position (3,) mm, angles (3,) deg, covariance (6, 6) of both or None) mapped by the
    rigid ``transform`` (4, 4) with covariance ``transform_cov`` (6, 6) of its (dt mm, dtheta deg)
    or None; returns the new position, angles and covariance (None when ``cov`` is None or NaN)."""
    position = np.asarray(position_mm, dtype=float).reshape(3)
    angles = np.asarray(angles_deg, dtype=float).reshape(3)
    r_x, t_x = transform[:3, :3], transform[:3, 3]
    rotation = r_x @ rotation_matrix(angles)
    new_position = r_x @ position + t_x
    new_angles = angles_from_rotation(rotation)
    if cov is None or not np.all(np.isfinite(cov)):
        return new_position, new_angles, None
    # d(new angles)/d(angles): central differences through the rotation.
    steps = np.eye(3) * _STEP_DEG
    plus = angles_from_rotation(r_x @ rotation_matrix(angles + steps))
    minus = angles_from_rotation(r_x @ rotation_matrix(angles - steps))
    j_pose = np.zeros((6, 6))
    j_pose[:3, :3] = r_x
    j_pose[3:, 3:] = (angle_difference(plus, minus) / (2 * _STEP_DEG)).T
    out = j_pose @ cov @ j_pose.T
    if transform_cov is not None:
        # d/d(dt, dtheta) of exp(dtheta) (X_R p + X_t) + dt and of the angles of exp(dtheta) R'.
        rad = math.radians(_STEP_DEG)
        turned_plus = angles_from_rotation(rotation_exp(np.eye(3) * rad) @ rotation)
        turned_minus = angles_from_rotation(rotation_exp(-np.eye(3) * rad) @ rotation)
        j_x = np.zeros((6, 6))
        j_x[:3, :3] = np.eye(3)
        j_x[:3, 3:] = -skew(r_x @ position) * (math.pi / 180.0)
        j_x[3:, 3:] = (angle_difference(turned_plus, turned_minus) / (2 * _STEP_DEG)).T
        out = out + j_x @ transform_cov @ j_x.T
    return new_position, new_angles, 0.5 * (out + out.T)


class PoseFrame:
    """The frame poses are reported in: "camera" (as measured), or "tool" / "base" through a
    calibration whose set-up maps into that frame (eye-in-hand: tool; eye-to-hand: base)."""

    def __init__(self, frame: str = CAMERA, calibration: HandEyeCalibration | None = None) -> None:
        if frame not in FRAMES:
            raise HandEyeError(f"frame {frame!r} is not one of {', '.join(FRAMES)}")
        if frame != CAMERA:
            where = f" {calibration.path}" if calibration is not None and calibration.path else ""
            if calibration is None:
                raise HandEyeError(f"frame {frame} needs a hand-eye calibration ({setup_for_frame(frame)})")
            if calibration.target_frame != frame:
                raise HandEyeError(
                    f"frame {frame} needs an {setup_for_frame(frame)} calibration; the hand-eye file{where} "
                    f"is {calibration.setup} (it gives poses in the {calibration.target_frame} frame: "
                    f"--frame {calibration.target_frame})"
                )
        self.frame = frame
        self.calibration = calibration if frame != CAMERA else None

    @classmethod
    def from_settings(cls, settings: Any, config_dir: str | os.PathLike[str] | None = None) -> PoseFrame:
        """From :class:`~qrfield.handeye.settings.HandEyeSettings`: the file named there, else
        ``handeye.json`` in the config folder (read only when the frame is not camera)."""
        if settings.frame == CAMERA:
            return cls()
        return cls(settings.frame, HandEyeCalibration.load(calibration_path(settings, config_dir)))

    @classmethod
    def from_saved(cls, frame: str, calibration: dict[str, Any], session: str) -> PoseFrame:
        """The PoseFrame a session recorded (session.json's ``pose_frame`` and ``handeye``: the
        hand-eye file's contents at ``session new``); HandEyeError naming the session if unusable."""
        if not calibration:
            return cls(frame)
        return cls(frame, HandEyeCalibration.from_dict(calibration, f"session {session}: field 'handeye'"))

    def check_source(self, live: bool) -> None:
        """HandEyeError (one line) when poses of a live camera (``live``) would go through a
        calibration made from simulated frames (the file's ``simulated`` field): its numbers are
        those of a made-up cell."""
        c = self.calibration
        if live and c is not None and c.simulated:
            where = f" {c.path}" if c.path else ""
            raise HandEyeError(
                f"the hand-eye file{where} was made from simulated frames (the virtual bench, a video or "
                "a folder): not for a live camera; calibrate with the camera (qrfield handeye, or "
                "$QRC,TOOL and $QRC,HANDEYE over serial)"
            )

    @property
    def identity(self) -> bool:
        """Poses stay in the camera frame (nothing to do)."""
        return self.calibration is None

    def describe(self) -> str:
        """One line for the user: the frame, and the calibration it comes from."""
        if self.calibration is None:
            return "poses in the camera frame"
        c = self.calibration
        where = f" of {c.path}" if c.path else ""
        return (
            f"poses in the {self.frame} frame through the {c.setup} calibration{where} ({c.n_pairs} pairs, "
            f"residuals {c.residual_mm:.2f} mm, {c.residual_deg:.3f} deg)"
        )

    def pose_result(self, result: Any) -> Any:
        """A PoseResult (and its mirror candidate) in this frame: position, angles, rotation,
        vertices, and the std fields and pose_cov with the calibration's uncertainty added (all NaN
        when the pose's covariance is not known in full: its std is the camera axes')."""
        if self.calibration is None or result is None:
            return result
        x, x_cov = self.calibration.transform, self.calibration.covariance
        if not np.all(np.isfinite(result.position_mm)):
            return result
        cov = result.pose_cov if np.all(np.isfinite(result.pose_cov)) else None
        position, angles, new_cov = transform_pose(result.position_mm, result.angles_deg, cov, x, x_cov)
        changes: dict[str, Any] = {
            "position_mm": position,
            "angles_deg": angles,
            "rotation": x[:3, :3] @ result.rotation,
            "vertices_mm": result.vertices_mm @ x[:3, :3].T + x[:3, 3],
        }
        if new_cov is not None:
            std = np.sqrt(np.diag(new_cov))
            changes.update(pose_cov=new_cov, position_std_mm=std[:3], angles_std_deg=std[3:])
        else:  # the camera axes' std is not the new axes' (audit-serial): unknown, NaN
            unknown = np.full(3, np.nan)
            changes.update(pose_cov=np.full((6, 6), np.nan), position_std_mm=unknown, angles_std_deg=unknown)
        if result.alternative is not None:
            changes["alternative"] = self.pose_result(result.alternative)
        return dataclasses.replace(result, **changes)

    def pose(self, pose: Pose | None) -> Pose | None:
        """A true pose (the virtual bench's) in this frame."""
        if self.calibration is None or pose is None:
            return pose
        position, angles, _ = transform_pose(
            pose.position_mm, pose.angles_deg, None, self.calibration.transform
        )
        return Pose(position, angles)

    def frame_result(self, result: Any) -> Any:
        """A copy of a FrameResult with every method's pose and the truth in this frame, and
        ``pose_frame`` set (the original is not changed: other sinks see the camera's)."""
        if self.calibration is None:
            return result
        out = dataclasses.replace(
            result,
            poses={name: self.pose_result(p) for name, p in result.poses.items()},
            truth=self.pose(result.truth),
        )
        out.pose_frame = self.frame
        return out


def frame_of(result: Any) -> str:
    """The frame a FrameResult's poses are in ("camera" unless a PoseFrame put them elsewhere)."""
    return getattr(result, "pose_frame", CAMERA)


def calibration_path(settings: Any, config_dir: str | os.PathLike[str] | None = None) -> Path:
    """The hand-eye file of the settings: ``handeye_file``, else ``handeye.json`` in the config folder."""
    from qrfield import paths

    name = str(getattr(settings, "handeye_file", "") or "")
    return Path(name).expanduser() if name else paths.config_dir(config_dir) / FILE_NAME


class InFrame(BaseSink):
    """A frame-loop sink whose results arrive in ``pose_frame`` (the other calls pass unchanged)."""

    def __init__(self, inner: Sink, pose_frame: PoseFrame) -> None:
        self.inner = inner
        self.pose_frame = pose_frame

    def on_result(self, result: Any, simulated: bool) -> Any:
        return self.inner.on_result(self.pose_frame.frame_result(result), simulated)

    def on_source_down(self, reason: str) -> None:
        self.inner.on_source_down(reason)

    def on_source_up(self) -> None:
        self.inner.on_source_up()


class InFrameEvents(LoopEventsBase):
    """A frame loop's events handler whose ``processed`` results arrive in ``pose_frame`` (a
    session's recorder); the other events pass unchanged."""

    def __init__(self, inner: LoopEvents, pose_frame: PoseFrame) -> None:
        self.inner = inner
        self.pose_frame = pose_frame

    def opened(self, description: str, again: bool) -> None:
        self.inner.opened(description, again)

    def failed(self, message: str, ended: bool) -> None:
        self.inner.failed(message, ended)

    def note(self, message: str) -> None:
        self.inner.note(message)

    def processed(self, frame: Any, result: Any, frames_behind: int) -> None:
        self.inner.processed(frame, self.pose_frame.frame_result(result), frames_behind)

    def source_down(self, reason: str) -> None:
        self.inner.source_down(reason)

    def source_up(self) -> None:
        self.inner.source_up()
