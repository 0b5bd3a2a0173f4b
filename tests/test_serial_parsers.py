"""The parsers users copy to their controller (assets/qrf_parser.c and assets/qrf_parser.py).

The C parser is compiled with -O2 -Wall -Wextra -Werror -pedantic and again under
-fsanitize=address,undefined (skipped with a reason where gcc is missing); the MicroPython one runs
here on CPython. Both read 10,000 real lines from a run (tests/serial_lines.py) exactly as
qrfield's codec and the independent tests/serial_truth.py do, and 100,000 corruptions of those
lines (bit flips, bursts of up to 16 bits, truncation, concatenation, NUL bytes, lines over 160
bytes) are never accepted as anything but one of the lines they came from.
"""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from serial_lines import record_lines
from serial_truth import command_line, crc16, parse_answer_line, parse_frame_line

from qrfield.serial import codec

pytestmark = pytest.mark.timeout(300)
ASSETS = Path(__file__).resolve().parent.parent / "assets"
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
MARK = b"$QRA,MARK,OK*%04X\r\n" % crc16(b"QRA,MARK,OK")  # separates corrupted blobs in the C's output


def _compile(tmp: Path, name: str, *extra: str) -> Path:
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("gcc not found: cannot compile assets/qrf_parser.c")
    binary = tmp / name
    done = subprocess.run(
        [gcc, *FLAGS, *extra, "-o", str(binary), str(ASSETS / "qrf_parser.c")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and not done.stderr, done.stderr  # warning-free
    return binary


@pytest.fixture(scope="module")
def c_parser(tmp_path_factory) -> Path:
    return _compile(tmp_path_factory.mktemp("cparser"), "qrf_parser", "-O2")


@pytest.fixture(scope="module")
def c_parser_sanitized(tmp_path_factory) -> Path:
    return _compile(
        tmp_path_factory.mktemp("cparser_san"),
        "qrf_parser_san",
        "-O1",
        "-g",
        "-fsanitize=address,undefined",
        "-fno-sanitize-recover=all",
    )


@pytest.fixture(scope="module")
def mpy():
    spec = importlib.util.spec_from_file_location("qrf_parser_asset", ASSETS / "qrf_parser.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def real_lines() -> list[bytes]:
    return record_lines(10_000)[:10_000]


def run_c(binary: Path, data: bytes) -> list[str]:
    done = subprocess.run([str(binary)], input=data, capture_output=True, timeout=120)
    assert done.returncode == 0 and not done.stderr, done.stderr[-2000:]
    return done.stdout.decode().splitlines()


# ------------------------------------------------------------------ one text per decoded line
def _ints(values, scale: int) -> list[str]:
    return ["?" if v is None else str(round(v * scale)) for v in values]


def canonical_codec(item) -> str | None:
    """The C demo's output line for an item of qrfield's codec (None: not a line of ours)."""
    if isinstance(item, codec.QrfFrame):
        head = f"FRAME {item.seq} {item.t_ms} {'-' if item.age_ms is None else item.age_ms} {item.status}"
        if item.position_mm is None:
            return head
        values = [*_ints(item.position_mm, 10), *_ints(item.angles_deg, 100)]
        values += [*_ints(item.std_position_mm, 10), *_ints(item.std_angles_deg, 100)]
        return f"{head} {' '.join(values)}"
    if isinstance(item, codec.QrmMeasurement):
        head = f"MEAS {item.seq} {item.t_ms} {item.status}"
        if item.position_mm is None:
            return head
        values = [*_ints(item.position_mm, 10), *_ints(item.angles_deg, 100)]
        values += [*_ints(item.std_position_mm, 10), *_ints(item.std_angles_deg, 100), str(item.n_used)]
        return f"{head} {' '.join(values)}"
    if isinstance(item, codec.QraAnswer):
        return f"ANSWER {item.command} {','.join(item.fields)}"
    return None


def canonical_mpy(kind: str, item) -> str:
    def text(values) -> list[str]:
        return ["?" if v is None else str(v) for v in values]

    if kind == "QRF":
        seq, t_ms, age, status, pose, sigmas = item
        head = f"FRAME {seq} {t_ms} {'-' if age is None else age} {status}"
        return head if pose is None else f"{head} {' '.join(text(pose) + text(sigmas))}"
    if kind == "QRM":
        seq, t_ms, status, mean, sigmas, n_used = item
        head = f"MEAS {seq} {t_ms} {status}"
        return head if mean is None else f"{head} {' '.join(text(mean) + text(sigmas))} {n_used}"
    command, fields = item
    return f"ANSWER {command} {','.join(fields)}"


def decode_codec(data: bytes) -> list[str]:
    items = codec.FrameDecoder().feed(data)
    return [t for t in map(canonical_codec, items) if t is not None]


def decode_mpy(mpy, data: bytes) -> list[str]:
    return [canonical_mpy(kind, item) for kind, item in mpy.Reader().feed_all(data)]


# ------------------------------------------------------------------ the tests
@pytest.mark.slow  # recording 10,000 lines takes 10-20 s on a loaded 2-core machine
def test_real_lines_are_valid_for_the_independent_truth_and_cover_every_kind(real_lines):
    kinds = set()
    for line in real_lines:
        parsed = parse_frame_line(line) if line.startswith(b"$QRF") else parse_answer_line(line)
        kinds.add(parsed["status"] if line.startswith(b"$QRF") else (parsed["type"], parsed.get("result")))
        assert len(line) <= 160
    assert {"OK", "AMBIG", "SIM", "NOQR", "NOCONV", "STALE", "NOSRC"} <= kinds
    assert {("QRA", "OK"), ("QRA", "ERR"), ("QRA", "QRF2"), ("QRM", None)} <= kinds


@pytest.mark.slow
def test_ten_thousand_real_lines_decode_identically_in_c_micropython_and_qrfield(real_lines, c_parser, mpy):
    data = b"".join(real_lines)
    expected = decode_codec(data)
    assert len(expected) == len(real_lines) == 10_000  # every line read by qrfield's codec
    assert run_c(c_parser, data) == expected
    assert decode_mpy(mpy, data) == expected
    # Received a byte at a time (a UART interrupt), and with LF alone: the same.
    reader = mpy.Reader()
    assert [canonical_mpy(k, i) for b in data[:3000] for k, i in reader.feed_all(bytes([b]))] == decode_codec(
        data[:3000]
    )
    assert run_c(c_parser, data.replace(b"\r\n", b"\n")) == expected


@pytest.mark.slow
def test_the_sanitized_c_parser_reads_them_too_and_survives_random_bytes(real_lines, c_parser_sanitized):
    data = b"".join(real_lines[:2000])
    assert run_c(c_parser_sanitized, data) == decode_codec(data)
    rng = np.random.default_rng(7)
    noise = rng.integers(0, 256, 200_000).astype(np.uint8).tobytes()
    dollars = noise.replace(b"A", b"$").replace(b"B", b"\n")  # many short and long lines
    run_c(c_parser_sanitized, noise + dollars + b"$" + b"9" * 5000 + b"\n")  # no sanitizer report


def corruptions(lines: list[bytes], n: int, seed: int):
    """(blob, indices of the lines it came from): n seeded corruptions of the lines."""
    rng = np.random.default_rng(seed)
    for k in range(n):
        i = int(rng.integers(len(lines)))
        line = bytearray(lines[i])
        kind = k % 8
        used = [i]
        if kind in (0, 1, 2):  # 1, 2 or 3 bit flips anywhere in the line
            for bit in rng.choice(len(line) * 8, kind + 1, replace=False):
                line[bit // 8] ^= 1 << (bit % 8)
        elif kind == 3:  # a burst: any pattern within 16 consecutive bits, first and last bit set
            length = int(rng.integers(2, 17))
            start = int(rng.integers(0, len(line) * 8 - length + 1))
            pattern = (int(rng.integers(0, 1 << max(0, length - 2))) << 1) | 1 | (1 << (length - 1))
            for b in range(length):
                if pattern >> b & 1:
                    bit = start + b
                    line[bit // 8] ^= 1 << (7 - bit % 8)
        elif kind == 4:  # truncation
            del line[int(rng.integers(1, len(line))) :]
        elif kind == 5:  # concatenation: this line cut or whole, then another line
            j = int(rng.integers(len(lines)))
            cut = int(rng.integers(1, len(line) + 1))
            line = line[:cut] + lines[j]
            used.append(j)
        elif kind == 6:  # a NUL byte put in or over a byte
            at = int(rng.integers(1, len(line) - 2))
            if rng.random() < 0.5:
                line.insert(at, 0)
            else:
                line[at] = 0
        else:  # longer than 160 bytes: digits inserted in the body
            at = int(rng.integers(5, len(line) - 7))
            line[at:at] = b"7" * int(rng.integers(161 - len(line), 300 - len(line)))
        yield bytes(line), used


@pytest.mark.slow
def test_a_hundred_thousand_corruptions_are_never_accepted_as_a_wrong_line(real_lines, c_parser, mpy):
    truth = {i: decode_codec(line) for i, line in enumerate(real_lines)}
    wrong = {"codec": 0, "c": 0, "mpy": 0}
    accepted = {"codec": 0, "c": 0, "mpy": 0}
    blobs, allowed = [], []
    for blob, used in corruptions(real_lines, 100_000, seed=22):
        ok = {t for i in used for t in truth[i]}
        allowed.append(ok)
        blobs.append(blob)
        for name, got in (("codec", decode_codec(blob + b"\n")), ("mpy", decode_mpy(mpy, blob + b"\n"))):
            accepted[name] += len(got)
            wrong[name] += sum(t not in ok for t in got)
    out = run_c(c_parser, b"".join(blob + b"\n" + MARK for blob in blobs))
    per_blob: list[list[str]] = [[]]
    for text in out:
        if text == "ANSWER MARK OK":
            per_blob.append([])
        elif not text.startswith(("ERR", "OTHER")):
            per_blob[-1].append(text)
    assert len(per_blob) == len(blobs) + 1
    for got, ok in zip(per_blob, allowed, strict=False):
        accepted["c"] += len(got)
        wrong["c"] += sum(t not in ok for t in got)
    assert wrong == {"codec": 0, "c": 0, "mpy": 0}, (wrong, accepted)
    assert accepted["c"] == accepted["mpy"] > 10_000  # truncated at CR, concatenated: some are whole


@pytest.mark.slow
@pytest.mark.parametrize(
    "body",
    [
        "QRF,1,2,3,+1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,3, 1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,3,1.e5,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,3,01.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,3,-0.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,3,-110.1\r,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,3,1.0,0.0,1.0,-180.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,3,1.0,0.0,1.0,0.00,90.01,0.00,,,,,,,OK",
        "QRF,1,2,3,1.0,0.0,1.0,0.00,0.00,0.00,-0.1,,,,,,OK",
        "QRF,1,2,3,9999999.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,,1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",
        "QRF,1,2,3,,,,,,,,,,,,,OK",
        "QRF,1,2,3,1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,NOQR",
        "QRF,65536,2,3,,,,,,,,,,,,,NOQR",
        "QRF,1,4294967296,3,,,,,,,,,,,,,NOQR",
        "QRF,1,2,3,,,,,,,,,,,,NOQR",
        "QRM,1,2,1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,101,OK",
        "QRA,PING,ERR",
        "QRA,PING",
    ],
)
def test_both_parsers_reject_every_number_and_field_outside_the_grammar(body, c_parser, mpy):
    data = body.encode()
    line = b"$%s*%04X\r\n" % (data, crc16(data))
    assert decode_codec(line) == [] and decode_mpy(mpy, line) == []
    assert run_c(c_parser, line)[-1].startswith("ERR")


def test_both_write_commands_qrfield_reads_with_the_right_crc(c_parser, mpy):
    done = subprocess.run([str(c_parser), "--command", "MEAS", "10"], capture_output=True, timeout=20)
    assert done.stdout == command_line("MEAS", "10") == mpy.command("MEAS", 10)
    assert mpy.command("PING") == command_line("PING") and mpy.crc16(b"123456789") == 0x29B1
    decoder = codec.FrameDecoder()
    assert decoder.feed(done.stdout) == [codec.ControllerCommand("QRC", ("MEAS", "10"))]
