"""``qrfield serial-monitor`` on the slave end of a pty, fed hand-made bytes through the master."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from serial_truth import crc16

pytestmark = pytest.mark.timeout(30)
REPO = Path(__file__).resolve().parent.parent


def line(body: str) -> bytes:
    """A line with its CRC from tests/serial_truth.py (written from the conventions)."""
    return b"$%s*%04X\r\n" % (body.encode(), crc16(body.encode()))


GOOD_NOQR = line("QRF,7,100,4,,,,,,,,,,,,,NOQR")
GOOD_OK = line("QRF,1,2,3,0.0,0.0,0.0,0.00,0.00,0.00,0.1,,0.3,0.01,0.02,,OK")
BAD_CS = GOOD_NOQR.replace(GOOD_NOQR[-6:-2], b"0000")
COMMAND = line("QRC,RATE,10")


def start_monitor(*args: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    cmd = [sys.executable, "-m", "qrfield", "serial-monitor", *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=REPO)
    assert proc.stderr is not None
    banner = proc.stderr.readline().decode()  # the monitor has the port open once it says so
    assert "listening on" in banner, banner + proc.stderr.read().decode()
    return proc


@pytest.fixture
def pty_pair():
    master, slave = os.openpty()
    yield master, os.ttyname(slave)
    for fd in (master, slave):
        os.close(fd)


def test_monitor_prints_frames_and_counts_problems_as_json(pty_pair):
    master, slave_name = pty_pair
    proc = start_monitor(slave_name, "--json", "--count", "3")
    os.write(master, b"junk!" + GOOD_NOQR + BAD_CS + b"$QRF,9,1" + GOOD_OK + COMMAND)
    out, err = proc.communicate(timeout=15)
    assert proc.returncode == 0, err.decode()
    lines = [json.loads(text) for text in out.decode().splitlines()]
    none = dict.fromkeys(("position_mm", "angles_deg", "std_position_mm", "std_angles_deg"))
    # The age at arrival: age_ms + bytes x 10 / 115200 ms (36 bytes, counted by hand, and 67).
    assert lines == [
        {
            "type": "frame",
            "seq": 7,
            "t_ms": 100,
            "age_ms": 4,
            **none,
            "status": "NOQR",
            "arrival_age_ms": 4 + 360 / 115.2,
        },
        {
            "type": "frame",
            "seq": 1,
            "t_ms": 2,
            "age_ms": 3,
            "position_mm": [0.0, 0.0, 0.0],
            "angles_deg": [0.0, 0.0, 0.0],
            "std_position_mm": [0.1, None, 0.3],
            "std_angles_deg": [0.01, 0.02, None],
            "status": "OK",
            "arrival_age_ms": 3 + 10 * len(GOOD_OK) / 115.2,
        },
        {"type": "command", "talker": "QRC", "fields": ["RATE", "10"]},
    ]
    assert (len(GOOD_NOQR), len(GOOD_OK)) == (36, 67)
    summary = err.decode()
    assert "frames 2" in summary and "bad CRCs 1" in summary and "truncated 1" in summary
    assert "garbage bytes 5" in summary and "seq gaps 1" in summary  # 7 -> 1 is not 7 + 1


def test_monitor_text_output_and_clean_exit_on_ctrl_c(pty_pair):
    master, slave_name = pty_pair
    proc = start_monitor(slave_name)
    # The example line of docs/serial.md.
    os.write(master, line("QRF,42,1234,17,12.5,-3.0,250.0,1.25,-0.50,90.00,0.1,0.2,0.5,0.05,0.10,0.20,OK"))
    assert proc.stdout is not None
    text = proc.stdout.readline().decode()
    expected = (
        "seq=42 t=1234 ms age 17 ms (at arrival 24 ms) x=12.5 y=-3.0 z=250.0 mm alpha=1.25 beta=-0.50 "
        "gamma=90.00 deg sigma x=0.1 y=0.2 z=0.5 mm alpha=0.05 beta=0.10 gamma=0.20 deg OK"
    )
    assert text.split() == expected.split()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=15)
    assert proc.returncode == 0 and "interrupted; frames 1" in err.decode()


def test_monitor_stops_cleanly_on_sigterm(pty_pair):
    proc = start_monitor(pty_pair[1])
    proc.terminate()
    _, err = proc.communicate(timeout=15)
    assert proc.returncode == 0 and "interrupted; frames 0" in err.decode()


def test_monitor_says_clearly_when_the_port_cannot_be_opened(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    missing = tmp_path / "ttyGone"
    result = subprocess.run(
        [sys.executable, "-m", "qrfield", "serial-monitor", str(missing)],
        capture_output=True,
        env=env,
        cwd=REPO,
        timeout=15,
    )
    assert result.returncode == 2
    assert f"cannot open serial port {missing}" in result.stderr.decode()
    assert "Traceback" not in result.stderr.decode()


def test_monitor_sends_commands_and_stops_once_they_are_answered(pty_pair):
    from serial_truth import command_line

    master, slave_name = pty_pair
    proc = start_monitor(
        slave_name, "--send", "PING", "--send", "$QRC,MEAS,10*00", "--answers-only", "--json"
    )
    sent = b""
    while sent.count(b"\r\n") < 2:
        sent += os.read(master, 4096)
    # The CRC is computed by the monitor (a wrong one typed is replaced).
    assert sent == command_line("PING") + command_line("MEAS", "10")
    measurement = "QRM,0,5321,10.0,-5.0,300.0,15.04,-20.01,10.00,0.0,0.0,0.0,0.01,0.01,0.00,10,OK"
    os.write(master, GOOD_NOQR + line("QRA,PING,OK") + line(measurement))
    out, err = proc.communicate(timeout=15)
    assert proc.returncode == 0, err.decode()
    lines = [json.loads(text) for text in out.decode().splitlines()]
    assert lines[0] == {"type": "answer", "command": "PING", "fields": ["OK"]}
    assert lines[1]["type"] == "measurement" and lines[1]["status"] == "OK" and lines[1]["n_used"] == 10
    assert lines[1]["position_mm"] == [10.0, -5.0, 300.0] and lines[1]["std_angles_deg"] == [0.01, 0.01, 0.0]
    assert len(lines) == 2 and "2 answers received" in err.decode()
