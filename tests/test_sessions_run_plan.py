"""``qrfield session run-plan`` in a real process: the study's 12 combinations x 2 angles on the
virtual bench (24 rows whose ground truth is each target, typed here from docs/conventions.md's
list, and whose measured poses are within the criteria of it), a run stopped with Ctrl-C that
continues where it was, and an operator at a terminal (a folder of rendered images standing in
for a camera that is not the virtual bench): Enter, s to skip, q."""

from __future__ import annotations

import csv
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_sessions_plan import DESIGN_COMBINATIONS

from qrfield.camera import resolve_camera
from qrfield.geometry import Pose, angle_difference
from qrfield.render import render_view

CAMERA = "picam-v2@640x480"
SIDE = 50.0
Z = 300.0
ANGLES = (10.0, 20.0)


def qrfield(*args: str, stdin: str | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "qrfield", *args],
        capture_output=True,
        text=True,
        input=stdin,
        timeout=timeout,
    )


@pytest.fixture
def config_dir(tmp_path: Path, monkeypatch) -> Path:
    folder = tmp_path / "config"
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(folder))
    return folder


def new_session(tmp_path: Path, name: str, frames: int = 5) -> Path:
    done = qrfield(
        "session", "new", str(tmp_path / "sessions"), "--name", name, "--camera", CAMERA,
        "--side-mm", str(SIDE), "--method", "numerical", "--frames-per-row", str(frames),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return Path(done.stdout.strip())


def rows_of(session: Path) -> list[dict[str, str]]:
    with open(session / "rows.csv", newline="", encoding="utf-8") as f:
        return [r for r in csv.DictReader(f) if r["row"]]


@pytest.mark.slow
def test_the_studys_12_combinations_at_2_angles_on_the_virtual_bench(tmp_path: Path, config_dir) -> None:
    plan = tmp_path / "plan.csv"
    assert qrfield("plan", "--angles", "10,20", "--z-mm", "300", "--out", str(plan)).returncode == 0
    session = new_session(tmp_path, "bench plan")
    done = qrfield(
        "session", "run-plan", str(session), "--plan", str(plan), "--source", "virtual", "--hold-s", "0.5"
    )
    assert done.returncode == 0, done.stderr
    assert "plan: 24 of 24 targets done" in done.stdout
    rows = rows_of(session)
    assert len(rows) == 24
    expected = [
        (name, tuple(t * m for m in multipliers))
        for name, multipliers in DESIGN_COMBINATIONS.items()
        for t in ANGLES
    ]
    within = 0
    for row, (name, angles) in zip(rows, expected, strict=True):
        assert row["combo"] == name
        truth = [float(row[f"gt_{k}"]) for k in ("x", "y", "z", "alpha", "beta", "gamma")]
        assert truth == [0.0, 0.0, Z, *angles]  # the target, exactly
        measured = np.array([float(row[k]) for k in ("x", "y", "z", "alpha", "beta", "gamma")])
        position_ok = math.dist(measured[:3], truth[:3]) < 5.0
        angles_ok = np.all(np.abs(angle_difference(measured[3:], truth[3:])) <= 2.0)
        within += bool(position_ok and angles_ok)
        assert row["pass"] == ("1" if position_ok and angles_ok else "0")
    assert within >= 22, f"only {within} of 24 rows within 5 mm and 2 deg of their target"


@pytest.mark.slow
def test_a_stopped_run_continues_where_it_was(tmp_path: Path, config_dir) -> None:
    plan = tmp_path / "plan.csv"
    assert (
        qrfield(
            "plan", "--combos", "alpha,beta", "--angles", "5,15", "--z-mm", "280", "--out", str(plan)
        ).returncode
        == 0
    )
    session = new_session(tmp_path, "stopped", frames=3)
    command = [sys.executable, "-m", "qrfield", "session", "run-plan", str(session), "--plan", str(plan)]
    process = subprocess.Popen(
        # A hold of 2 s a target: the three targets after row 1 take 6 s or more, so the SIGINT sent
        # on reading "logged row 1" lands mid-run even when this process waits a second or two for
        # the CPU (at 0.3 s the run once ended first at load 8).
        [*command, "--source", "virtual", "--hold-s", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        for line in process.stdout:
            if line.startswith("logged row 1:") or time.monotonic() > deadline:
                break
        process.send_signal(signal.SIGINT)
        process.wait(60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 130, process.stderr.read()
    first = rows_of(session)
    assert 1 <= len(first) < 4
    again = qrfield("session", "run-plan", str(session), "--source", "virtual", "--hold-s", "0.3")
    assert again.returncode == 0, again.stderr
    assert "plan: 4 of 4 targets done" in again.stdout
    rows = rows_of(session)
    assert [r["row"] for r in rows] == ["1", "2", "3", "4"]
    assert [(r["combo"], r["gt_alpha"], r["gt_beta"]) for r in rows] == [
        ("alpha", "5.000", "0.000"),
        ("alpha", "15.000", "0.000"),
        ("beta", "0.000", "5.000"),
        ("beta", "0.000", "15.000"),
    ]


@pytest.mark.slow
def test_an_operator_at_a_terminal_logs_skips_and_stops(tmp_path: Path, config_dir) -> None:
    plan = tmp_path / "plan.csv"
    plan.write_text(
        "x,y,z,alpha,beta,gamma,combo,note\n"
        "0,0,300,15,0,0,alpha,jig A\n0,0,300,0,15,0,beta,\n0,0,300,0,0,15,gamma,\n",
        encoding="utf-8",
    )
    # The "camera": a folder of the card rendered at target 1 (not the virtual bench: the terminal asks).
    folder = tmp_path / "camera"
    folder.mkdir()
    camera = resolve_camera(CAMERA)
    import cv2

    for k in range(4):
        view = render_view(camera, SIDE, Pose([0, 0, 300], [15, 0, 0]), noise_sigma=2.0, blur_px=0.6, seed=k)
        cv2.imwrite(str(folder / f"frame{k}.png"), view.image)
    session = new_session(tmp_path, "operator", frames=3)
    done = qrfield(
        "session", "run-plan", str(session), "--plan", str(plan), "--source", str(folder), "--loop",
        "--hold-s", "0.3", stdin="\ns\nq\n",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("Enter when the jig is set") == 3
    assert "skipped target 2" in done.stdout
    assert "plan: 1 of 3 targets done (1 of 1 rows pass), 1 skipped, 1 to do" in done.stdout
    (row,) = rows_of(session)
    assert (row["gt_alpha"], row["combo"], row["note"], row["pass"]) == ("15.000", "alpha", "jig A", "1")
    # The skipped target is offered again only when asked for.
    later = qrfield(
        "session", "run-plan", str(session), "--source", str(folder), "--loop", "--retry-skipped", stdin="q\n"
    )
    assert "target 2: beta" in later.stdout


@pytest.mark.slow
def test_a_bad_plan_is_refused_before_anything_changes(tmp_path: Path, config_dir) -> None:
    plan = tmp_path / "plan.csv"
    plan.write_text(
        "x,y,z,alpha,beta,gamma,combo\n0,0,300,10,0,0,alpha\n0,0,300,0,10,0,alpha\n", encoding="utf-8"
    )
    session = new_session(tmp_path, "bad plan")
    done = qrfield("session", "run-plan", str(session), "--plan", str(plan), "--source", "virtual")
    assert done.returncode == 2
    assert f"{plan} line 3 (target 2), column 'combo'" in done.stderr
    assert sorted(p.name for p in session.iterdir()) == ["rows.csv", "session.json"]
    none = qrfield("session", "run-plan", str(session), "--source", "virtual")
    assert none.returncode == 2 and "has no plan yet" in none.stderr


@pytest.mark.slow
def test_a_session_in_the_tool_frame_is_refused_for_a_plan_of_camera_poses(
    tmp_path: Path, config_dir
) -> None:
    from qrfield.handeye import HandEyeCalibration

    config_dir.mkdir(parents=True, exist_ok=True)
    HandEyeCalibration("eye-in-hand", np.eye(4), 0.1, 0.02, 15, "test").save(config_dir / "handeye.json")
    done = qrfield(
        "session", "new", str(tmp_path / "sessions"), "--name", "tool", "--camera", CAMERA,
        "--side-mm", str(SIDE), "--method", "numerical", "--frame", "tool",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    session = Path(done.stdout.strip())
    plan = tmp_path / "plan.csv"
    plan.write_text("x,y,z,alpha,beta,gamma,combo\n0,0,300,10,0,0,alpha\n", encoding="utf-8")
    refused = qrfield("session", "run-plan", str(session), "--plan", str(plan), "--source", "virtual")
    assert refused.returncode == 2 and "reports poses in the tool frame" in refused.stderr
    assert rows_of(session) == []


@pytest.mark.slow
def test_a_plan_whose_input_ends_says_nobody_answered_and_fails(tmp_path: Path, config_dir) -> None:
    """Not the virtual bench, and stdin at its end (a script, ``< /dev/null``): the prompt gets no
    answer; the run stops with a line saying so and exit code 1, not as a plain 'q' (exit 0)."""
    import cv2

    plan = tmp_path / "plan.csv"
    plan.write_text("x,y,z,alpha,beta,gamma,combo,note\n0,0,300,15,0,0,alpha,\n", encoding="utf-8")
    folder = tmp_path / "camera"
    folder.mkdir()
    cv2.imwrite(str(folder / "blank.png"), np.full((480, 640), 110, np.uint8))
    session = new_session(tmp_path, "no input")
    args = ("session", "run-plan", str(session), "--plan", str(plan), "--source", str(folder), "--loop")
    done = qrfield(*args, stdin="")
    assert done.returncode == 1, done.stderr
    assert "end of input: no one answered the prompt" in done.stderr
    assert "plan: 0 of 1 targets done" in done.stdout and rows_of(session) == []
    assert qrfield(*args, stdin="q\n").returncode == 0  # a 'q' typed is a choice: exit 0
