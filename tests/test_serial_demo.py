"""``qrfield serial-demo`` streams its synthetic path to a pty; frames checked by the independent parser."""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest
from serial_truth import parse_frame_line, split_lines

from qrfield.cli import main
from qrfield.commands.serial_demo import demo_pose

pytestmark = [pytest.mark.timeout(30), pytest.mark.slow]


def test_serial_demo_streams_sim_then_noqr_frames_to_a_pty(capsys):
    master, slave = os.openpty()
    received = bytearray()

    def read() -> None:
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:
                return
            if not data:
                return
            received.extend(data)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        # 1 s at 40 poses/s; NOQR when t mod 1.5 s >= 0.5 s, i.e. from t = 0.5 s on.
        args = ["serial-demo", os.ttyname(slave), "--seconds", "1", "--fps", "40", "--max-rate", "100"]
        assert main([*args, "--noqr-every", "1.5"]) == 0
    finally:
        os.close(slave)
        os.close(master)
        reader.join(5)
    frames = [parse_frame_line(line) for line in split_lines(bytes(received))]
    assert len(frames) >= 10
    assert [f["seq"] for f in frames] == list(range(len(frames)))
    assert frames[-1]["status"] == "NOSRC"  # the last line as the demo ends
    for f in frames[:-1]:
        if f["t_ms"] < 500:
            position, angles = demo_pose(f["t_ms"] / 1000.0)
            assert f["status"] == "SIM"  # made-up poses are never OK
            assert np.all(np.abs(np.array(f["pose"][:3]) - position) <= 0.05 + 1e-9)
            assert np.all(np.abs(np.array(f["pose"][3:]) - angles) <= 0.005 + 1e-9)
            assert f["sigma"] == [0.2, 0.2, 1.0, 0.1, 0.1, 0.05]  # the path's made-up uncertainty
        else:
            assert f["status"] in ("NOQR", "STALE") and f["pose"] is None
    assert {f["status"] for f in frames} >= {"SIM", "NOQR"}
    assert "closed" in capsys.readouterr().err


def test_serial_demo_answers_ping_and_meas_from_its_path(capsys):
    from serial_truth import command_line, frames_and_answers

    master, slave = os.openpty()
    received = bytearray()
    done = threading.Event()

    def read() -> None:
        while not done.is_set():
            try:
                data = os.read(master, 4096)
            except OSError:
                return
            received.extend(data)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    demo = threading.Thread(
        target=main,
        args=(["serial-demo", os.ttyname(slave), "--seconds", "3", "--fps", "40", "--noqr-every", "0"],),
    )
    demo.start()
    try:
        while b"$QRF" not in received:  # the link is up
            time.sleep(0.02)
        os.write(master, command_line("PING") + command_line("MEAS", "5"))
        demo.join(20)
    finally:
        done.set()
        os.close(slave)
        os.close(master)
        reader.join(5)
    frames, answers = frames_and_answers(bytes(received))
    assert (answers[0]["command"], answers[0]["result"]) == ("PING", "OK")
    meas = answers[1]
    assert meas["type"] == "QRM" and meas["status"] == "SIM" and meas["n_used"] == 5
    # The mean of 5 poses of the path lies within the path's range over those 5 frames (1/8 s).
    t = meas["t_ms"] / 1000.0
    window = np.array([np.concatenate(demo_pose(t - k / 40.0)) for k in range(5)])
    assert np.all(np.array(meas["pose"]) >= window.min(axis=0) - 0.06)
    assert np.all(np.array(meas["pose"]) <= window.max(axis=0) + 0.06)
    assert {f["status"] for f in frames[:-1]} <= {"SIM", "STALE"} and frames[-1]["status"] == "NOSRC"


@pytest.mark.parametrize(
    ("setup", "key", "truth"),
    [
        # SimulatedRobot.example's cells, written out: camera_to_tool, camera_to_base (mm, degrees).
        ("eye-in-hand", "camera_to_tool", ([60.0, -15.0, 40.0], [2.0, -3.0, 90.0])),
        ("eye-to-hand", "camera_to_base", ([420.0, 20.0, 900.0], [180.0, 0.0, 90.0])),
    ],
)
def test_serial_demo_robot_recovers_the_known_transform_over_a_pty(tmp_path, capsys, setup, key, truth):
    import json

    from serial_truth import parse_answer_line

    from qrfield.handeye.rigid import difference, transform_from_pose

    args = ["serial-demo", "--robot", "--setup", setup, "--poses", "10", "--seed", "5"]
    assert main([*args, "--out-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    sent = [line[3:] for line in out.splitlines() if line.startswith("-> ")]
    answers = [
        parse_answer_line(line[3:].encode() + b"\r\n") for line in out.splitlines() if line.startswith("<- ")
    ]
    assert len(sent) == len(answers) == 12  # HELLO, 10 TOOL, HANDEYE: one answer each, in order
    assert answers[0]["command"] == "HELLO" and answers[0]["values"][-1] == "camera"
    tools = answers[1:11]
    assert all(a["command"] == "TOOL" for a in tools)
    ok = [a for a in tools if a["result"] == "OK"]
    assert all(a["values"][-1] == "SIM" for a in ok)  # the bench is not a live camera
    assert [int(a["values"][0]) for a in ok] == list(range(1, len(ok) + 1)) and len(ok) >= 8
    assert all(a["reason"].startswith("ambiguous") for a in tools if a["result"] == "ERR")
    handeye = answers[-1]
    assert (handeye["command"], handeye["result"], handeye["values"][-1]) == ("HANDEYE", "OK", "SIM")
    saved = json.loads((tmp_path / "handeye-simulated.json").read_text())
    assert saved["setup"] == setup and saved["simulated"] is True and saved["n_pairs"] == len(ok)
    assert f"{float(handeye['values'][0]):.3f}" == f"{saved['residual_mm']:.3f}"
    err = difference(np.array(saved[key]), transform_from_pose(*truth))
    assert np.linalg.norm(err[:3]) < 2.0 and np.degrees(np.linalg.norm(err[3:])) < 0.3, err
    assert "error against the true" in out


@pytest.mark.slow
def test_serial_demo_to_a_port_that_never_opens_fails_saying_so(tmp_path, capsys):
    """A path that is no serial port (missing, or a plain file): the link retries for the demo's
    time, nothing is sent, and the command ends with exit code 1 and a line saying so (not 0)."""
    plain = tmp_path / "notes.txt"
    plain.write_text("not a port")
    for port in (str(tmp_path / "missing"), str(plain)):
        assert main(["serial-demo", port, "--seconds", "0.3"]) == 1
        err = capsys.readouterr().err
        assert f"qrfield serial-demo: {port} never opened: nothing was sent (last: cannot open" in err


def test_serial_demo_refuses_a_noqr_period_that_leaves_no_pose(capsys):
    """``--noqr-every S`` is 1 s of NOQR every S s: S of 1 s or less would send NOQR only."""
    for value in ("0.5", "1"):
        assert main(["serial-demo", "loop://", "--seconds", "0.2", "--noqr-every", value]) == 2
        assert "--noqr-every must be 0 (never) or more than 1 s" in capsys.readouterr().err


def test_serial_demo_robot_checks_its_out_dir_before_the_program_runs(tmp_path, capsys):
    """``--robot --out-dir`` naming a file, or a folder under one that does not exist: refused at
    once (exit 2, naming --out-dir), not after the whole calibration as "not saved: ...Error"."""
    plain = tmp_path / "notes.txt"
    plain.write_text("a file")
    for out_dir, words in (
        (plain, "a file of that name exists"),
        (tmp_path / "no" / "deeper", "does not exist"),
    ):
        assert main(["serial-demo", "--robot", "--poses", "5", "--out-dir", str(out_dir)]) == 2
        err = capsys.readouterr().err
        assert f"--out-dir {out_dir}: cannot create the folder" in err and words in err
