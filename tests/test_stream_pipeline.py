"""The stream stage in the pipeline and on the command line: a single image comes out exactly as the
solvers made it; a still card's frames are filtered with ``--filter-s``; JSON lines say what was done."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from qrfield.geometry import Pose, marker_vertices
from qrfield.methods import METHODS
from qrfield.pipeline import Pipeline
from qrfield.render import render_view
from qrfield.sources import Frame
from qrfield.stream import StreamSettings

REPO = Path(__file__).resolve().parent.parent
SIDE = 50.0
POSE = Pose([15.0, -10.0, 420.0], [10.0, -14.0, 30.0])


def _views(camera, count: int, pose: Pose = POSE) -> list[np.ndarray]:
    return [render_view(camera, SIDE, pose, noise_sigma=2.0, blur_px=0.6, seed=i).image for i in range(count)]


def _comparable(line: dict) -> dict:
    """A JSON line without what differs between runs of the same frame (time)."""
    return {k: v for k, v in line.items() if k not in ("latency_ms",)}


@pytest.mark.parametrize(
    "stream",
    [StreamSettings(), StreamSettings(filter_s=0.2), StreamSettings(continuity=False, filter_s=1.5)],
    ids=["defaults", "filter 0.2 s", "no continuity, filter 1.5 s"],
)
def test_a_single_image_is_reported_exactly_as_the_solvers_made_it(camera_vga, stream) -> None:
    """One frame has no history and nothing to filter: every setting gives the pipeline without a
    stream stage's answer (continuity off, no filter), and each pose is the solve of the detection."""
    from qrfield.solvers import solve_methods

    image = _views(camera_vga, 1)[0]
    alone = Pipeline(camera_vga, SIDE, METHODS, stream=StreamSettings(continuity=False)).process(
        Frame(image, 5.0, 0)
    )
    result = Pipeline(camera_vga, SIDE, METHODS, stream=stream).process(Frame(image, 5.0, 0))
    assert _comparable(result.to_json_dict()) == _comparable(alone.to_json_dict())
    direct = solve_methods(
        result.detection.corners_px, camera_vga, SIDE, METHODS, {}, result.detection.pose_cov
    )
    for name in METHODS:
        assert result.poses[name] is result.frame_poses[name]
        assert np.array_equal(result.poses[name].position_mm, direct[name].position_mm)
        assert np.array_equal(result.poses[name].angles_std_deg, direct[name].angles_std_deg)
        assert result.poses[name].ambiguous == direct[name].ambiguous
    line = result.to_json_dict()
    assert line["resolved_by"] == "frame" and line["filtered"] is False
    assert all(m["resolved_by"] == "frame" and m["filtered"] is False for m in line["methods"].values())


def test_a_frame_without_a_pose_says_nothing_was_resolved(camera_vga) -> None:
    result = Pipeline(camera_vga, SIDE, METHODS).process(Frame(np.full((480, 640), 128, np.uint8), 1.0, 0))
    line = result.to_json_dict()
    assert line["status"] == "NOQR" and line["resolved_by"] is None and line["filtered"] is False


def test_a_still_card_is_filtered_steadier_and_each_filtered_pose_is_consistent(camera_vga) -> None:
    images = _views(camera_vga, 24)
    raw = Pipeline(camera_vga, SIDE, ("ippe",), stream=StreamSettings())
    filtered = Pipeline(camera_vga, SIDE, ("ippe",), stream=StreamSettings(filter_s=0.3))
    plain, smooth = [], []
    for i, image in enumerate(images):
        frame = Frame(image, 10.0 + i / 30.0, i)
        plain.append(raw.process(frame))
        smooth.append(filtered.process(frame))
    assert [r.filtered for r in smooth] == [False] + [True] * (len(images) - 1)
    assert not any(r.filtered for r in plain)
    spread = lambda results: np.std([r.poses["ippe"].angles_deg for r in results[8:]], axis=0)  # noqa: E731
    assert np.all(spread(smooth) < 0.7 * spread(plain))
    for result in smooth[1:]:
        pose = result.poses["ippe"]
        # Its own reprojection (the rigid square at the filtered pose, by cv2) and angles.
        rvec = cv2.Rodrigues(pose.rotation)[0]
        projected, _ = cv2.projectPoints(
            marker_vertices(SIDE), rvec, pose.position_mm, camera_vga.K, camera_vga.dist
        )
        rms = float(
            np.sqrt(np.mean(np.sum((projected.reshape(4, 2) - result.detection.corners_px) ** 2, axis=1)))
        )
        assert pose.reprojection_px == pytest.approx(rms, rel=1e-6)
        assert np.allclose(Pose(pose.position_mm, pose.angles_deg).rotation, pose.rotation, atol=1e-9)
        line = result.to_json_dict()
        assert line["filtered"] is True and line["resolved_by"] == "frame"


def _qrfield(*args: str, tmp_path: Path) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": str(REPO), "QRFIELD_CONFIG_DIR": str(tmp_path), "PATH": "/usr/bin:/bin"}
    return subprocess.run(
        [sys.executable, "-m", "qrfield", *args], capture_output=True, text=True, timeout=120, env=env
    )


@pytest.mark.slow
def test_filter_s_on_the_command_line_and_in_app_json(tmp_path: Path) -> None:
    bench = [
        "run",
        "--headless",
        "--source",
        "virtual",
        "--virtual-fps",
        "30",
        "--frames",
        "6",
        "--json-lines",
    ]
    done = _qrfield(*bench, "--filter-s", "0.2", tmp_path=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    # The first frame starts the filter; the others are filtered (the gate may restart it once at
    # the step between the first, full detection and the tracked frames after it).
    assert len(lines) == 6 and not lines[0]["filtered"] and sum(line["filtered"] for line in lines) >= 4
    assert all(line["resolved_by"] == "frame" for line in lines)
    (tmp_path / "app.json").write_text(json.dumps({"stream": {"filter_s": 0.2}}), encoding="utf-8")
    from_file = [json.loads(line) for line in _qrfield(*bench, tmp_path=tmp_path).stdout.splitlines()]
    assert not from_file[0]["filtered"] and sum(line["filtered"] for line in from_file) >= 4
    off = [
        json.loads(line)
        for line in _qrfield(*bench, "--filter-s", "0", tmp_path=tmp_path).stdout.splitlines()
    ]
    assert not any(line["filtered"] for line in off)
    bad = _qrfield(*bench, "--filter-s", "-1", tmp_path=tmp_path)
    assert bad.returncode != 0 and "filter_s" in bad.stderr and "Traceback" not in bad.stderr


@pytest.mark.slow
def test_the_stream_benchmark_runs_and_prints_every_mode(tmp_path: Path) -> None:
    args = [
        "benchmark",
        "stream",
        "--seeds",
        "1",
        "--frames",
        "4",
        "--only",
        "still 450 mm",
        "--sections",
        "1,2",
    ]
    done = _qrfield(*args, "--still-views", "1", "--still-frames", "3", tmp_path=tmp_path)
    assert done.returncode == 0, done.stderr
    for mode in ("single frame", "continuity", "filter 0.2 s", "filter 0.5 s"):
        assert mode in done.stdout
    assert "seeds [1] were used for tuning" in done.stdout and "RMS (mean - truth) / sem" in done.stdout
    # why frames miss the criteria, per method and mode, and the single frames' tilt precision
    for method in ("num", "ipp"):
        assert f"{method} continuity" in done.stdout.split("why frames miss 2 deg / 5 mm")[1]
        assert f"{method} single frames' tilt (alpha, beta): RMS error" in done.stdout
