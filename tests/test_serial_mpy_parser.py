"""The MicroPython example parser assets/qrf_parser.py, run here with CPython on real frames."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from qrfield.serial_link import encode_answer, encode_frame, encode_measurement

pytestmark = pytest.mark.timeout(30)
SOURCE = Path(__file__).resolve().parent.parent / "assets" / "qrf_parser.py"


@pytest.fixture(scope="module")
def mpy():
    spec = importlib.util.spec_from_file_location("qrf_parser_asset", SOURCE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_micropython_parser_reads_frames_and_rejects_bad_ones(mpy):
    rng = np.random.default_rng(9)
    sent = []
    data = b"junk"
    for i in range(50):
        pos = rng.uniform(-1000, 1000, 3)
        ang = rng.uniform([-180, -90, -180], [180, 90, 180])
        sent.append((i, pos, ang))
        data += encode_frame(i, 5 * i, pos, ang, "OK")
    bad = b"$QRF,7,100,,,,,,,NOQR*6C\r\n"  # the right checksum is 6D (worked out in test_serial_frames.py)
    data += bad + b"$QRF," + b"1" * 300 + b"\r\n" + encode_frame(50, 250, None, None, "NOQR")
    reader = mpy.Reader()
    frames = []
    for k in range(0, len(data), 7):
        frames += reader.feed(data[k : k + 7])
    assert reader.bad == 2
    assert frames[-1] == (50, 250, "NOQR", None)
    for (seq, t_ms, status, pose), (i, pos, ang) in zip(frames[:-1], sent, strict=True):
        assert (seq, t_ms, status) == (i, 5 * i, "OK")
        assert np.all(np.abs(np.array(pose[:3]) - pos) <= 0.05 + 1e-9)
        assert np.all(np.abs(np.array(pose[3:]) - ang) <= 0.005 + 1e-9)


def test_micropython_parser_reads_measurements_answers_and_writes_commands(mpy):
    from serial_truth import command_line

    rng = np.random.default_rng(12)
    data, sent = b"", []
    for i in range(30):
        mean = np.concatenate([rng.uniform(-2000, 2000, 3), rng.uniform([-180, -90, -180], [180, 90, 180])])
        std = np.concatenate([rng.uniform(0, 20, 3), rng.uniform(0, 3, 3)])
        data += encode_measurement(i, 7 * i, "SIM", mean[:3], mean[3:], std[:3], std[3:], 10)
        sent.append((mean, std))
    data += (
        encode_measurement(30, 5, "TIMEOUT") + encode_answer("STREAM") + encode_answer("X", "ERR", "unknown")
    )
    data += encode_frame(31, 6, (1, 2, 3), (4, 5, 6), "SIM") + encode_frame(32, 6, None, None, "NOSRC")
    data += b"$QRC,PING*7C\r\n"  # a command (another talker): not ours to read, not bad either
    reader = mpy.Reader()
    items = []
    for k in range(0, len(data), 11):
        items += reader.feed_all(data[k : k + 11])
    assert reader.bad == 0
    measurements = [item for kind, item in items if kind == "QRM"]
    for (seq, t_ms, mean, std, n_used, status), (true_mean, true_std) in zip(
        measurements[:30], sent, strict=True
    ):
        assert (t_ms, n_used, status) == (7 * seq, 10, "SIM")
        tolerance = np.array([0.05] * 3 + [0.005] * 3) + 1e-9
        assert np.all(np.abs(np.array(mean) - true_mean) <= tolerance)
        assert np.all(np.abs(np.array(std) - true_std) <= tolerance)
    assert measurements[30] == (30, 5, None, None, None, "TIMEOUT")
    assert [item for kind, item in items if kind == "QRA"] == [("STREAM", "OK", ""), ("X", "ERR", "unknown")]
    assert [item for kind, item in items if kind == "QRF"] == [(31, 6, "SIM", (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)),
                                                              (32, 6, "NOSRC", None)]  # fmt: skip
    assert mpy.command("MEAS", 10) == command_line("MEAS", "10") and mpy.command("PING") == command_line(
        "PING"
    )
