"""The example controller parser assets/qrf_parser.c, compiled with gcc and fed real frames."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from qrfield.serial_link import encode_frame

pytestmark = pytest.mark.timeout(60)
SOURCE = Path(__file__).resolve().parent.parent / "assets" / "qrf_parser.c"


@pytest.fixture(scope="module")
def parser_binary(tmp_path_factory) -> Path:
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("gcc not found: cannot compile assets/qrf_parser.c")
    binary = tmp_path_factory.mktemp("cparser") / "qrf_parser"
    subprocess.run(
        [gcc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-o", str(binary), str(SOURCE)],
        check=True,
        timeout=60,
        capture_output=True,
    )
    return binary


def run_parser(binary: Path, data: bytes) -> list[str]:
    result = subprocess.run([str(binary)], input=data, capture_output=True, timeout=20, check=True)
    return result.stdout.decode().splitlines()


def test_c_parser_reads_encoded_frames_in_fixed_point(parser_binary):
    rng = np.random.default_rng(5)
    frames, expected = [], []
    for i in range(200):
        position = rng.uniform(-5000, 5000, 3)
        angles = np.array([rng.uniform(-180, 180), rng.uniform(-90, 90), rng.uniform(-180, 180)])
        if i == 0:
            position, angles = np.array([-0.04, 0.0, 0.5]), np.array([-0.004, 0.0, 179.999])
        frames.append(encode_frame(i * 331 % 65536, i * 33, position, angles, "OK"))
        expected.append((i * 331 % 65536, i * 33, position * 10, angles * 100))
    lines = run_parser(parser_binary, b"".join(frames))
    assert len(lines) == len(frames)
    for line, (seq, t_ms, pos_scaled, ang_scaled) in zip(lines, expected, strict=True):
        tag, seq_text, t_text, status, *values = line.split()
        assert (tag, int(seq_text), int(t_text), status) == ("FRAME", seq, t_ms, "OK")
        got = np.array([float(v) for v in values])
        # Tenths of a mm and hundredths of a degree: within half a unit of the value sent.
        assert np.all(np.abs(got[:3] * 10 - pos_scaled) <= 0.5 + 1e-6), line
        assert np.all(np.abs(got[3:] * 100 - ang_scaled) <= 0.5 + 1e-6), line


def test_c_parser_rejects_bad_checksum_and_resynchronises(parser_binary):
    good = encode_frame(7, 100, None, None, "NOQR")
    bad = good.replace(b"*6D", b"*6C")  # 6D worked out by hand in test_serial_frames.py
    cut = encode_frame(8, 101, (1, 2, 3), (4, 5, 6), "OK")[:20]
    long_line = b"$QRF," + b"9" * 500 + b"\r\n"
    data = (
        b"noise"
        + good
        + bad
        + cut
        + good
        + long_line
        + b"$QRC,RATE,10*43\r\n"
        + encode_frame(9, 5, None, None, "NOCONV")
    )
    assert run_parser(parser_binary, data) == [
        "FRAME 7 100 NOQR",
        "ERR checksum",
        "FRAME 7 100 NOQR",
        "ERR length",
        "OTHER",
        "FRAME 9 5 NOCONV",
    ]
