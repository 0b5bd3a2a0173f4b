"""Poses in the tool or base frame (qrfield.handeye.frames): hand values, the covariance carried
checked by Monte Carlo, the frame a calibration fits, and a FrameResult through InFrame."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from qrfield.geometry import Pose, angle_difference, angles_from_rotation, rotation_matrix
from qrfield.handeye import (
    HandEyeCalibration,
    HandEyeError,
    HandEyeSettings,
    InFrame,
    InFrameEvents,
    PoseFrame,
)
from qrfield.handeye.frames import frame_of, transform_pose
from qrfield.handeye.rigid import rotation_exp
from qrfield.pipeline import OK, FrameResult
from qrfield.seams import BaseSink, LoopEvents, LoopEventsBase
from qrfield.seams import Sink as SinkProtocol
from qrfield.solvers import solve
from qrfield.solvers.uncertainty import isotropic_cov


def rigid(r, t):
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = r, t
    return out


def calibration(setup="eye-in-hand", transform=None, cov=None):
    x = (
        transform
        if transform is not None
        else rigid(rotation_matrix([10.0, -20.0, 75.0]), [40.0, -15.0, 60.0])
    )
    return HandEyeCalibration(setup, x, 0.1, 0.05, 15, "test", cov)


def test_a_quarter_turn_about_z_by_hand():
    # Camera x -> tool y, camera y -> tool -x; plus 10 mm along tool z.
    x = rigid(rotation_matrix([0.0, 0.0, 90.0]), [0.0, 0.0, 10.0])
    cov = np.diag([1.0, 4.0, 9.0, 0.01, 0.04, 0.09])
    position, angles, out = transform_pose([5.0, 7.0, 300.0], [0.0, 0.0, 0.0], cov, x)
    np.testing.assert_allclose(position, [-7.0, 5.0, 310.0], atol=1e-12)
    np.testing.assert_allclose(angles, [0.0, 0.0, 90.0], atol=1e-12)
    np.testing.assert_allclose(np.diag(out)[:3], [4.0, 1.0, 9.0], atol=1e-9)
    # The code's tilts about camera x and y become tilts about tool y and x: alpha <-> beta.
    np.testing.assert_allclose(np.diag(out)[3:], [0.04, 0.01, 0.09], atol=1e-6)


def test_the_carried_covariance_matches_monte_carlo():
    rng = np.random.default_rng(1)
    position, angles = np.array([20.0, -10.0, 320.0]), np.array([25.0, -15.0, 140.0])
    a = rng.normal(size=(6, 6))
    d = np.diag([0.02, 0.02, 0.1, 0.05, 0.05, 0.03])
    cov = d @ (a @ a.T + 6 * np.eye(6)) @ d / 8
    x = calibration().transform
    b = rng.normal(size=(6, 6))
    e = np.diag([0.3, 0.3, 0.3, 0.1, 0.1, 0.1])
    x_cov = e @ (b @ b.T + 6 * np.eye(6)) @ e / 8
    _, mean_angles, stated = transform_pose(position, angles, cov, x, x_cov)
    count = 20000
    n = rng.normal(size=(count, 6)) @ np.linalg.cholesky(cov).T
    d = rng.normal(size=(count, 6)) @ np.linalg.cholesky(x_cov).T
    xr = rotation_exp(np.radians(d[:, 3:])) @ x[:3, :3]
    r = xr @ rotation_matrix(angles + n[:, 3:])
    p = np.einsum("nij,nj->ni", xr, position + n[:, :3]) + x[:3, 3] + d[:, :3]
    draws = np.concatenate([p, angle_difference(angles_from_rotation(r), mean_angles)], axis=1)
    empirical = np.cov(draws.T)
    np.testing.assert_allclose(np.sqrt(np.diag(stated)), np.sqrt(np.diag(empirical)), rtol=0.04)
    corr = stated / np.sqrt(np.outer(np.diag(stated), np.diag(stated)))
    corr_mc = empirical / np.sqrt(np.outer(np.diag(empirical), np.diag(empirical)))
    assert np.abs(corr - corr_mc).max() < 0.05


def test_a_frame_needs_a_calibration_of_the_set_up_that_maps_into_it():
    with pytest.raises(HandEyeError, match="frame tool needs a hand-eye calibration"):
        PoseFrame("tool")
    with pytest.raises(HandEyeError, match=r"frame base needs an eye-to-hand calibration.*--frame tool"):
        PoseFrame("base", calibration("eye-in-hand"))
    with pytest.raises(HandEyeError, match="frame 'gripper' is not one of camera, tool, base"):
        PoseFrame("gripper")
    assert PoseFrame("camera", calibration()).identity  # the camera frame ignores a calibration


def test_from_settings_reads_the_config_folders_file_by_default(tmp_path):
    calibration("eye-to-hand").save(tmp_path / "handeye.json")
    frame = PoseFrame.from_settings(HandEyeSettings(frame="base"), tmp_path)
    assert frame.frame == "base" and "eye-to-hand" in frame.describe()
    with pytest.raises(HandEyeError, match=r"x\.json"):
        PoseFrame.from_settings(HandEyeSettings(frame="base", handeye_file=str(tmp_path / "x.json")))
    assert PoseFrame.from_settings(HandEyeSettings(), tmp_path / "nowhere").identity


def _frame_result(camera):
    truth = Pose([15.0, -8.0, 300.0], [12.0, -18.0, 40.0])
    corners = truth.corners_px(camera, 50.0)
    pose = solve(corners, camera, 50.0, "ippe", corners_cov=isotropic_cov(0.05))
    return FrameResult(3, 100, OK, poses={"ippe": pose}, truth=truth), truth


def test_a_frame_result_in_the_tool_frame_keeps_the_original_untouched(camera_vga):
    result, truth = _frame_result(camera_vga)
    cal = calibration(cov=np.diag([0.2, 0.2, 0.2, 0.05, 0.05, 0.05]) ** 2)
    moved = PoseFrame("tool", cal).frame_result(result)
    x = cal.transform
    np.testing.assert_allclose(moved.truth.position_mm, x[:3, :3] @ truth.position_mm + x[:3, 3], atol=1e-9)
    np.testing.assert_allclose(moved.truth.rotation, x[:3, :3] @ truth.rotation, atol=1e-9)
    pose = moved.poses["ippe"]
    np.testing.assert_allclose(pose.position_mm, x[:3, :3] @ result.primary.position_mm + x[:3, 3], atol=1e-9)
    np.testing.assert_allclose(
        pose.vertices_mm, result.primary.vertices_mm @ x[:3, :3].T + x[:3, 3], atol=1e-9
    )
    # The calibration's 0.2 mm and 0.05 deg (at 300 mm: 0.26 mm) are added to the pose's own.
    assert np.all(pose.position_std_mm > 0.2) and np.all(pose.angles_std_deg > 0.05)
    assert frame_of(moved) == "tool" and frame_of(result) == "camera"
    np.testing.assert_allclose(result.truth.position_mm, truth.position_mm)  # the original as it was
    assert moved.to_json_dict(True)["position_mm"] == pytest.approx(list(pose.position_mm))


def test_in_frame_hands_every_call_on_with_the_result_moved(camera_vga):
    result, _ = _frame_result(camera_vga)
    seen = []

    class Sink(BaseSink):
        def on_result(self, r, simulated):
            seen.append(("on_result", frame_of(r), simulated))

        def on_source_down(self, reason):
            seen.append(("down", reason))

    class Events(LoopEventsBase):
        def processed(self, frame, r, behind):
            seen.append(("processed", frame_of(r), behind))

        def note(self, message):
            seen.append(("note", message))

    frame = PoseFrame("tool", calibration())
    sink, events = InFrame(Sink(), frame), InFrameEvents(Events(), frame)
    assert isinstance(sink, SinkProtocol) and isinstance(events, LoopEvents)
    sink.on_result(result, True)
    sink.on_source_down("gone")
    events.processed(None, result, 2)
    events.note("hello")
    assert seen == [
        ("on_result", "tool", True),
        ("down", "gone"),
        ("processed", "tool", 2),
        ("note", "hello"),
    ]
    assert frame_of(result) == "camera" and math.isfinite(result.primary.position_mm[0])


def test_a_pose_whose_covariance_is_unknown_has_no_std_in_the_tool_frame(camera_vga):
    """audit-serial: a pose with its covariance unknown in part (NaN, as at beta = +-90 degrees)
    but a position std known in camera axes (0.1, 0.1, 2.0 mm: z is along the line of sight).
    Through a quarter turn about z plus the calibration's own uncertainty, its tool-frame std is
    not known: the camera axes' std must not be handed on as the tool axes' (it went out over
    serial as the sigma of tool x, y, z: 2.0 mm on the wrong axis when the turn is about x).
    Each std field is NaN (an empty sigma field on the wire)."""
    result, _ = _frame_result(camera_vga)
    pose = result.primary
    cov = np.full((6, 6), np.nan)
    cov[:3, :3] = np.diag([0.01, 0.01, 4.0])
    pose = dataclasses.replace(
        pose, pose_cov=cov, position_std_mm=np.array([0.1, 0.1, 2.0]), angles_std_deg=np.full(3, np.nan)
    )
    cal = calibration(transform=rigid(rotation_matrix([90.0, 0.0, 0.0]), [0.0, 0.0, 10.0]))
    moved = PoseFrame("tool", cal).pose_result(pose)
    assert np.all(np.isnan(moved.position_std_mm)) and np.all(np.isnan(moved.angles_std_deg))
