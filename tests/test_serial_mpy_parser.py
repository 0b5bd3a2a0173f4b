"""The MicroPython example parser assets/qrf_parser.py, run here with CPython on real frames."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from qrfield.serial_link import encode_frame

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
