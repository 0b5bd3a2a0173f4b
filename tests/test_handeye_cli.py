"""``qrfield handeye PAIRS.csv``: images drawn by tests/scene_truth.py at tool poses written as
quaternions by hand; the calibration written matches the truth; bad rows are reported and left out;
bad input and degenerate pose sets are one line."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
from scene_truth import draw_card

from qrfield.cli import main
from qrfield.geometry import Pose, angles_from_rotation
from qrfield.handeye.rigid import difference, transform_from_pose

SIDE = 50.0
X = transform_from_pose([420.0, 20.0, 900.0], [178.0, 3.0, 90.0])  # camera_to_base
Y = transform_from_pose([0.0, 10.0, 80.0], [0.0, 0.0, 30.0])  # the code in the gripper


def _tool(axis, angle_deg, position):
    """A tool pose and its quaternion, by hand: q = (cos(a/2), sin(a/2) axis)."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    half = math.radians(angle_deg) / 2
    q = np.r_[math.cos(half), math.sin(half) * axis]
    t = np.eye(4)
    t[:3, :3] = cv2.Rodrigues(axis * math.radians(angle_deg))[0]
    t[:3, 3] = position
    return t, q


def _write_set(folder, camera, tools):
    folder.mkdir(exist_ok=True)
    lines = ["x,y,z,qw,qx,qy,qz,image"]
    for k, (tool, q) in enumerate(tools):
        code = (
            np.linalg.inv(X) @ tool @ Y
        )  # eye-to-hand: T_base_camera T_camera_marker = T_base_tool T_tool_marker
        pose = Pose(code[:3, 3], angles_from_rotation(code[:3, :3]))
        cv2.imwrite(str(folder / f"view{k:02d}.png"), draw_card(camera, pose, SIDE, seed=k))
        lines.append(",".join(f"{v:.6f}" for v in (*tool[:3, 3], *q)) + f",view{k:02d}.png")
    return lines


def _viewing_tools(rng, camera, count):
    """Tool poses that hold the code 250-380 mm below the camera, tilted up to ~30 deg."""
    out = []
    while len(out) < count:
        axis = rng.normal(size=3)
        angle = rng.uniform(-30, 30)
        base_turn = rng.uniform(-60, 60)
        tool, q = _tool(axis, angle, [0, 0, 0])
        turn, qt = _tool([0, 0, 1], base_turn, [0, 0, 0])
        # The gripper under the camera: tool = (turn about base z) * (tilt), placed 250-380 mm below.
        rotation = turn[:3, :3] @ tool[:3, :3]
        qw1, v1 = qt[0], qt[1:]
        qw2, v2 = q[0], q[1:]
        quat = np.r_[qw1 * qw2 - v1 @ v2, qw1 * v2 + qw2 * v1 + np.cross(v1, v2)]
        position = X[:3, 3] + X[:3, :3] @ np.r_[rng.uniform(-40, 40, 2), rng.uniform(250, 380)]
        position = position - rotation @ Y[:3, 3]  # so that the code, not the flange, sits there
        t = np.eye(4)
        t[:3, :3], t[:3, 3] = rotation, position
        code = np.linalg.inv(X) @ t @ Y
        pose = Pose(code[:3, 3], angles_from_rotation(code[:3, :3]))
        if code[2, 2] < -0.87 and np.all(np.abs(pose.corners_px(camera, SIDE) - [320, 240]) < [300, 220]):
            out.append((t, quat))
    return out


@pytest.mark.slow
def test_a_pairs_file_gives_the_calibration_and_bad_rows_are_left_out(tmp_path, camera_vga, capsys):
    rng = np.random.default_rng(28)
    lines = _write_set(tmp_path / "shots", camera_vga, _viewing_tools(rng, camera_vga, 15))
    lines.append("0,0,500,1,0,0,0,missing.png")
    cv2.imwrite(str(tmp_path / "shots" / "blank.png"), np.full((480, 640), 128, np.uint8))
    lines.append("0,0,500,1,0,0,0,blank.png")
    (tmp_path / "shots" / "pairs.csv").write_text("\n".join(lines) + "\n")
    out = tmp_path / "he.json"
    code = main(["handeye", str(tmp_path / "shots" / "pairs.csv"), "--setup", "eye-to-hand", "--camera",
                 "picam-v2@640x480", "--side-mm", "50", "--out", str(out)])  # fmt: skip
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "missing.png: left out:" in printed.out and "blank.png: left out: no QR code found" in printed.out
    assert "pairs from 17 rows" in printed.out and "camera_to_base (eye-to-hand" in printed.out
    data = json.loads(out.read_text())
    assert data["setup"] == "eye-to-hand" and data["n_pairs"] >= 12
    err = difference(np.array(data["camera_to_base"]), X)
    assert np.linalg.norm(err[:3]) < 2.0 and math.degrees(np.linalg.norm(err[3:])) < 0.3
    assert data["camera"] == "picam-v2@640x480" and data["side_mm"] == 50.0
    # Once more into the same file: the first is kept beside it.
    assert main(["handeye", str(tmp_path / "shots" / "pairs.csv"), "--setup", "eye-to-hand", "--camera",
                 "picam-v2@640x480", "--side-mm", "50", "--out", str(out)]) == 0  # fmt: skip
    assert json.loads((tmp_path / "he.json.previous").read_text())["n_pairs"] == data["n_pairs"]


@pytest.mark.slow
def test_a_degenerate_set_is_refused_in_one_line_naming_what_to_add(tmp_path, camera_vga, capsys):
    # The gripper turns only about the camera's optical axis (base z here): degenerate.
    tools = []
    for k in range(8):
        t, q = _tool([0, 0, 1], -70 + 20 * k, [0, 0, 0])
        t[:3, 3] = X[:3, 3] + X[:3, :3] @ [0, 0, 300] - t[:3, :3] @ Y[:3, 3]
        tools.append((t, q))
    lines = _write_set(tmp_path / "shots", camera_vga, tools)
    (tmp_path / "shots" / "pairs.csv").write_text("\n".join(lines) + "\n")
    code = main(["handeye", str(tmp_path / "shots" / "pairs.csv"), "--setup", "eye-to-hand", "--camera",
                 "picam-v2@640x480", "--side-mm", "50", "--out", str(tmp_path / "he.json")])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "all about one axis" in err[0] and "add poses turned" in err[0]
    assert not (tmp_path / "he.json").exists()


def test_a_bad_pairs_file_is_one_line(tmp_path, capsys):
    (tmp_path / "pairs.csv").write_text("x,y,z,qw,qx,qy,qz,image\n1,2,3,0.5,0,0,0,a.png\n")
    code = main(["handeye", str(tmp_path / "pairs.csv"), "--setup", "eye-in-hand", "--focal-px", "500",
                 "--size", "640x480", "--side-mm", "50", "--out", str(tmp_path / "he.json")])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "line 2: qw,qx,qy,qz" in err[0] and "unit quaternion" in err[0]
