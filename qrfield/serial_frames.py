"""Serial frames to the gripper controller: encoding and a robust decoder (no I/O, no pyserial).

The frame is fixed in docs/conventions.md ("Serial frames"), one ASCII line per frame, NMEA style::

    $QRF,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<status>*<CS>\\r\\n

- ``seq``: 0..65535, +1 per frame written to the line, wraps 65535 -> 0 (a gap means a lost line).
- ``t_ms``: integer milliseconds since the stream started: the capture time of the pose. Limited to
  0..4294967295 (fits a uint32 on a microcontroller); the link wraps it after 49.7 days.
- ``x, y, z``: the QR centre in the camera frame, millimetres, 1 decimal.
- ``alpha, beta, gamma``: R = Rx(alpha) Ry(beta) Rz(gamma), degrees, 2 decimals.
- ``status``: ``OK`` (a live camera's pose: fields filled), ``SIM`` (a pose from the virtual bench or
  a recording: fields filled, never to be acted on as a measurement), ``NOQR`` (no code seen: pose
  fields empty), ``NOCONV`` (solver did not converge: pose fields empty), ``NOSRC`` (no camera frames:
  pose fields empty, at least once a second while the source is down), ``STALE`` (our decision:
  nothing new arrived for a while, so the link repeats the last frame's ``t_ms`` and pose fields
  unchanged, filled if that frame had a pose, empty otherwise, with a new ``seq``; the controller
  learns "no news since t_ms").
- ``CS``: two uppercase hex digits, XOR of every byte between ``$`` and ``*`` (both excluded).

Number formatting (our decisions): values are rounded by Python's ``format`` (correctly rounded from
the binary value, exact ties to even); a value that rounds to zero is written without a sign ("0.0",
never "-0.0"), so equal poses give equal bytes and a controller never sees a negative zero; an angle
that rounds to -180.00 is written 180.00 (docs/conventions.md's range for alpha and gamma is (-180, 180]).
Positions must lie within +-999999.9 mm (our limit) and angles within +-180 degrees, so a frame is
at most 86 bytes (:data:`MAX_QRF_LINE` leaves room).

Commands from the controller use the same framing: ``$<TALKER>[,<field>...]*<CS>\\r\\n`` where TALKER
is 1 to 8 characters A-Z/0-9; fields are printable ASCII without ``$ * ,``. The controller's talker
is ``QRC`` (``$QRC,PING``, ``$QRC,STREAM,ON``, ``$QRC,MEAS,10``); the answers are ``$QRA`` lines
(:func:`encode_answer`) and ``$QRM`` measurements (:func:`encode_measurement`). The decoder returns
``$QRF`` as :class:`QrfFrame`, ``$QRM`` as :class:`QrmMeasurement`, ``$QRA`` as :class:`QraAnswer`
and any other talker as :class:`ControllerCommand` (:mod:`qrfield.serial_controller` acts on them).
A line is at most :data:`MAX_LINE_BYTES` bytes, CR LF included.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from qrfield.status import QRF_POSE_STATUSES, QRF_STATUSES, QRM_STATUSES, WireStatus

#: The statuses a $QRF frame carries on the wire (qrfield.status: the one home of the words and of
#: the rule from a pipeline result to them, qrfield.status.reported_status / wire_status).
WIRE_STATUSES = tuple(str(s) for s in QRF_STATUSES)
#: Statuses whose pose fields are filled (OK, AMBIG, SIM), empty (NOQR, NOCONV, NOSRC), or either (STALE).
POSE_STATUSES = tuple(str(s) for s in QRF_STATUSES if s in QRF_POSE_STATUSES)
EMPTY_STATUSES = (WireStatus.NOQR.value, WireStatus.NOCONV.value, WireStatus.NOSRC.value)
#: Statuses of a $QRM answer: a mean pose (OK, AMBIG, SIM) or why there is none.
MEAS_STATUSES = tuple(str(s) for s in QRM_STATUSES)
#: The controller's talker, and the talkers of our answers.
COMMAND_TALKER, ANSWER_TALKER, MEASUREMENT_TALKER = "QRC", "QRA", "QRM"
#: Longest reason text in a $QRA ERR answer (docs/conventions.md), bytes.
MAX_REASON_BYTES = 40
#: Largest standard deviation a $QRM carries (mm for positions, degrees for angles).
MAX_STD_MM = 999999.9
MAX_STD_DEG = 999.99
SEQ_MODULUS = 65536
T_MS_MODULUS = 2**32
MAX_POSITION_MM = 999999.9
MAX_ANGLE_DEG = 180.0
# Longest frame: $QRF,65535,4294967295,-999999.9 x3,-180.00 x3,STALE*CS\r\n = 86 bytes.
MAX_QRF_LINE = 96
# Longest valid line, CR LF included (docs/conventions.md); the decoder drops longer lines.
MAX_LINE_BYTES = 160
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

    OK and SIM need both position (x, y, z in mm, camera frame) and angles (alpha, beta, gamma in
    degrees); NOQR, NOCONV and NOSRC need both None; STALE takes both or neither. Raises FrameError
    otherwise.
    """
    if status not in WIRE_STATUSES:
        raise FrameError(f"status must be one of {', '.join(WIRE_STATUSES)}, got {status!r}")
    given = (position_mm is not None, angles_deg is not None)
    if given[0] != given[1]:
        raise FrameError(f"status {status}: give both position_mm and angles_deg or neither")
    if status in POSE_STATUSES and not given[0]:
        raise FrameError(f"status {status} needs position_mm (x, y, z) and angles_deg (alpha, beta, gamma)")
    if status in EMPTY_STATUSES and given[0]:
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
    return _line(f"QRF,{seq},{t_ms},{_pose_text(position, angles)},{status}")


def _pose_text(position: Triplet | None, angles: Triplet | None) -> str:
    """x,y,z (1 decimal) and alpha,beta,gamma (2 decimals, -180.00 written 180.00), or 5 commas."""
    if position is None or angles is None:
        return ",,,,,"
    angle_texts = ["180.00" if (t := _format_fixed(v, 2)) == "-180.00" else t for v in angles]
    return ",".join([_format_fixed(v, 1) for v in position] + angle_texts)


def _line(body: str) -> bytes:
    data = body.encode("ascii")
    line = b"$%s*%02X\r\n" % (data, checksum(data))
    if len(line) > MAX_LINE_BYTES:
        raise FrameError(f"line is {len(line)} bytes, longer than the {MAX_LINE_BYTES} bytes allowed")
    return line


def _check_field(text: str, what: str) -> str:
    if (
        not isinstance(text, str)
        or any(c in text for c in "$*,\r\n")
        or not text.isascii()
        or not text.isprintable()
    ):
        raise FrameError(f"{what} must be printable ASCII without $ * , : got {text!r}")
    return text


def encode_answer(command: str, result: str = "OK", reason: str = "") -> bytes:
    """``$QRA,<command>,OK*CS`` or ``$QRA,<command>,ERR,<reason>*CS`` (docs/conventions.md).

    ``reason`` (ERR only): commas become spaces and it is cut to MAX_REASON_BYTES.
    """
    _check_field(command, "command")
    if result == "OK":
        return _line(f"{ANSWER_TALKER},{command},OK")
    if result != "ERR":
        raise FrameError(f"an answer's result is OK or ERR, got {result!r}")
    text = " ".join(reason.replace(",", " ").split())[:MAX_REASON_BYTES] or "error"
    return _line(f"{ANSWER_TALKER},{command},ERR,{_check_field(text, 'reason')}")


def encode_measurement(
    seq: int,
    t_ms: int,
    status: str,
    position_mm: Sequence[float] | np.ndarray | None = None,
    angles_deg: Sequence[float] | np.ndarray | None = None,
    std_position_mm: Sequence[float] | np.ndarray | None = None,
    std_angles_deg: Sequence[float] | np.ndarray | None = None,
    n_used: int | None = None,
) -> bytes:
    """One ``$QRM`` answer to ``MEAS,n`` (docs/conventions.md).

    OK / SIM: the mean position (mm, 1 decimal) and angles (degrees, 2 decimals), their standard
    deviations over the frames (same units and decimals, >= 0) and n_used (1..100); any other
    status (NOQR, NOCONV, NOSRC, TIMEOUT) with every number field after t_ms empty.
    seq: 0..65535 (the answers' own count); t_ms: 0..2**32-1. Raises FrameError.
    """
    seq = _check_uint(seq, "seq", SEQ_MODULUS)
    t_ms = _check_uint(t_ms, "t_ms", T_MS_MODULUS)
    if status not in MEAS_STATUSES:
        raise FrameError(f"measurement status must be one of {', '.join(MEAS_STATUSES)}, got {status!r}")
    parts = (position_mm, angles_deg, std_position_mm, std_angles_deg, n_used)
    if status not in POSE_STATUSES:
        if any(p is not None for p in parts):
            raise FrameError(f"status {status} has empty number fields: pass no pose, deviations or n_used")
        fields = "," * 12
    else:
        if any(p is None for p in parts):
            raise FrameError(f"status {status} needs the mean pose, its deviations and n_used")
        position, angles = check_pose_fields(status, position_mm, angles_deg)
        spos = _as_triplet(std_position_mm, "std_position_mm", "mm", MAX_STD_MM)  # type: ignore[arg-type]
        sang = _as_triplet(std_angles_deg, "std_angles_deg", "degrees", MAX_STD_DEG)  # type: ignore[arg-type]
        if min(spos + sang) < 0:
            raise FrameError(f"standard deviations must be >= 0, got {list(spos + sang)}")
        n = _check_uint(n_used, "n_used", 101)  # type: ignore[arg-type]
        if n < 1:
            raise FrameError("n_used must be 1..100 for a mean pose")
        stds = [_format_fixed(v, 1) for v in spos] + [_format_fixed(v, 2) for v in sang]
        fields = f"{_pose_text(position, angles)},{','.join(stds)},{n}"
    return _line(f"{MEASUREMENT_TALKER},{seq},{t_ms},{fields},{status}")


def encode_command(talker: str, *fields: str) -> bytes:
    """A controller command line ``$TALKER,field,...*CS\\r\\n``: ``encode_command("QRC", "MEAS", "10")``."""
    if (
        not isinstance(talker, str)
        or not _TALKER.fullmatch(talker.encode("ascii", "replace"))
        or talker in ("QRF", ANSWER_TALKER, MEASUREMENT_TALKER)
    ):
        raise FrameError(f"talker must be 1-8 characters A-Z/0-9 other than QRF, QRA, QRM, got {talker!r}")
    for f in fields:
        _check_field(f, "command field")
    return _line(",".join((talker, *fields)))


@dataclass(frozen=True)
class QrfFrame:
    """A decoded pose frame: position in mm (camera frame), angles in degrees, or None when empty."""

    seq: int
    t_ms: int
    position_mm: tuple[float, float, float] | None
    angles_deg: tuple[float, float, float] | None
    status: str


@dataclass(frozen=True)
class QrmMeasurement:
    """A decoded ``$QRM`` answer: the mean pose and its deviations (mm, degrees), or None when empty."""

    seq: int
    t_ms: int
    position_mm: tuple[float, float, float] | None
    angles_deg: tuple[float, float, float] | None
    std_position_mm: tuple[float, float, float] | None
    std_angles_deg: tuple[float, float, float] | None
    n_used: int | None
    status: str


@dataclass(frozen=True)
class QraAnswer:
    """A decoded ``$QRA`` answer: the command answered, OK or ERR, and the reason of an ERR."""

    command: str
    result: str
    reason: str = ""


@dataclass(frozen=True)
class ControllerCommand:
    """A decoded line from the controller: ``$TALKER,fields...*CS`` (checksum verified)."""

    talker: str
    fields: tuple[str, ...]


#: What the decoder returns for one good line.
Decoded = QrfFrame | QrmMeasurement | QraAnswer | ControllerCommand


@dataclass
class DecoderCounters:
    """What the decoder saw besides good lines. Every byte received ends up in exactly one place."""

    frames: int = 0  # good $QRF frames
    answers: int = 0  # good $QRA and $QRM answers
    commands: int = 0  # good lines of other talkers (the controller's commands)
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

    def feed(self, data: bytes | bytearray | memoryview) -> list[Decoded]:
        out: list[Decoded] = []
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
            if len(self._line) + len(chunk) + 1 > self.max_line:  # + 1: the LF that ends it
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

    def _decode_line(self, line: bytes) -> Decoded | None:
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
            item: Decoded
            if parts[0] == "QRF":
                item = _parse_qrf(parts)
                self.counters.frames += 1
            elif parts[0] in (ANSWER_TALKER, MEASUREMENT_TALKER):
                item = _parse_qra(parts) if parts[0] == ANSWER_TALKER else _parse_qrm(parts)
                self.counters.answers += 1
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
    _parse_seq_t(seq_text, t_text)
    if status not in WIRE_STATUSES:
        raise ValueError(f"status {status!r} is not one of {', '.join(WIRE_STATUSES)}")
    empty = all(p == "" for p in pose_text)
    if empty and status not in POSE_STATUSES:
        return QrfFrame(int(seq_text), int(t_text), None, None, status)
    if status in EMPTY_STATUSES:
        raise ValueError(f"status {status} must have empty pose fields")
    values = _parse_numbers(pose_text, ("x", "y", "z", "alpha", "beta", "gamma"))
    return QrfFrame(int(seq_text), int(t_text), values[:3], values[3:], status)  # type: ignore[arg-type]


def _parse_numbers(texts: Sequence[str], names: Sequence[str]) -> tuple[float, ...]:
    values = tuple(_parse_number(p, name) for p, name in zip(texts, names, strict=True))
    if not all(math.isfinite(v) for v in values):
        raise ValueError("values must be finite")
    return values


def _parse_qra(parts: list[str]) -> QraAnswer:
    if len(parts) == 3 and parts[2] == "OK":
        return QraAnswer(parts[1], "OK")
    if len(parts) == 4 and parts[2] == "ERR" and len(parts[3].encode()) <= MAX_REASON_BYTES:
        return QraAnswer(parts[1], "ERR", parts[3])
    raise ValueError("QRA answer is not <command>,OK or <command>,ERR,<reason of at most 40 bytes>")


def _parse_qrm(parts: list[str]) -> QrmMeasurement:
    if len(parts) != 17:
        raise ValueError(f"QRM answer has {len(parts)} fields, expected 17")
    _, seq_text, t_text, *numbers, n_text, status = parts
    seq, t_ms = _parse_seq_t(seq_text, t_text)
    if status not in MEAS_STATUSES:
        raise ValueError(f"measurement status {status!r} is not one of {', '.join(MEAS_STATUSES)}")
    if status not in POSE_STATUSES:
        if any(numbers) or n_text:
            raise ValueError(f"status {status} must have empty number fields")
        return QrmMeasurement(seq, t_ms, None, None, None, None, None, status)
    names = ("x", "y", "z", "alpha", "beta", "gamma", "sx", "sy", "sz", "salpha", "sbeta", "sgamma")
    values = _parse_numbers(numbers, names)
    if not _UINT.fullmatch(n_text) or not 1 <= int(n_text) <= 100:
        raise ValueError(f"n_used {n_text!r} is not in 1..100")
    if min(values[6:]) < 0:
        raise ValueError("standard deviations must be >= 0")
    v = values
    return QrmMeasurement(seq, t_ms, v[0:3], v[3:6], v[6:9], v[9:12], int(n_text), status)  # type: ignore[arg-type]


def _parse_seq_t(seq_text: str, t_text: str) -> tuple[int, int]:
    if not _UINT.fullmatch(seq_text) or int(seq_text) >= SEQ_MODULUS:
        raise ValueError(f"seq {seq_text!r} is not in 0..65535")
    if not _UINT.fullmatch(t_text) or int(t_text) >= T_MS_MODULUS:
        raise ValueError(f"t_ms {t_text!r} is not in 0..{T_MS_MODULUS - 1}")
    return int(seq_text), int(t_text)
