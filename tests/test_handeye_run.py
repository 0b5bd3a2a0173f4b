"""``qrfield run --frame tool|base``: JSON lines in the gripper's frame through a hand-eye file
(the virtual bench's true pose carried by hand through the calibration), ``pose_frame`` on every
line, and one clear line for a file that does not fit the frame or is missing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from qrfield.geometry import angles_from_rotation, rotation_matrix
from qrfield.handeye import HandEyeCalibration
from qrfield.handeye.rigid import transform_from_pose

REPO = Path(__file__).resolve().parent.parent
BENCH = ["--virtual-fps", "0", "--virtual-x-mm", "20", "--virtual-y-mm", "-10", "--virtual-z-mm", "320",
         "--virtual-alpha-deg", "15", "--virtual-beta-deg", "-20", "--virtual-gamma-deg", "30"]  # fmt: skip


def qrfield(*args: str, config: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.update(PYTHONPATH=str(REPO), QRFIELD_CONFIG_DIR=str(config))
    return subprocess.run(
        [sys.executable, "-m", "qrfield", *args], capture_output=True, text=True, timeout=120, env=env
    )


def test_json_lines_in_the_tool_frame_carry_the_bench_pose_through_the_calibration(tmp_path):
    x = transform_from_pose([60.0, -15.0, 40.0], [2.0, -3.0, 90.0])
    cov = np.diag([0.2, 0.2, 0.2, 0.05, 0.05, 0.05]) ** 2
    HandEyeCalibration("eye-in-hand", x, 0.1, 0.02, 15, "test", cov).save(tmp_path / "handeye.json")
    done = qrfield("run", "--source", "virtual", "--frames", "3", "--json-lines", "--method", "ippe",
                   "--frame", "tool", *BENCH, config=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "poses in the tool frame through the eye-in-hand calibration" in done.stderr
    # By hand: the code in the tool frame is X applied to the bench's pose in the camera frame.
    r = x[:3, :3] @ rotation_matrix([15.0, -20.0, 30.0])
    p = x[:3, :3] @ [20.0, -10.0, 320.0] + x[:3, 3]
    for line in map(json.loads, done.stdout.splitlines()):
        assert line["pose_frame"] == "tool"
        np.testing.assert_allclose(line["truth"]["position_mm"], p, atol=1e-6)
        np.testing.assert_allclose(line["truth"]["angles_deg"], angles_from_rotation(r), atol=1e-6)
        assert np.linalg.norm(np.array(line["position_mm"]) - p) < 1.0
        # The calibration's 0.2 mm per axis is in the reported std.
        assert all(s > 0.2 for s in line["position_std_mm"])
    plain = qrfield("run", "--source", "virtual", "--frames", "1", "--json-lines", *BENCH, config=tmp_path)
    line = json.loads(plain.stdout.splitlines()[0])
    assert line["pose_frame"] == "camera"
    np.testing.assert_allclose(line["truth"]["position_mm"], [20.0, -10.0, 320.0])


def test_a_file_that_does_not_fit_the_frame_or_is_missing_is_one_line(tmp_path):
    x = transform_from_pose([400.0, 0.0, 900.0], [180.0, 0.0, 0.0])
    HandEyeCalibration("eye-to-hand", x, 0.1, 0.02, 15, "test").save(tmp_path / "handeye.json")
    done = qrfield("run", "--source", "virtual", "--frames", "1", "--frame", "tool", config=tmp_path)
    err = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(err) == 1
    assert "frame tool needs an eye-in-hand calibration" in err[0] and "--frame base" in err[0]
    done = qrfield("run", "--source", "virtual", "--frames", "1", "--frame", "base",
                   "--handeye-file", str(tmp_path / "nothing.json"), config=tmp_path)  # fmt: skip
    err = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(err) == 1 and "nothing.json" in err[0] and "qrfield handeye" in err[0]
