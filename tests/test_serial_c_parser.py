"""The example controller parser assets/qrf_parser.c, compiled with gcc -Wall -Wextra -Werror -pedantic
and fed the lines qrfield writes (frames, measurements, answers); it also writes the commands."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from qrfield.serial_link import encode_answer, encode_frame, encode_measurement

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


@pytest.mark.slow
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


def test_c_parser_reads_measurements_answers_and_the_new_statuses(parser_binary):
    rng = np.random.default_rng(11)
    data, expected = b"", []
    for i in range(100):
        mean_pos, mean_ang = rng.uniform(-3000, 3000, 3), rng.uniform([-180, -90, -180], [180, 90, 180])
        std_pos, std_ang = rng.uniform(0, 50, 3), rng.uniform(0, 5, 3)
        status = ("OK", "SIM")[i % 2]
        data += encode_measurement(i, 40 * i, status, mean_pos, mean_ang, std_pos, std_ang, i % 100 + 1)
        expected.append(
            (i, 40 * i, status, np.concatenate([mean_pos * 10, mean_ang * 100, std_pos * 10, std_ang * 100]))
        )
    data += encode_measurement(7, 9, "TIMEOUT") + encode_measurement(8, 9, "NOSRC")
    data += encode_answer("PING") + encode_answer("MEAS", "ERR", "busy: a MEAS is collecting")
    data += encode_frame(3, 4, (1.25, -2, 3), (4, 5, -6), "SIM") + encode_frame(5, 6, None, None, "NOSRC")
    data += b"$QRM,1,2,,,,,,,,,,,,,,,OK*00\r\n"  # OK with empty fields (checksum wrong as well)
    lines = run_parser(parser_binary, data)
    for line, (seq, t_ms, status, scaled) in zip(lines[:100], expected, strict=True):
        tag, seq_text, t_text, got_status, *values = line.split()
        assert (tag, int(seq_text), int(t_text), got_status) == ("MEAS", seq, t_ms, status)
        got = np.array([float(v) for v in values[:12]])
        scale = np.array([10] * 3 + [100] * 3 + [10] * 3 + [100] * 3)
        assert np.all(np.abs(got * scale - scaled) <= 0.5 + 1e-6), line
        assert int(values[12]) == seq % 100 + 1
    assert lines[100:] == [
        "MEAS 7 9 TIMEOUT",
        "MEAS 8 9 NOSRC",
        "ANSWER PING OK",
        "ANSWER MEAS ERR busy: a MEAS is collecting",
        "FRAME 3 4 SIM 1.2 -2.0 3.0 4.00 5.00 -6.00",
        "FRAME 5 6 NOSRC",
        "ERR checksum",
    ]


def test_c_parser_rejects_a_filled_status_without_fields(parser_binary):
    def line(body: str) -> bytes:  # the checksum by hand, as docs/conventions.md defines it
        cs = 0
        for ch in body.encode():
            cs ^= ch
        return b"$%s*%02X\r\n" % (body.encode(), cs)

    data = (
        line("QRM,1,2,,,,,,,,,,,,,,,OK")
        + line("QRF,1,2,,,,,,,SIM")
        + line("QRF,1,2,1.0,2.0,3.0,1.00,2.00,3.00,NOSRC")
    )
    data += line("QRA,PING") + line("QRM,1,2,1.0,2.0,3.0,1.00,2.00,3.00,0.1,0.1,0.1,0.01,0.01,0.01,101,OK")
    assert run_parser(parser_binary, data) == ["ERR format"] * 5


def test_c_parser_writes_commands_qrfield_reads(parser_binary):
    from serial_truth import command_line

    from qrfield.serial_frames import ControllerCommand, FrameDecoder

    for args in (("PING",), ("STREAM", "OFF"), ("MEAS", "10")):
        done = subprocess.run(
            [str(parser_binary), "--command", *args], capture_output=True, timeout=20, check=True
        )
        assert done.stdout == command_line(*args)  # the bytes docs/conventions.md gives
        assert FrameDecoder().feed(done.stdout) == [ControllerCommand("QRC", args)]
