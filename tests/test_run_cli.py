"""``qrfield run --headless``: one pose per frame, no Qt imported, clean stop on SIGINT/SIGTERM;
and ``qrfield`` without a display says how to run headless."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from serial_truth import parse_frame_line, split_lines

from qrfield.geometry import Pose, angle_difference
from qrfield.render import render_view

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parent.parent


def env(**extra: str) -> dict[str, str]:
    out = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    out["PYTHONPATH"] = str(REPO)
    out.update(extra)
    return out


def qrfield(*args: str, timeout: float = 60, **extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "qrfield", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env(**extra),
    )


def within_seed_criteria(position, angles, truth: Pose) -> bool:
    position_ok = np.linalg.norm(np.asarray(position) - truth.position_mm) < 5.0
    return bool(position_ok and np.all(np.abs(angle_difference(np.asarray(angles), truth.angles_deg)) <= 2.0))


def test_json_lines_on_the_virtual_bench_match_its_true_pose() -> None:
    truth = Pose([30.0, -20.0, 400.0], [-12.0, 18.0, 40.0])
    args = ["--virtual-fps", "0", "--virtual-x-mm", "30", "--virtual-y-mm", "-20", "--virtual-z-mm", "400"]
    args += ["--virtual-alpha-deg", "-12", "--virtual-beta-deg", "18", "--virtual-gamma-deg", "40"]
    done = qrfield(
        "run", "--headless", "--source", "virtual", "--frames", "4", "--json-lines", "--method", "both", *args
    )
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(lines) == 4
    keys = {"method", "position_mm", "angles_deg", "converged", "iterations", "reprojection_px", "corners"}
    for i, line in enumerate(lines):
        assert keys | {"t_ms", "status"} <= set(line)
        # A made-up pose is never reported OK (docs/conventions.md): the virtual bench's is SIM.
        assert line["status"] == "SIM" and line["simulated"] is True
        assert line["frame"] == i and isinstance(line["t_ms"], int)
        assert line["method"] == "numerical" and set(line["methods"]) == {"numerical", "ippe"}
        for result in line["methods"].values():
            assert within_seed_criteria(result["position_mm"], result["angles_deg"], truth)
    assert lines[0]["t_ms"] == 0 and [x["t_ms"] for x in lines] == sorted(x["t_ms"] for x in lines)
    assert "done after 4 frames" in done.stderr


def test_headless_run_imports_no_qt() -> None:
    code = (
        "import sys\n"
        "from qrfield.cli import main\n"
        "rc = main(['run', '--headless', '--source', 'virtual', '--frames', '2', '--virtual-fps', '0'])\n"
        "qt_roots = ('PySide6', 'shiboken6', 'pyqtgraph', 'ui')\n"
        "qt = sorted(m for m in sys.modules if m.split('.')[0] in qt_roots)\n"
        "print('QT-MODULES', qt, file=sys.stderr)\n"
        "sys.exit(rc)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env())
    assert done.returncode == 0, done.stderr
    assert "QT-MODULES []" in done.stderr
    assert len(done.stdout.splitlines()) == 2 and " SIM " in done.stdout.splitlines()[0]  # never OK


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signals_stop_the_stream_cleanly(sig: signal.Signals) -> None:
    process = subprocess.Popen(
        [sys.executable, "-m", "qrfield", "run", "--headless", "--source", "virtual", "--json-lines"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env(),
    )
    try:
        first = {}
        reader = threading.Thread(target=lambda: first.setdefault("line", process.stdout.readline()))
        reader.start()
        reader.join(60)
        assert json.loads(first["line"])["status"] == "SIM"  # it is streaming (the virtual bench)
        process.send_signal(sig)
        out, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, err
    assert f"stopped by {sig.name} after" in err and "Traceback" not in err
    for line in out.splitlines():  # every line written is whole JSON
        json.loads(line)


def test_folder_source_runs_to_its_end(tmp_path: Path, camera_vga) -> None:
    pose = Pose([0.0, 10.0, 300.0], [5.0, -15.0, 90.0])
    for i in range(3):
        cv2.imwrite(
            str(tmp_path / f"{i}.png"), render_view(camera_vga, 50.0, pose, noise_sigma=1.0, seed=i).image
        )
    (tmp_path / "3.png").write_bytes(b"broken")
    (tmp_path / "4.png").write_bytes(cv2.imencode(".png", np.full((480, 640), 128, np.uint8))[1].tobytes())
    done = qrfield(
        "run", "--source", str(tmp_path), "--json-lines", "--method", "ippe", "--camera", "picam-v2@640x480"
    )
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    # A folder of images is a recording, not a live camera: its poses are SIM, never OK.
    assert [line["status"] for line in lines] == ["SIM", "SIM", "SIM", "NOQR"]
    assert all(line["simulated"] for line in lines)
    assert [line["label"] for line in lines] == ["0.png", "1.png", "2.png", "4.png"]
    assert all(within_seed_criteria(x["position_mm"], x["angles_deg"], pose) for x in lines[:3])
    assert lines[3]["position_mm"] is None and lines[3]["reason"] == "no QR code found"
    assert "skipped 3.png" in done.stderr and "end after 5 files" in done.stderr


def test_a_video_files_lines_carry_its_own_times(tmp_path: Path) -> None:
    """A clip written at 5 frames/s and decoded as fast as it goes: t_ms is the clip's (0, 200, 400,
    ...), not the decoding's, so the stream's history and filter see the recorded motion."""
    clip = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (160, 120), False)
    assert writer.isOpened(), "this OpenCV build cannot write MJPG .avi"
    for i in range(4):
        writer.write(np.full((120, 160), 40 + 40 * i, np.uint8))
    writer.release()
    done = qrfield("run", "--source", str(clip), "--json-lines", "--focal-px", "200", "--size", "160x120")
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert [line["t_ms"] for line in lines] == [0, 200, 400, 600]


def test_unopenable_source_is_one_clear_error(tmp_path: Path) -> None:
    done = qrfield("run", "--source", str(tmp_path / "missing.avi"))
    assert done.returncode == 1
    assert "cannot open source" in done.stderr and "Traceback" not in done.stderr


def test_no_display_says_how_to_run_headless() -> None:
    done = qrfield(timeout=30)
    assert done.returncode == 3
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "no display" in lines[0] and "qrfield run --headless" in lines[0]
    assert "PySide6" not in done.stderr


# A picamera2 module on PYTHONPATH that is the stand-in (qrfield.sources.picamera_sim): the real
# `--source picamera2` code path, a simulated camera behind it.
FAKE_PICAMERA2 = """
import os
from qrfield.sources.picamera_sim import picamera2_class
from qrfield.sources.virtual import VirtualBenchSettings
Picamera2 = picamera2_class(os.environ.get("SIM_SENSOR", "imx219"), VirtualBenchSettings(noise_sigma=1.0))
"""


def z_of(done: subprocess.CompletedProcess, status: str = "OK") -> list[float]:
    """The z of every line, each of which must have ``status`` (OK: a camera; SIM: the stand-in)."""
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert [line["status"] for line in lines] == [status] * len(lines) and lines, done.stdout
    return [line["position_mm"][2] for line in lines]


def test_picamera2_at_640x480_measures_a_card_at_300_mm_as_300_mm(tmp_path: Path) -> None:
    # The command, on the stand-in IMX219 as the picamera2 module.
    (tmp_path / "picamera2.py").write_text(FAKE_PICAMERA2)
    done = qrfield(
        "run", "--headless", "--source", "picamera2", "--camera", "picam-v2@640x480",
        "--picamera-width", "640", "--picamera-height", "480", "--side-mm", "50", "--frames", "3",
        "--json-lines", "--picamera-settle-frames", "2", PYTHONPATH=f"{REPO}{os.pathsep}{tmp_path}",
    )  # fmt: skip
    assert np.allclose(z_of(done), 300.0, atol=5.0)
    notes = done.stderr.splitlines()
    # The first note names the mode and the crop; the next one the model derived from them.
    assert (
        "imx219 (picamera2, 640x480 from sensor mode 1640x1232 10-bit, ScalerCrop (0, 2)/3280x2460)"
        in notes[0]
    )
    assert notes[1].startswith(
        "qrfield run: camera model: 640x480 px, fx 529.6, fy 529.6, cx 319.5, cy 239.5"
    )
    assert "exposure locked at 10000 us" in done.stderr


@pytest.mark.parametrize(
    ("sensor", "camera", "size"),
    [
        ("imx219", "picam-v2", "1280x720"),
        ("imx708", "picam-v3", "1536x864"),
        ("imx708", "picam-v3", "640x480"),
    ],
)
def test_the_simulated_pi_camera_measures_300_mm_at_other_sizes(sensor, camera, size) -> None:
    width, height = size.split("x")
    done = qrfield(
        "run", "--headless", "--source", f"picamera2-sim:{sensor}", "--camera", camera,
        "--picamera-width", width, "--picamera-height", height, "--side-mm", "50", "--frames", "2",
        "--json-lines",
    )  # fmt: skip
    assert np.allclose(z_of(done, "SIM"), 300.0, atol=5.0)  # the stand-in's poses are never OK
    assert done.stderr.startswith("qrfield run: source: SIMULATED Raspberry Pi camera 0")


def test_picamera2_missing_is_one_clear_line(tmp_path: Path) -> None:
    (tmp_path / "picamera2.py").write_text("raise ImportError('no libcamera here')\n")
    done = qrfield("run", "--source", "picamera2", PYTHONPATH=f"{REPO}{os.pathsep}{tmp_path}")
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert (
        "picamera2 is not installed: on Raspberry Pi OS run sudo apt install python3-picamera2" in done.stderr
    )


def test_serial_link_sends_each_bench_pose_as_a_sim_qrf_line(tmp_path: Path) -> None:
    master, slave = os.openpty()
    os.set_blocking(master, False)
    try:
        done = qrfield(
            "run", "--source", "virtual", "--frames", "6", "--json-lines", "--virtual-fps", "10",
            "--serial", os.ttyname(slave), "--serial-max-rate-hz", "1000", "--serial-stale-after-s", "0",
        )  # fmt: skip
        received = b""
        while True:
            try:
                chunk = os.read(master, 65536)
            except BlockingIOError:
                break
            if not chunk:
                break
            received += chunk
    finally:
        os.close(master)
        os.close(slave)
    assert done.returncode == 0, done.stderr
    poses = {line["t_ms"]: line for line in map(json.loads, done.stdout.splitlines())}
    frames = [parse_frame_line(line) for line in split_lines(received)]
    assert len(frames) >= 4, (frames, done.stderr)
    assert frames[-1]["status"] == "NOSRC"  # the last line as the run ends
    for frame in frames[:-1]:
        assert frame["status"] == "SIM"  # the virtual bench is never OK
        line = poses[frame["t_ms"]]  # t_ms ties each frame to the JSON line of the same capture
        assert np.allclose(frame["pose"][:3], line["position_mm"], atol=0.051)
        assert np.allclose(frame["pose"][3:], line["angles_deg"], atol=0.0051)
        assert np.allclose(frame["sigma"][:3], line["position_std_mm"], atol=0.051)  # its uncertainty too
    assert [f["seq"] for f in frames] == list(range(len(frames)))  # seq counts up from 0
    assert "frames sent" in done.stderr


def test_several_codes_in_view_say_which_one_is_reported(tmp_path: Path, camera_vga) -> None:
    """Two codes in each of two frames (texts 'alpha' far, 'bravo' near and larger): the lines
    report 'bravo' (the largest), and stderr says so once, naming the other code (as ``solve``)."""
    far = render_view(camera_vga, 60.0, Pose([-90.0, 0.0, 500.0], [0.0, 10.0, 5.0]), text="alpha")
    near = render_view(
        camera_vga, 60.0, Pose([55.0, 10.0, 330.0], [-10.0, 0.0, -20.0]), text="bravo", background=far.image
    )
    for i in range(2):
        cv2.imwrite(str(tmp_path / f"{i}.png"), near.image)
    done = qrfield(
        "run", "--source", str(tmp_path), "--json-lines", "--side-mm", "60", "--camera", "picam-v2@640x480"
    )
    assert done.returncode == 0, done.stderr
    assert [json.loads(line)["text"] for line in done.stdout.splitlines()] == ["bravo", "bravo"]
    said = [line for line in done.stderr.splitlines() if "codes in view" in line]
    assert said == [
        "qrfield run: frame 0: 2 codes in view (others: 'alpha'); reporting the one with text 'bravo'; "
        "--select-text TEXT picks one (else the largest)"
    ]
