"""Independent truth for the serial tests: a frame parser written from docs/conventions.md alone.

It shares no code with qrfield.serial_link, so tests compare the link's bytes against this.
"""

from __future__ import annotations

import functools
import operator
import re

FRAME = re.compile(rb"^\$(QRF,[^*]*)\*([0-9A-F]{2})\r\n$")


def parse_frame_line(line: bytes) -> dict:
    """Parse one full line ``$QRF,...*CS\\r\\n``; asserts the framing and the XOR checksum."""
    match = FRAME.match(line)
    assert match, f"not a docs/conventions.md frame: {line!r}"
    body, cs = match.group(1), int(match.group(2), 16)
    assert functools.reduce(operator.xor, body, 0) == cs, f"checksum wrong in {line!r}"
    fields = body.decode("ascii").split(",")
    assert len(fields) == 10, line
    _, seq, t_ms, *pose, status = fields
    out = {"seq": int(seq), "t_ms": int(t_ms), "status": status, "text": pose}
    out["pose"] = None if all(p == "" for p in pose) else [float(p) for p in pose]
    return out


def split_lines(data: bytes) -> list[bytes]:
    """Complete CRLF-terminated lines of ``data`` (an incomplete tail is left out)."""
    parts = data.split(b"\r\n")
    return [p + b"\r\n" for p in parts[:-1]]
