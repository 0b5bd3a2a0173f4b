"""Serial frames to the gripper controller: encoding and a robust decoder (no I/O, no pyserial).

The frame is fixed in docs/conventions.md ("Serial frames"), one ASCII line per frame, NMEA style::

    $QRF,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<status>*<CS>\\r\\n

- ``seq``: 0..65535, +1 per frame written to the line, wraps 65535 -> 0 (a gap means a lost line).
- ``t_ms``: integer milliseconds since the stream started: the capture time of the pose. Limited to
  0..4294967295 (fits a uint32 on a microcontroller); the link wraps it after 49.7 days.
- ``x, y, z``: the QR centre in the camera frame, millimetres, 1 decimal.
- ``alpha, beta, gamma``: R = Rx(alpha) Ry(beta) Rz(gamma), degrees, 2 decimals.
- ``status``: ``OK`` (pose fields filled), ``NOQR`` (no code seen: pose fields empty), ``NOCONV``
  (solver did not converge: pose fields empty), ``STALE`` (our decision: nothing new arrived for a
  while, so the link repeats the last frame's ``t_ms`` and pose fields unchanged, filled if that frame
  was OK, empty otherwise, with a new ``seq``; the controller learns "no news since t_ms").
- ``CS``: two uppercase hex digits, XOR of every byte between ``$`` and ``*`` (both excluded).

Number formatting (our decisions): values are rounded by Python's ``format`` (correctly rounded from
the binary value, exact ties to even); a value that rounds to zero is written without a sign ("0.0",
never "-0.0"), so equal poses give equal bytes and a controller never sees a negative zero; an angle
that rounds to -180.00 is written 180.00 (docs/conventions.md's range for alpha and gamma is (-180, 180]).
Positions must lie within +-999999.9 mm (our limit) and angles within +-180 degrees, so a frame is
at most 86 bytes (:data:`MAX_QRF_LINE` leaves room).

Commands from the controller use the same framing: ``$<TALKER>[,<field>...]*<CS>\\r\\n`` where TALKER
is 1 to 8 characters A-Z/0-9 (not ``QRF``); fields are printable ASCII without ``$ * ,``. The decoder
returns them as :class:`ControllerCommand`; no command is defined yet, so nothing acts on them.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

STATUSES = ("OK", "NOQR", "NOCONV", "STALE")
SEQ_MODULUS = 65536
T_MS_MODULUS = 2**32
MAX_POSITION_MM = 999999.9
MAX_ANGLE_DEG = 180.0
# Longest frame: $QRF,65535,4294967295,-999999.9 x3,-180.00 x3,STALE*CS\r\n = 86 bytes.
MAX_QRF_LINE = 96
# Longest line the decoder keeps (frames and controller commands); longer lines are dropped.
MAX_LINE_BYTES = 256
_TALKER = re.compile(rb"[A-Z0-9]{1,8}")
_UINT = re.compile(r"[0-9]{1,10}")
_NUMBER = re.compile(r"-?[0-9]{1,7}(\.[0-9]{1,6})?")


class FrameError(ValueError):
    """A frame could not be encoded from the values given; the message names the value."""


class PoseValueError(FrameError):
    """The pose has the right shape but a value is not finite or out of range (see MAX_*)."""


def checksum(body: bytes) -> int:
    """XOR of the bytes of ``body`` (the text between '$' and '*')."""
    value = 0
    for byte in body:
        value ^= byte
    return value


def _format_fixed(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]  # -0.0 -> 0.0: see the module docstring
    return text


Triplet = tuple[float, ...]


def _as_triplet(values: Sequence[float] | np.ndarray, name: str, unit: str, limit: float) -> Triplet:
    # Plain floats, not numpy: this runs once per frame and numpy's per-call overhead dominated it.
    if isinstance(values, np.ndarray):
        if values.shape != (3,):
            raise FrameError(f"{name}: expected shape (3,) in {unit}, got shape {values.shape}")
        values = values.tolist()
    try:
        triplet = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise FrameError(f"{name}: expected 3 numbers in {unit}, got {values!r}") from None
    if len(triplet) != 3:
        raise FrameError(f"{name}: expected shape (3,) in {unit}, got {len(triplet)} values")
    if not all(math.isfinite(v) for v in triplet):
        raise PoseValueError(f"{name}: values must be finite, got {list(triplet)} {unit}")
    if any(abs(v) > limit for v in triplet):
        raise PoseValueError(f"{name}: values must lie within +-{limit} {unit}, got {list(triplet)}")
    return triplet


def check_pose_fields(
    status: str,
    position_mm: Sequence[float] | np.ndarray | None,
    angles_deg: Sequence[float] | np.ndarray | None,
) -> tuple[Triplet | None, Triplet | None]:
    """Validate status and pose for one frame; returns (position, angles) as 3-tuples of floats or Nones.

    OK needs both position (x, y, z in mm, camera frame) and angles (alpha, beta, gamma in degrees);
    NOQR and NOCONV need both None; STALE takes both or neither. Raises FrameError otherwise.
    """
    if status not in STATUSES:
        raise FrameError(f"status must be one of {', '.join(STATUSES)}, got {status!r}")
    given = (position_mm is not None, angles_deg is not None)
    if given[0] != given[1]:
        raise FrameError(f"status {status}: give both position_mm and angles_deg or neither")
    if status == "OK" and not given[0]:
        raise FrameError("status OK needs position_mm (x, y, z) and angles_deg (alpha, beta, gamma)")
    if status in ("NOQR", "NOCONV") and given[0]:
        raise FrameError(f"status {status} has empty pose fields: pass position_mm=None, angles_deg=None")
    if not given[0]:
        return None, None
    position = _as_triplet(position_mm, "position_mm", "mm", MAX_POSITION_MM)
    angles = _as_triplet(angles_deg, "angles_deg", "degrees", MAX_ANGLE_DEG + 0.004)
    return position, angles


def _check_uint(value: int, name: str, modulus: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise FrameError(f"{name} must be a whole number, got {value!r}")
    if not 0 <= int(value) < modulus:
        raise FrameError(f"{name} must be in 0..{modulus - 1}, got {value}")
    return int(value)


def encode_frame(
    seq: int,
    t_ms: int,
    position_mm: Sequence[float] | np.ndarray | None,
    angles_deg: Sequence[float] | np.ndarray | None,
    status: str,
) -> bytes:
    """One ``$QRF`` line with checksum and CRLF, per docs/conventions.md.

    seq: 0..65535; t_ms: 0..2**32-1 integer ms since the stream started (capture time);
    position_mm: (x, y, z) of the QR centre in the camera frame, mm; angles_deg: (alpha, beta,
    gamma), degrees; status: OK / NOQR / NOCONV / STALE (see :func:`check_pose_fields`).
    Raises FrameError (a ValueError) naming the bad value.
    """
    seq = _check_uint(seq, "seq", SEQ_MODULUS)
    t_ms = _check_uint(t_ms, "t_ms", T_MS_MODULUS)
    position, angles = check_pose_fields(status, position_mm, angles_deg)
    if position is None or angles is None:
        pose = ",,,,,"
    else:
        angle_texts = ["180.00" if (t := _format_fixed(v, 2)) == "-180.00" else t for v in angles]
        pose = ",".join([_format_fixed(v, 1) for v in position] + angle_texts)
    body = f"QRF,{seq},{t_ms},{pose},{status}".encode("ascii")
    return b"$%s*%02X\r\n" % (body, checksum(body))


def encode_command(talker: str, *fields: str) -> bytes:
    """A controller command line ``$TALKER,field,...*CS\\r\\n`` (for controllers' tests and tools)."""
    if (
        not isinstance(talker, str)
        or not _TALKER.fullmatch(talker.encode("ascii", "replace"))
        or talker == "QRF"
    ):
        raise FrameError(f"talker must be 1-8 characters A-Z/0-9 other than QRF, got {talker!r}")
    for f in fields:
        if not isinstance(f, str) or any(c in f for c in "$*,\r\n") or not f.isascii() or not f.isprintable():
            raise FrameError(f"command field must be printable ASCII without $ * , : got {f!r}")
    body = ",".join((talker, *fields)).encode("ascii")
    line = b"$%s*%02X\r\n" % (body, checksum(body))
    if len(line) > MAX_LINE_BYTES:
        raise FrameError(
            f"command is {len(line)} bytes, longer than the {MAX_LINE_BYTES} bytes a decoder keeps"
        )
    return line


@dataclass(frozen=True)
class QrfFrame:
    """A decoded pose frame: position in mm (camera frame), angles in degrees, or None when empty."""

    seq: int
    t_ms: int
    position_mm: tuple[float, float, float] | None
    angles_deg: tuple[float, float, float] | None
    status: str


@dataclass(frozen=True)
class ControllerCommand:
    """A decoded line from the controller: ``$TALKER,fields...*CS`` (checksum verified)."""

    talker: str
    fields: tuple[str, ...]


@dataclass
class DecoderCounters:
    """What the decoder saw besides good lines. Every byte received ends up in exactly one place."""

    frames: int = 0  # good $QRF frames
    commands: int = 0  # good controller lines
    bad_checksum: int = 0  # complete line whose checksum does not match
    truncated: int = 0  # line cut short: no '*CS' before its end, or a new '$' began inside it
    malformed: int = 0  # checksum right but content wrong (field count, numbers, status, talker)
    overlong: int = 0  # line longer than MAX_LINE_BYTES, dropped
    garbage_bytes: int = 0  # bytes outside any line (CR/LF between lines are not counted)
    notes: list[str] = field(default_factory=list)  # the last few problems, for tools

    def as_dict(self) -> dict[str, int]:
        return {k: v for k, v in self.__dict__.items() if k != "notes"}


class FrameDecoder:
    """Split a byte stream into lines and decode them; never raises, memory bounded.

    ``feed(data)`` returns the :class:`QrfFrame` and :class:`ControllerCommand` items completed by
    ``data``. Accepted: a line starts at '$' and ends at LF (a CR before it is optional); the
    checksum may be upper or lower case hex. A '$' inside a line starts a new line (the cut line
    counts as truncated), so one lost LF costs one frame only. The partial line kept between calls
    never exceeds ``max_line`` bytes: a longer line is counted as overlong and its bytes as garbage
    until the next '$'.
    """

    MAX_NOTES = 20

    def __init__(self, max_line: int = MAX_LINE_BYTES) -> None:
        self.max_line = int(max_line)
        self.counters = DecoderCounters()
        self._line: bytearray | None = None  # bytes of the current line, from '$', or None between lines

    @property
    def buffered(self) -> int:
        """Bytes of the incomplete line held between calls (always <= max_line)."""
        return 0 if self._line is None else len(self._line)

    def discard_partial(self) -> None:
        """Forget an incomplete line (e.g. after the port was reopened); it counts as truncated."""
        if self._line is not None:
            self.counters.truncated += 1
            self._line = None

    def _note(self, text: str) -> None:
        notes = self.counters.notes
        notes.append(text)
        if len(notes) > self.MAX_NOTES:
            del notes[: len(notes) - self.MAX_NOTES]

    def _garbage(self, chunk: bytes) -> None:
        self.counters.garbage_bytes += len(chunk) - chunk.count(b"\r") - chunk.count(b"\n")

    def feed(self, data: bytes | bytearray | memoryview) -> list[QrfFrame | ControllerCommand]:
        out: list[QrfFrame | ControllerCommand] = []
        if not isinstance(data, (bytes, bytearray, memoryview)):  # never raise, whatever it is
            self._note(f"ignored non-bytes input {type(data).__name__}")
            return out
        try:
            data = bytes(data)
        except Exception:  # e.g. a released memoryview
            self._note("ignored unreadable buffer")
            return out
        i, n = 0, len(data)
        while i < n:
            if self._line is None:
                start = data.find(b"$", i)
                if start < 0:
                    self._garbage(data[i:])
                    break
                self._garbage(data[i:start])
                self._line = bytearray(b"$")
                i = start + 1
                continue
            newline = data.find(b"\n", i)
            dollar = data.find(b"$", i)
            ends = [k for k in (newline, dollar) if k >= 0]
            end = min(ends) if ends else n
            chunk = data[i:end]
            if len(self._line) + len(chunk) > self.max_line:
                self.counters.overlong += 1
                self._note(f"line longer than {self.max_line} bytes dropped")
                self._garbage(bytes(self._line) + chunk)
                self._line = None
                i = end if end == dollar else min(end + 1, n) if end == newline else n
                continue
            self._line += chunk
            if end == n:
                break
            line = bytes(self._line)
            self._line = None
            if end == dollar:  # a new line began before this one ended
                self.counters.truncated += 1
                self._note(f"truncated {line[:40]!r}")
                i = end
                continue
            i = end + 1
            item = self._decode_line(line[:-1] if line.endswith(b"\r") else line)
            if item is not None:
                out.append(item)
        return out

    def _decode_line(self, line: bytes) -> QrfFrame | ControllerCommand | None:
        star = line.rfind(b"*")
        if star < 0 or len(line) - star - 1 < 2:
            self.counters.truncated += 1
            self._note(f"no checksum in {line[:40]!r}")
            return None
        cs_text = line[star + 1 :]
        body = line[1:star]
        try:
            expected = int(cs_text.decode("ascii"), 16) if len(cs_text) == 2 and cs_text.isalnum() else -1
        except ValueError:
            expected = -1
        if expected < 0:
            self.counters.malformed += 1
            self._note(f"checksum field {cs_text[:8]!r} is not two hex digits")
            return None
        actual = checksum(body)
        if actual != expected:
            self.counters.bad_checksum += 1
            self._note(f"bad checksum {expected:02X} (computed {actual:02X}) in {line[:40]!r}")
            return None
        try:
            text = body.decode("ascii")
            if not text.isprintable():
                raise ValueError("non-printable characters")
            parts = text.split(",")
            if parts[0] == "QRF":
                item: QrfFrame | ControllerCommand = _parse_qrf(parts)
                self.counters.frames += 1
            else:
                if not _TALKER.fullmatch(parts[0].encode("ascii")):
                    raise ValueError(f"talker {parts[0]!r} is not 1-8 characters A-Z/0-9")
                item = ControllerCommand(parts[0], tuple(parts[1:]))
                self.counters.commands += 1
            return item
        except ValueError as exc:  # includes UnicodeDecodeError
            self.counters.malformed += 1
            self._note(f"malformed {line[:40]!r}: {exc}")
            return None


def _parse_number(text: str, name: str) -> float:
    if not _NUMBER.fullmatch(text):
        raise ValueError(f"{name} {text!r} is not a decimal number")
    return float(text)


def _parse_qrf(parts: list[str]) -> QrfFrame:
    if len(parts) != 10:
        raise ValueError(f"QRF frame has {len(parts)} fields, expected 10")
    _, seq_text, t_text, *pose_text, status = parts
    if not _UINT.fullmatch(seq_text) or int(seq_text) >= SEQ_MODULUS:
        raise ValueError(f"seq {seq_text!r} is not in 0..65535")
    if not _UINT.fullmatch(t_text) or int(t_text) >= T_MS_MODULUS:
        raise ValueError(f"t_ms {t_text!r} is not in 0..{T_MS_MODULUS - 1}")
    if status not in STATUSES:
        raise ValueError(f"status {status!r} is not one of {', '.join(STATUSES)}")
    empty = all(p == "" for p in pose_text)
    if empty and status != "OK":
        return QrfFrame(int(seq_text), int(t_text), None, None, status)
    if status in ("NOQR", "NOCONV"):
        raise ValueError(f"status {status} must have empty pose fields")
    names = ("x", "y", "z", "alpha", "beta", "gamma")
    values = [_parse_number(p, name) for p, name in zip(pose_text, names, strict=True)]
    if not all(math.isfinite(v) for v in values):
        raise ValueError("pose values must be finite")
    return QrfFrame(
        int(seq_text),
        int(t_text),
        (values[0], values[1], values[2]),
        (values[3], values[4], values[5]),
        status,
    )
