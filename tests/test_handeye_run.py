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
import pytest

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


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_serial_poses_hello_and_the_hand_eye_commands_in_the_tool_frame(tmp_path):
    # `qrfield run --serial --frame tool`: $QRF carries the bench's pose through the calibration
    # (by hand), HELLO says tool, and TOOL / HANDEYE are answered (the bench is simulated: SIM).
    from serial_truth import command_line
    from test_run_serial import Controller

    x = transform_from_pose([60.0, -15.0, 40.0], [2.0, -3.0, 90.0])
    HandEyeCalibration("eye-in-hand", x, 0.1, 0.02, 15, "test").save(tmp_path / "handeye.json")
    controller = Controller()
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.update(PYTHONPATH=str(REPO), QRFIELD_CONFIG_DIR=str(tmp_path))
    args = ["run", "--source", "virtual", "--method", "ippe", "--frame", "tool", "--serial", controller.tty]
    bench = [b if b != "0" or BENCH[i - 1] != "--virtual-fps" else "10" for i, b in enumerate(BENCH)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "qrfield", *args, *bench],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        controller.wait(lambda f, a: sum(x["status"] == "SIM" for x in f) >= 3, 60, "SIM frames")
        os.write(controller.master, command_line("HELLO"))
        controller.wait(lambda f, a: len(a) >= 1, 20, "HELLO")
        q = ["1.0", "0.0", "0.0", "0.0"]
        os.write(
            controller.master, command_line("TOOL", "400.0", "10.0", "300.0", *q) + command_line("HANDEYE")
        )
        controller.wait(lambda f, a: len(a) >= 3, 30, "the TOOL and HANDEYE answers")
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=60)
        controller.close()
    frames, answers = controller.lines()
    got = [(a["command"], a["result"], *a["values"]) for a in answers]
    assert got[0][0] == "HELLO" and got[0][-1] == "tool"
    assert got[1] == ("TOOL", "OK", "1", "SIM")
    assert got[2] == ("HANDEYE", "ERR", "1 pairs: at least 5 needed")
    r = x[:3, :3] @ rotation_matrix([15.0, -20.0, 30.0])
    p = x[:3, :3] @ [20.0, -10.0, 320.0] + x[:3, 3]
    poses = [f["pose"] for f in frames if f["status"] == "SIM"]
    assert poses and all(np.linalg.norm(np.array(v[:3]) - p) < 1.0 for v in poses)
    angles = angles_from_rotation(r)
    assert all(np.abs(np.array(v[3:]) - angles).max() < 0.3 for v in poses)
    assert "in the tool frame" in err and "HANDEYE solves eye-in-hand" in err and "Traceback" not in err


@pytest.mark.slow
def test_a_set_up_that_does_not_fit_the_frame_and_a_simulated_file_for_a_camera_are_refused(tmp_path):
    x = transform_from_pose([60.0, -15.0, 40.0], [2.0, -3.0, 90.0])
    HandEyeCalibration("eye-in-hand", x, 0.1, 0.02, 15, "test").save(tmp_path / "handeye.json")
    done = qrfield("run", "--source", "virtual", "--frames", "1", "--frame", "tool", "--serial", "loop://",
                   "--allow-virtual", "--handeye-setup", "eye-to-hand", config=tmp_path)  # fmt: skip
    err = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(err) == 1, done.stderr
    assert "eye-to-hand gives poses in the base frame" in err[0] and "--handeye-setup eye-in-hand" in err[0]
    simulated = HandEyeCalibration("eye-in-hand", x, 0.1, 0.02, 15, "test", extra={"simulated": True})
    simulated.save(tmp_path / "handeye-simulated.json")
    for source in ("usb:7", "auto"):
        done = qrfield("run", "--source", source, "--frames", "1", "--frame", "tool", "--handeye-file",
                       str(tmp_path / "handeye-simulated.json"), config=tmp_path)  # fmt: skip
        err = done.stderr.strip().splitlines()  # the camera's assumed model and QR side, then the error
        assert done.returncode == 2 and "error:" in err[-1] and "Traceback" not in done.stderr, done.stderr
        assert "made from simulated frames" in err[-1] and "not for a live camera" in err[-1]
    done = qrfield("run", "--source", "virtual", "--frames", "1", "--frame", "tool", "--handeye-file",
                   str(tmp_path / "handeye-simulated.json"), config=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr  # with the virtual bench it may be used
