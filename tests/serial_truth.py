"""Independent truth for the serial tests: the protocol written from docs/conventions.md alone.

It shares no code with qrfield.serial_frames / serial_link / serial_controller, so tests compare
the link's bytes against this. Everything below restates the conventions' serial section:

- every line is ``$<body>*<CS>\\r\\n``, CS two uppercase hex digits, the XOR of every byte between
  ``$`` and ``*``; a line longer than 160 bytes is invalid;
- ``$QRF,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<status>``: seq 0..65535, t_ms an integer,
  x, y, z with 1 decimal, angles with 2; status OK or SIM with the fields filled, NOQR, NOCONV or
  NOSRC with them empty, STALE either way;
- commands ``$QRC,<command>[,<arg>]``; answers ``$QRA,PING,OK``, ``$QRA,STREAM,OK``,
  ``$QRA,<command>,ERR,<reason>`` (no commas, at most 40 bytes) and
  ``$QRM,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,<n_used>,<status>``
  with status OK or SIM and the fields filled (s* in the same units and decimals), or NOQR,
  NOCONV, NOSRC or TIMEOUT with the number fields empty.
"""

from __future__ import annotations

import functools
import operator
import re

LINE = re.compile(rb"^\$([^$*]*)\*([0-9A-F]{2})\r\n$")
ONE_DECIMAL = re.compile(r"^-?\d+\.\d$")
TWO_DECIMALS = re.compile(r"^-?\d+\.\d\d$")
FILLED, EMPTY = ("OK", "SIM"), ("NOQR", "NOCONV", "NOSRC")


def _xor(data: bytes) -> int:
    return functools.reduce(operator.xor, data, 0)


def parse_line(line: bytes) -> list[str]:
    """The comma-separated fields of one full line; asserts the framing, checksum and length."""
    assert len(line) <= 160, f"longer than 160 bytes: {line!r}"
    match = LINE.match(line)
    assert match, f"not a docs/conventions.md line: {line!r}"
    body, cs = match.group(1), int(match.group(2), 16)
    assert _xor(body) == cs, f"checksum wrong in {line!r}"
    return body.decode("ascii").split(",")


def _numbers(texts: list[str], decimals: list[re.Pattern]) -> list[float]:
    for text, pattern in zip(texts, decimals, strict=True):
        assert pattern.match(text), f"{text!r} has the wrong number of decimals"
    return [float(t) for t in texts]


POSE_DECIMALS = [ONE_DECIMAL] * 3 + [TWO_DECIMALS] * 3


def parse_frame_line(line: bytes) -> dict:
    """Parse one ``$QRF`` line (see the module docstring)."""
    fields = parse_line(line)
    assert fields[0] == "QRF" and len(fields) == 10, line
    _, seq, t_ms, *pose, status = fields
    assert 0 <= int(seq) <= 65535 and int(t_ms) >= 0, line
    out = {"seq": int(seq), "t_ms": int(t_ms), "status": status, "text": pose}
    empty = all(p == "" for p in pose)
    assert status in (*FILLED, *EMPTY, "STALE"), line
    assert not (status in FILLED and empty) and not (status in EMPTY and not empty), line
    out["pose"] = None if empty else _numbers(pose, POSE_DECIMALS)
    return out


def parse_answer_line(line: bytes) -> dict:
    """Parse one ``$QRA`` or ``$QRM`` line (see the module docstring)."""
    fields = parse_line(line)
    if fields[0] == "QRA":
        assert len(fields) in (3, 4), line
        if fields[2] == "OK":
            assert len(fields) == 3, line
            return {"type": "QRA", "command": fields[1], "result": "OK"}
        assert fields[2] == "ERR" and len(fields) == 4 and len(fields[3].encode()) <= 40, line
        return {"type": "QRA", "command": fields[1], "result": "ERR", "reason": fields[3]}
    assert fields[0] == "QRM" and len(fields) == 17, line
    _, seq, t_ms, *numbers, n_used, status = fields
    out: dict = {"type": "QRM", "seq": int(seq), "t_ms": int(t_ms), "status": status}
    if status in FILLED:
        values = _numbers(numbers, POSE_DECIMALS + POSE_DECIMALS)
        out.update(pose=values[:6], std=values[6:], n_used=int(n_used))
        assert all(s >= 0 for s in out["std"]) and 1 <= out["n_used"] <= 100, line
    else:
        assert status in (*EMPTY, "TIMEOUT") and all(n == "" for n in numbers) and n_used == "", line
        out.update(pose=None, std=None, n_used=None)
    return out


def command_line(command: str, *args: str) -> bytes:
    """``$QRC,<command>[,<arg>]*CS\\r\\n``, as a controller writes it."""
    body = ",".join(("QRC", command, *args)).encode("ascii")
    return b"$%s*%02X\r\n" % (body, _xor(body))


def split_lines(data: bytes) -> list[bytes]:
    """Complete CRLF-terminated lines of ``data`` (an incomplete tail is left out)."""
    parts = data.split(b"\r\n")
    return [p + b"\r\n" for p in parts[:-1]]


def frames_and_answers(data: bytes) -> tuple[list[dict], list[dict]]:
    """Every complete line of ``data``, parsed: ($QRF frames, $QRA/$QRM answers)."""
    frames, answers = [], []
    for line in split_lines(data):
        (frames if line.startswith(b"$QRF,") else answers).append(
            parse_frame_line(line) if line.startswith(b"$QRF,") else parse_answer_line(line)
        )
    return frames, answers
