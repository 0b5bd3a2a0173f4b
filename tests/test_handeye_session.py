"""Sessions in the tool frame: ``session new --frame tool`` records the frame and the calibration in
session.json; ``session log`` writes the rows' measured pose and the bench's truth in that frame
(carried by hand through the calibration here); ``session show`` says which frame."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from qrfield.cli import main
from qrfield.geometry import angles_from_rotation, rotation_matrix
from qrfield.handeye import HandEyeCalibration
from qrfield.handeye.rigid import transform_from_pose
from qrfield.sessions import Session

pytestmark = pytest.mark.timeout(120)
X = transform_from_pose([60.0, -15.0, 40.0], [2.0, -3.0, 90.0])


def test_a_session_in_the_tool_frame(tmp_path: Path, capsys) -> None:
    cfg = tmp_path / "cfg"
    cfg.mkdir()
    HandEyeCalibration("eye-in-hand", X, 0.1, 0.02, 15, "test").save(cfg / "handeye.json")
    assert main(["session", "new", str(tmp_path / "root"), "--name", "tool", "--config-dir", str(cfg),
                 "--frame", "tool", "--side-mm", "50", "--method", "ippe"]) == 0  # fmt: skip
    out = capsys.readouterr()
    assert "rows and their ground truth in the tool frame" in out.err
    folder = Path(out.out.strip())
    meta = json.loads((folder / "session.json").read_text())
    assert meta["pose_frame"] == "tool" and meta["handeye"]["setup"] == "eye-in-hand"
    np.testing.assert_allclose(meta["handeye"]["camera_to_tool"], X, atol=1e-12)
    # The calibration travels with the session: a later handeye.json does not change its rows.
    (cfg / "handeye.json").unlink()
    assert main(["session", "log", str(folder), "--source", "virtual", "--config-dir", str(cfg),
                 "--truth", "virtual", "--combo", "alpha", "--frames", "3"]) == 0  # fmt: skip
    assert capsys.readouterr().out.startswith("logged row 1: pass")
    with open(folder / "rows.csv", newline="", encoding="utf-8") as f:
        (row,) = list(csv.DictReader(f))
    # The bench's default pose (10, -5, 300 mm; 15, -20, 10 deg) carried into the tool frame by hand.
    p = X[:3, :3] @ [10.0, -5.0, 300.0] + X[:3, 3]
    a = angles_from_rotation(X[:3, :3] @ rotation_matrix([15.0, -20.0, 10.0]))
    np.testing.assert_allclose([float(row[f"gt_{k}"]) for k in "xyz"], p, atol=2e-3)
    np.testing.assert_allclose([float(row[f"gt_{k}"]) for k in ("alpha", "beta", "gamma")], a, atol=2e-3)
    assert np.linalg.norm(np.array([float(row[k]) for k in "xyz"]) - p) < 1.0
    assert main(["session", "show", str(folder)]) == 0
    assert (
        "poses in the tool frame (poses in the tool frame through the eye-in-hand" in capsys.readouterr().out
    )


def test_an_older_session_is_in_the_camera_frame_and_a_mismatch_is_refused(tmp_path: Path) -> None:
    from qrfield.camera import resolve_camera
    from qrfield.sessions import SessionError

    session = Session.create(
        tmp_path, "old", camera=resolve_camera("picam-v2@640x480"), side_mm=50.0, solver="ippe"
    )
    session.close()
    data = json.loads((session.path / "session.json").read_text())
    assert data["pose_frame"] == "camera" and "handeye" not in data
    del data["pose_frame"]  # written before hand-eye existed
    (session.path / "session.json").write_text(json.dumps(data))
    reopened = Session.open(session.path)
    assert reopened.info.pose_frame == "camera"
    reopened.close()
    with pytest.raises(SessionError, match="goes with the tool or base frame only"):
        Session.create(
            tmp_path,
            "bad",
            camera=resolve_camera("picam-v2@640x480"),
            side_mm=50.0,
            solver="ippe",
            pose_frame="tool",
        )


def test_a_session_through_a_simulated_calibration_is_not_logged_from_a_camera(
    tmp_path: Path, capsys
) -> None:
    from qrfield.camera import resolve_camera

    simulated = HandEyeCalibration("eye-in-hand", X, 0.1, 0.02, 15, "test", extra={"simulated": True})
    session = Session.create(tmp_path, "sim", camera=resolve_camera("picam-v2@640x480"), side_mm=50.0,
                             solver="ippe", pose_frame="tool", handeye=simulated.to_dict())  # fmt: skip
    session.close()
    args = ["session", "log", str(session.path), "--config-dir", str(tmp_path / "cfg"), "--truth", "virtual"]
    assert main([*args, "--source", "usb:7", "--combo", "alpha", "--frames", "1"]) == 2
    assert "made from simulated frames" in capsys.readouterr().err
    assert (session.path / "rows.csv").read_text().count("\n") == 1  # nothing logged
    assert main([*args, "--source", "virtual", "--combo", "alpha", "--frames", "1"]) == 0  # the bench may
