"""Independent truth for the serial tests: protocol 2 written from docs/conventions.md alone.

It shares no code with qrfield.serial (its CRC-16 is computed bit by bit here, checked against the
conventions' check value 29B1), so tests compare qrfield's bytes against this. It restates
"Serial protocol 2":

- every line is ``$<body>*<CRC>\\r\\n``, CRC 4 uppercase hex digits, CRC-16/CCITT-FALSE (poly
  0x1021, init 0xFFFF, no reflection, no final XOR) over the bytes between ``$`` and ``*``; a line
  is at most 160 bytes;
- ``$QRF,<seq>,<t_ms>,<age_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<sx>,...,<sgamma>,<status>``:
  seq 0..65535, t_ms and age_ms integers, x, y, z (and sx, sy, sz) with 1 decimal, angles (and
  their sigmas) with 2; status OK, AMBIG or SIM with the pose filled, NOQR, NOCONV, STALE, NOSRC
  with every number field after age_ms empty; age_ms empty only for STALE / NOSRC;
- ``$QRM,<seq>,<t_ms>,<x>..<gamma>,<sx>..<sgamma>,<n_used>,<status>``: OK, AMBIG or SIM filled,
  NOQR, NOCONV, NOSRC or TIMEOUT with the number fields empty;
- ``$QRA,<command>,...``: ``PING,OK``, ``STREAM,OK``, ``RATE,OK,<hz>``, ``HELLO,QRF2,...``,
  ``<command>,ERR,<reason>`` (no commas, at most 40 bytes), ``?,ERR,CRC``, ``?,ERR,OVERFLOW,<n>``;
- commands ``$QRC,<command>[,<arg>...]``.

Our decision, stated in docs/serial.md and checked here: a pose's sigma may be empty (unknown).
"""

from __future__ import annotations

import re

LINE = re.compile(rb"^\$([^$*]*)\*([0-9A-F]{4})\r\n$")
ONE_DECIMAL = re.compile(r"^-?\d+\.\d$")
TWO_DECIMALS = re.compile(r"^-?\d+\.\d\d$")
FILLED = ("OK", "AMBIG", "SIM")
FRAME_EMPTY = ("NOQR", "NOCONV", "STALE", "NOSRC")
MEAS_EMPTY = ("NOQR", "NOCONV", "NOSRC", "TIMEOUT")


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE, bit by bit, as the conventions define it."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


assert crc16(b"123456789") == 0x29B1, "the conventions' check value"


def parse_line(line: bytes) -> list[str]:
    """The comma-separated fields of one full line; asserts the framing, CRC and length."""
    assert len(line) <= 160, f"longer than 160 bytes: {line!r}"
    match = LINE.match(line)
    assert match, f"not a docs/conventions.md line: {line!r}"
    body, crc = match.group(1), int(match.group(2), 16)
    assert crc16(body) == crc, f"CRC wrong in {line!r}"
    return body.decode("ascii").split(",")


POSE_DECIMALS = [ONE_DECIMAL] * 3 + [TWO_DECIMALS] * 3


def _numbers(texts: list[str], patterns: list[re.Pattern], optional: bool = False) -> list[float | None]:
    out: list[float | None] = []
    for text, pattern in zip(texts, patterns, strict=True):
        if optional and text == "":
            out.append(None)
            continue
        assert pattern.match(text), f"{text!r} has the wrong number of decimals"
        out.append(float(text))
    return out


def _pose(numbers: list[str]) -> tuple[list[float], list[float | None]]:
    pose = _numbers(numbers[:6], POSE_DECIMALS)
    sigma = _numbers(numbers[6:12], POSE_DECIMALS, optional=True)
    assert all(s is None or s >= 0 for s in sigma), numbers
    assert -180 < pose[3] <= 180 and -90 <= pose[4] <= 90 and -180 < pose[5] <= 180, numbers
    return pose, sigma  # type: ignore[return-value]


def parse_frame_line(line: bytes) -> dict:
    """Parse one ``$QRF`` line (see the module docstring)."""
    fields = parse_line(line)
    assert fields[0] == "QRF" and len(fields) == 17, line
    _, seq, t_ms, age, *numbers, status = fields
    assert 0 <= int(seq) <= 65535 and int(t_ms) >= 0, line
    assert status in (*FILLED, *FRAME_EMPTY), line
    assert age != "" or status in ("STALE", "NOSRC"), line
    out = {"seq": int(seq), "t_ms": int(t_ms), "age_ms": int(age) if age else None, "status": status}
    out["text"] = numbers
    if status in FILLED:
        out["pose"], out["sigma"] = _pose(numbers)
    else:
        assert all(n == "" for n in numbers), line
        out["pose"] = out["sigma"] = None
    return out


def parse_answer_line(line: bytes) -> dict:
    """Parse one ``$QRA`` or ``$QRM`` line (see the module docstring)."""
    fields = parse_line(line)
    if fields[0] == "QRA":
        assert len(fields) >= 3, line
        out = {"type": "QRA", "command": fields[1], "result": fields[2], "values": fields[3:]}
        if fields[2] == "ERR":
            assert len(fields) >= 4 and 0 < len(fields[3].encode()) <= 40, line
            out["reason"] = fields[3]
        return out
    assert fields[0] == "QRM" and len(fields) == 17, line
    _, seq, t_ms, *numbers, n_used, status = fields
    out = {"type": "QRM", "seq": int(seq), "t_ms": int(t_ms), "status": status}
    if status in FILLED:
        pose, sigma = _pose(numbers)
        out.update(pose=pose, std=sigma, n_used=int(n_used))
        assert 1 <= out["n_used"] <= 100, line
    else:
        assert status in MEAS_EMPTY and all(n == "" for n in numbers) and n_used == "", line
        out.update(pose=None, std=None, n_used=None)
    return out


def command_line(command: str, *args: str) -> bytes:
    """``$QRC,<command>[,<arg>]*CRC\\r\\n``, as a controller writes it."""
    body = ",".join(("QRC", command, *args)).encode("ascii")
    return b"$%s*%04X\r\n" % (body, crc16(body))


def split_lines(data: bytes) -> list[bytes]:
    """Complete CRLF-terminated lines of ``data`` (an incomplete tail is left out)."""
    parts = data.split(b"\r\n")
    return [p + b"\r\n" for p in parts[:-1]]


def frames_and_answers(data: bytes) -> tuple[list[dict], list[dict]]:
    """Every complete line of ``data``, parsed: ($QRF frames, $QRA/$QRM answers)."""
    frames, answers = [], []
    for line in split_lines(data):
        if line.startswith(b"$QRF,"):
            frames.append(parse_frame_line(line))
        else:
            answers.append(parse_answer_line(line))
    return frames, answers
