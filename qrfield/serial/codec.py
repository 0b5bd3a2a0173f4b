"""The serial line format, protocol 2: encode and decode every line, CRC-16, number grammar (no I/O).

The only place that knows the format, fixed in docs/conventions.md ("Serial protocol 2")::

    $QRF,<seq>,<t_ms>,<age_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,<status>*<CRC>\\r\\n
    $QRM,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,<n_used>,<status>*<CRC>\\r\\n
    $QRA,<command>,<field>[,<field>...]*<CRC>\\r\\n        (OK / ERR,<reason> / HELLO's QRF2,...)
    $QRC,<command>[,<arg>...]*<CRC>\\r\\n                 (from the controller)

- CRC: CRC-16/CCITT-FALSE (polynomial 0x1021, initial 0xFFFF, no reflection, no final XOR; check
  value of "123456789" 0x29B1) over the bytes between ``$`` and ``*``, 4 uppercase hex digits
  (:func:`crc16`, the standard library's ``binascii.crc_hqx``).
- x, y, z: the QR centre in the camera frame, mm, 1 decimal; alpha, beta, gamma: R = Rx Ry Rz,
  degrees, 2 decimals (alpha, gamma in (-180, 180], beta in [-90, 90]); sx..sgamma: the standard
  uncertainty (1 sigma) in the same units and decimals.
- A line is at most :data:`MAX_LINE_BYTES` (160) bytes with its CR LF.

Number grammar, written and read (our decisions, the same in assets/qrf_parser.c and .py):
integers ``0`` or ``[1-9][0-9]*`` (no sign, no leading zero); fixed-point numbers ``-?`` then
``0`` or ``[1-9][0-9]*``, a point and exactly 1 (mm) or 2 (degrees) decimals; no ``+``, no
spaces, no exponent, never ``-0.0`` (a value that rounds to zero is written ``0.0``). Values are
rounded by Python's ``format`` (correctly rounded, ties to even); an angle that rounds to -180.00 is
written 180.00. Limits: positions within +-999999.9 mm, position sigmas 0..999999.9 mm, angle
sigmas 0..999.99 degrees (a larger sigma is written as the limit: "at least this uncertain");
seq < 65536; t_ms and age_ms < 2**32.

Our decision where the conventions leave room: a pose's sigma that is unknown (NaN: beta at +-90
degrees, a solver without corner covariances) is written as an empty field beside the filled pose;
a controller treats an empty sigma as "do not rely on this axis".

The decoder (:class:`FrameDecoder`) reads a byte stream of any of these lines; a line ends at LF
or CR (a CR LF pair ends one line), a ``$`` starts a new one, and a line that is too long, has no
valid CRC or a field out of grammar is never returned as data (counted, and returned as a
:class:`RejectedLine` when asked, so the controller's side can answer ``$QRA,?,ERR,CRC``).
"""

from __future__ import annotations

import binascii
import math
import numbers
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from qrfield.geometry import ANGLE_NAMES, POSITION_NAMES
from qrfield.status import QRF_POSE_STATUSES, QRF_STATUSES, QRM_STATUSES, WireStatus

#: The protocol's name in HELLO's answer.
PROTOCOL = "QRF2"
#: The statuses of a $QRF line; those with the pose filled; a $QRM answer's statuses.
FRAME_STATUSES = tuple(str(s) for s in QRF_STATUSES)
POSE_STATUSES = tuple(str(s) for s in QRF_STATUSES if s in QRF_POSE_STATUSES)
MEAS_STATUSES = tuple(str(s) for s in QRM_STATUSES)
#: Statuses whose age_ms may be empty (no frame was ever captured).
AGELESS_STATUSES = (WireStatus.STALE.value, WireStatus.NOSRC.value)
FRAME_TALKER, MEASUREMENT_TALKER, ANSWER_TALKER, COMMAND_TALKER = "QRF", "QRM", "QRA", "QRC"
OWN_TALKERS = (FRAME_TALKER, MEASUREMENT_TALKER, ANSWER_TALKER)
#: The command field of an answer to a line that could not be read.
UNKNOWN_COMMAND = "?"
#: Longest line, CR LF included (docs/conventions.md), bytes.
MAX_LINE_BYTES = 160
#: Longest reason of an ERR answer and longest other answer field, bytes.
MAX_REASON_BYTES = 40
MAX_FIELD_BYTES = 40
#: An answer carries 1..MAX_ANSWER_FIELDS fields after its command; a command name 1..16 characters.
MAX_ANSWER_FIELDS = 8
MAX_COMMAND_BYTES = 16
SEQ_MODULUS = 65536
T_MS_MODULUS = 2**32
MAX_POSITION_MM = 999999.9
MAX_STD_MM = 999999.9
MAX_STD_DEG = 999.99
#: Why a line was rejected (:class:`RejectedLine`).
REJECT_CRC, REJECT_LENGTH, REJECT_FORMAT = "CRC", "LENGTH", "FORMAT"

_TALKER = re.compile(r"[A-Z0-9]{1,8}")
_COMMAND = re.compile(r"[A-Za-z0-9]{1,16}")
_ANSWER_COMMAND = re.compile(r"[A-Z0-9]{1,16}|\?")
_UINT = re.compile(r"0|[1-9][0-9]{0,9}")
_FIXED = {
    1: re.compile(r"-?(?:0|[1-9][0-9]{0,5})\.[0-9]"),
    2: re.compile(r"-?(?:0|[1-9][0-9]{0,2})\.[0-9]{2}"),
}
_HEX4 = re.compile(rb"[0-9A-Fa-f]{4}")

Triplet = tuple[float, float, float]
Sigmas = tuple[float | None, float | None, float | None]


class FrameError(ValueError):
    """A line could not be encoded from the values given; the message names the value."""


class PoseValueError(FrameError):
    """The pose has the right shape but a value is not finite or out of range."""


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (poly 0x1021, init 0xFFFF, no reflection, no final XOR)."""
    return binascii.crc_hqx(data, 0xFFFF)


# ------------------------------------------------------------------------------------ numbers
def _fixed(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]  # never -0.0: equal poses give equal bytes
    return text


def _triplet(values: Sequence[float] | np.ndarray, name: str, unit: str) -> Triplet:
    # Plain floats, not numpy: this runs once per line and numpy's per-call overhead dominated it.
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
    return triplet  # type: ignore[return-value]


def _sigmas(values: Sequence[float | None] | np.ndarray | None, name: str, unit: str) -> Sigmas:
    """Three sigmas: None or NaN (or a negative value) is unknown; above the limit is the limit."""
    if values is None:
        return (None, None, None)
    raw = values.tolist() if isinstance(values, np.ndarray) else list(values)
    if len(raw) != 3:
        raise FrameError(f"{name}: expected 3 standard uncertainties in {unit}, got {len(raw)}")
    out: list[float | None] = []
    for v in raw:
        try:
            f = math.nan if v is None else float(v)
        except (TypeError, ValueError):
            raise FrameError(f"{name}: expected numbers in {unit}, got {values!r}") from None
        out.append(None if math.isnan(f) or f < 0 else f)
    return tuple(out)  # type: ignore[return-value]


@dataclass(frozen=True)
class WirePose:
    """A pose as a line carries it, checked and rounded to the line's decimals.

    position_mm: x, y, z (camera frame, mm, 1 decimal); angles_deg: alpha, beta, gamma (degrees, 2
    decimals); std_position_mm / std_angles_deg: the standard uncertainties, each None when unknown.
    ``texts``: the 12 fields as written. Make it with :func:`wire_pose`.
    """

    position_mm: Triplet
    angles_deg: Triplet
    std_position_mm: Sigmas
    std_angles_deg: Sigmas
    texts: tuple[str, ...]


def wire_pose(
    position_mm: Sequence[float] | np.ndarray,
    angles_deg: Sequence[float] | np.ndarray,
    std_position_mm: Sequence[float | None] | np.ndarray | None = None,
    std_angles_deg: Sequence[float | None] | np.ndarray | None = None,
) -> WirePose:
    """Check and round a pose for the line (see the module doc for the limits).

    Raises FrameError for a wrong shape or type, PoseValueError (a FrameError) for a value that is
    not finite or out of range after rounding: a position beyond +-999999.9 mm, alpha or gamma
    outside (-180, 180], beta outside [-90, 90] degrees.
    """
    position = _triplet(position_mm, "position_mm", "mm")
    angles = _triplet(angles_deg, "angles_deg", "degrees")
    spos = _sigmas(std_position_mm, "std_position_mm", "mm")
    sang = _sigmas(std_angles_deg, "std_angles_deg", "degrees")
    if not all(math.isfinite(v) for v in position + angles):
        raise PoseValueError(f"pose values must be finite, got {list(position)} mm, {list(angles)} degrees")
    texts = [_fixed(v, 1) for v in position]
    if any(abs(float(t)) > MAX_POSITION_MM for t in texts):
        raise PoseValueError(f"position_mm must lie within +-{MAX_POSITION_MM} mm, got {list(position)}")
    for k, v in enumerate(angles):
        text = _fixed(v, 2)
        if text == "-180.00" and k != 1:
            text = "180.00"
        a = float(text)
        low, high = (-90.0, 90.0) if k == 1 else (-180.0, 180.0)
        if not (low <= a <= high) or (k != 1 and a == -180.0):
            span = "[-90, 90]" if k == 1 else "(-180, 180]"
            raise PoseValueError(f"{ANGLE_NAMES[k]} must lie in {span} degrees, got {v}")
        texts.append(text)
    for sigmas, decimals, limit in ((spos, 1, MAX_STD_MM), (sang, 2, MAX_STD_DEG)):
        texts += ["" if s is None else _fixed(min(s, limit), decimals) for s in sigmas]
    values = [float(t) if t else None for t in texts]
    return WirePose(
        tuple(values[0:3]),  # type: ignore[arg-type]
        tuple(values[3:6]),  # type: ignore[arg-type]
        tuple(values[6:9]),  # type: ignore[arg-type]
        tuple(values[9:12]),  # type: ignore[arg-type]
        tuple(texts),
    )


def _uint(value: int | None, name: str, modulus: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise FrameError(f"{name} must be a whole number, got {value!r}")
    if not 0 <= int(value) < modulus:
        raise FrameError(f"{name} must be in 0..{modulus - 1}, got {value}")
    return int(value)


# ------------------------------------------------------------------------------------ encoding
def _line(body: str) -> bytes:
    data = body.encode("ascii")
    line = b"$%s*%04X\r\n" % (data, crc16(data))
    if len(line) > MAX_LINE_BYTES:
        raise FrameError(f"line is {len(line)} bytes, longer than the {MAX_LINE_BYTES} bytes allowed")
    return line


def encode_frame(seq: int, t_ms: int, age_ms: int | None, status: str, pose: WirePose | None = None) -> bytes:
    """One ``$QRF`` line with CRC and CR LF (docs/conventions.md).

    seq 0..65535; t_ms 0..2**32-1, ms since the stream started; age_ms 0..2**32-1 ms (None only for
    STALE and NOSRC when no frame was ever captured); status one of :data:`FRAME_STATUSES`; pose
    (:func:`wire_pose`) given for OK, AMBIG and SIM only. Raises FrameError naming what is wrong.
    """
    seq = _uint(seq, "seq", SEQ_MODULUS)
    t_ms = _uint(t_ms, "t_ms", T_MS_MODULUS)
    if status not in FRAME_STATUSES:
        raise FrameError(f"status must be one of {', '.join(FRAME_STATUSES)}, got {status!r}")
    if age_ms is None:
        if status not in AGELESS_STATUSES:
            raise FrameError(f"status {status} needs age_ms (only STALE and NOSRC may have none)")
        age = ""
    else:
        age = str(_uint(age_ms, "age_ms", T_MS_MODULUS))
    if (pose is not None) != (status in POSE_STATUSES):
        need = "needs a pose" if pose is None else "has empty pose fields: give no pose"
        raise FrameError(f"status {status} {need}")
    fields = ",".join(pose.texts) if pose is not None else "," * 11
    return _line(f"{FRAME_TALKER},{seq},{t_ms},{age},{fields},{status}")


def encode_measurement(
    seq: int, t_ms: int, status: str, pose: WirePose | None = None, n_used: int | None = None
) -> bytes:
    """One ``$QRM`` answer to ``MEAS,n``: the mean pose and its standard uncertainty of the mean
    (``pose``, :func:`wire_pose`) and n_used 1..100 for OK, AMBIG and SIM; NOQR, NOCONV, NOSRC and
    TIMEOUT with every number field empty. seq 0..65535, t_ms 0..2**32-1. Raises FrameError."""
    seq = _uint(seq, "seq", SEQ_MODULUS)
    t_ms = _uint(t_ms, "t_ms", T_MS_MODULUS)
    if status not in MEAS_STATUSES:
        raise FrameError(f"measurement status must be one of {', '.join(MEAS_STATUSES)}, got {status!r}")
    if status in POSE_STATUSES:
        if pose is None or n_used is None:
            raise FrameError(f"status {status} needs the mean pose and n_used")
        n = _uint(n_used, "n_used", 101)
        if n < 1:
            raise FrameError("n_used must be 1..100 for a mean pose")
        fields = f"{','.join(pose.texts)},{n}"
    else:
        if pose is not None or n_used is not None:
            raise FrameError(f"status {status} has empty number fields: give no pose and no n_used")
        fields = "," * 12
    return _line(f"{MEASUREMENT_TALKER},{seq},{t_ms},{fields},{status}")


def _check_text(text: str, what: str, limit: int, *, empty: bool = True) -> str:
    if not isinstance(text, str):
        raise FrameError(f"{what} must be text, got {text!r}")
    if len(text) > limit or (not empty and not text):
        raise FrameError(f"{what} must be {'0' if empty else '1'}..{limit} characters, got {text!r}")
    if not all(" " <= c <= "~" and c not in "$*," for c in text):
        raise FrameError(f"{what} must be printable ASCII without $ * , : got {text!r}")
    return text


def field_text(text: object, limit: int = MAX_FIELD_BYTES) -> str:
    """``text`` made fit for one field: other characters than printable ASCII without ``$ * ,``
    become ``_``, runs of spaces one space, cut to ``limit`` bytes (a camera's name in HELLO)."""
    clean = "".join(c if " " <= c <= "~" and c not in "$*," else "_" for c in str(text))
    return " ".join(clean.split())[:limit]


def answer_command(name: str) -> str:
    """The command field of an answer to ``name``: upper case if it is 1..16 letters and digits,
    else ``?``."""
    upper = str(name).strip().upper()
    return upper if _ANSWER_COMMAND.fullmatch(upper) else UNKNOWN_COMMAND


def encode_answer(command: str, *fields: str) -> bytes:
    """``$QRA,<command>,<field>,...``: ``encode_answer("PING", "OK")``,
    ``encode_answer("HELLO", "QRF2", ...)``. command: 1..16 of A-Z 0-9, or ``?``; 1..8 fields of at
    most 40 bytes of printable ASCII without ``$ * ,``; an ERR answer has a non-empty reason."""
    if not isinstance(command, str) or not _ANSWER_COMMAND.fullmatch(command):
        raise FrameError(f"an answer's command is 1-16 characters A-Z 0-9 or ?, got {command!r}")
    if not 1 <= len(fields) <= MAX_ANSWER_FIELDS:
        raise FrameError(f"an answer has 1..{MAX_ANSWER_FIELDS} fields after its command, got {len(fields)}")
    for text in fields:
        _check_text(text, "answer field", MAX_FIELD_BYTES)
    if fields[0] == "ERR" and (len(fields) < 2 or not fields[1]):
        raise FrameError("an ERR answer needs a reason")
    return _line(",".join((ANSWER_TALKER, command, *fields)))


def encode_ok(command: str, *values: str) -> bytes:
    """``$QRA,<command>,OK[,<value>...]``."""
    return encode_answer(command, "OK", *values)


def encode_error(command: str, reason: str, *values: str) -> bytes:
    """``$QRA,<command>,ERR,<reason>[,<value>...]``; the reason is made fit (commas become spaces,
    at most 40 bytes)."""
    text = field_text(str(reason).replace(",", " "), MAX_REASON_BYTES) or "error"
    return encode_answer(command, "ERR", text, *values)


def encode_command(command: str, *args: str) -> bytes:
    """A controller's command line ``$QRC,<command>[,<arg>...]*CRC\\r\\n``:
    ``encode_command("MEAS", "10")``. command: 1..16 letters and digits; args printable ASCII
    without ``$ * ,``."""
    if not isinstance(command, str) or not _COMMAND.fullmatch(command):
        raise FrameError(f"a command is 1-16 letters and digits, got {command!r}")
    for text in args:
        _check_text(text, "command argument", MAX_LINE_BYTES)
    return _line(",".join((COMMAND_TALKER, command, *args)))


# ------------------------------------------------------------------------------------ decoded lines
@dataclass(frozen=True)
class QrfFrame:
    """A decoded ``$QRF`` line: mm and degrees; the pose and its sigmas None when empty (each sigma
    None when unknown); age_ms None only for STALE / NOSRC before any frame."""

    seq: int
    t_ms: int
    age_ms: int | None
    position_mm: Triplet | None
    angles_deg: Triplet | None
    std_position_mm: Sigmas | None
    std_angles_deg: Sigmas | None
    status: str


@dataclass(frozen=True)
class QrmMeasurement:
    """A decoded ``$QRM`` answer: the mean pose and its standard uncertainty of the mean (mm,
    degrees), n_used, or None for all of them when the status carries no pose."""

    seq: int
    t_ms: int
    position_mm: Triplet | None
    angles_deg: Triplet | None
    std_position_mm: Sigmas | None
    std_angles_deg: Sigmas | None
    n_used: int | None
    status: str


@dataclass(frozen=True)
class QraAnswer:
    """A decoded ``$QRA`` answer: the command answered and the fields after it (``OK``, ``ERR`` and
    the reason, ``QRF2`` and HELLO's values, ...)."""

    command: str
    fields: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """Not an error (OK, or HELLO's QRF2 answer)."""
        return self.fields[0] != "ERR"

    @property
    def result(self) -> str:
        return self.fields[0]

    @property
    def reason(self) -> str:
        """The reason of an ERR answer, else empty."""
        return self.fields[1] if not self.ok and len(self.fields) > 1 else ""


@dataclass(frozen=True)
class ControllerCommand:
    """A decoded line of another talker (the controller's ``$QRC``): its talker and fields."""

    talker: str
    fields: tuple[str, ...]


@dataclass(frozen=True)
class RejectedLine:
    """A line that could not be read: why (CRC, LENGTH or FORMAT) and its first bytes."""

    reason: str
    text: bytes


Decoded = QrfFrame | QrmMeasurement | QraAnswer | ControllerCommand | RejectedLine


def _number(text: str, decimals: int, name: str, *, signed: bool = True) -> float:
    if not _FIXED[decimals].fullmatch(text) or (text[0] == "-" and (not signed or float(text) == 0.0)):
        raise ValueError(f"{name} {text!r} is not a number with {decimals} decimal(s)")
    return float(text)


def _parse_uint(text: str, name: str, modulus: int) -> int:
    if not _UINT.fullmatch(text) or int(text) >= modulus:
        raise ValueError(f"{name} {text!r} is not a whole number in 0..{modulus - 1}")
    return int(text)


def _parse_pose(texts: Sequence[str]) -> tuple[Triplet, Triplet, Sigmas, Sigmas]:
    position = tuple(_number(t, 1, n) for t, n in zip(texts[0:3], POSITION_NAMES, strict=True))
    angles = tuple(_number(t, 2, n) for t, n in zip(texts[3:6], ANGLE_NAMES, strict=True))
    alpha, beta, gamma = angles
    if not (-180.0 < alpha <= 180.0 and -90.0 <= beta <= 90.0 and -180.0 < gamma <= 180.0):
        raise ValueError(f"angles {angles} out of range")
    spos = tuple(_number(t, 1, "sigma", signed=False) if t else None for t in texts[6:9])
    sang = tuple(_number(t, 2, "sigma", signed=False) if t else None for t in texts[9:12])
    return position, angles, spos, sang  # type: ignore[return-value]


def _head(parts: list[str], statuses: tuple[str, ...]) -> tuple[int, int, str]:
    """seq, t_ms and status of a $QRF or $QRM line (17 fields, the status last)."""
    if len(parts) != 17:
        raise ValueError(f"${parts[0]} has {len(parts)} fields, expected 17")
    status = parts[16]
    if status not in statuses:
        raise ValueError(f"status {status!r} is not one of {', '.join(statuses)}")
    return _parse_uint(parts[1], "seq", SEQ_MODULUS), _parse_uint(parts[2], "t_ms", T_MS_MODULUS), status


def _parse_qrf(parts: list[str]) -> QrfFrame:
    seq, t_ms, status = _head(parts, FRAME_STATUSES)
    if parts[3] == "" and status in AGELESS_STATUSES:
        age = None
    else:
        age = _parse_uint(parts[3], "age_ms", T_MS_MODULUS)
    numbers_ = parts[4:16]
    if status not in POSE_STATUSES:
        if any(numbers_):
            raise ValueError(f"status {status} has empty pose fields")
        return QrfFrame(seq, t_ms, age, None, None, None, None, status)
    return QrfFrame(seq, t_ms, age, *_parse_pose(numbers_), status)


def _parse_qrm(parts: list[str]) -> QrmMeasurement:
    seq, t_ms, status = _head(parts, MEAS_STATUSES)
    if status not in POSE_STATUSES:
        if any(parts[3:16]):
            raise ValueError(f"status {status} has empty number fields")
        return QrmMeasurement(seq, t_ms, None, None, None, None, None, status)
    n_used = _parse_uint(parts[15], "n_used", 101)
    if n_used < 1:
        raise ValueError("n_used must be 1..100")
    return QrmMeasurement(seq, t_ms, *_parse_pose(parts[3:15]), n_used, status)


def _parse_qra(parts: list[str]) -> QraAnswer:
    if not 3 <= len(parts) <= 2 + MAX_ANSWER_FIELDS or not _ANSWER_COMMAND.fullmatch(parts[1]):
        raise ValueError("$QRA is not <command>,<1..8 fields>")
    if any(len(p) > MAX_FIELD_BYTES for p in parts[2:]):
        raise ValueError(f"an answer field is longer than {MAX_FIELD_BYTES} bytes")
    if parts[2] == "ERR" and (len(parts) < 4 or not parts[3]):
        raise ValueError("an ERR answer needs a reason")
    return QraAnswer(parts[1], tuple(parts[2:]))


@dataclass
class DecoderCounters:
    """What the decoder saw. Every byte received ends up in exactly one place."""

    frames: int = 0  # good $QRF lines
    answers: int = 0  # good $QRA and $QRM lines
    commands: int = 0  # good lines of other talkers (the controller's commands)
    bad_checksum: int = 0  # a complete line whose CRC does not match
    truncated: int = 0  # cut short: no '*CRC' before its end, or a new '$' began inside it
    malformed: int = 0  # CRC right but content wrong (field count, number grammar, range, status)
    overlong: int = 0  # longer than MAX_LINE_BYTES, dropped
    garbage_bytes: int = 0  # bytes outside any line (CR and LF between lines are not counted)
    notes: list[str] = field(default_factory=list)  # the last few problems, for tools

    def as_dict(self) -> dict[str, int]:
        return {k: v for k, v in self.__dict__.items() if k != "notes"}


class FrameDecoder:
    """Split a byte stream into lines and decode them; never raises; memory bounded.

    ``feed(data)`` returns the items completed by ``data``. A line starts at ``$`` and ends at LF
    or CR; the CRC's hex digits may be upper or lower case (a controller's printf). A ``$`` inside a
    line starts a new line (the cut one counts as truncated), so a lost line end costs one line.
    The partial line kept between calls never exceeds ``max_line`` - 2 bytes (room for CR LF); a
    longer line is dropped as overlong and its bytes counted as garbage until the next ``$``.
    ``report_rejected``: also return a :class:`RejectedLine` for each line not read (the
    controller's side answers each of them).
    """

    MAX_NOTES = 20

    def __init__(self, max_line: int = MAX_LINE_BYTES, *, report_rejected: bool = False) -> None:
        self.max_line = int(max_line)
        self.report_rejected = report_rejected
        self.counters = DecoderCounters()
        self._line: bytearray | None = None  # bytes of the current line from '$', or None between lines

    @property
    def buffered(self) -> int:
        """Bytes of the incomplete line held between calls (always < max_line)."""
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

    def _reject(self, out: list[Decoded], reason: str, line: bytes, note: str) -> None:
        self._note(f"{note}: {line[:40]!r}")
        if self.report_rejected:
            out.append(RejectedLine(reason, line[:40]))

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
        limit = self.max_line - 2  # the line's bytes before its CR LF
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
            ends = [k for k in (data.find(b"\n", i), data.find(b"\r", i), data.find(b"$", i)) if k >= 0]
            end = min(ends) if ends else n
            chunk = data[i:end]
            if len(self._line) + len(chunk) > limit:
                self.counters.overlong += 1
                self._garbage(bytes(self._line) + chunk)
                self._reject(out, REJECT_LENGTH, bytes(self._line), f"line longer than {self.max_line} bytes")
                self._line = None
                i = end if end == n or data[end] == 0x24 else end + 1
                continue
            self._line += chunk
            if end == n:
                break
            line = bytes(self._line)
            self._line = None
            if data[end] == 0x24:  # '$': a new line began before this one ended
                self.counters.truncated += 1
                self._reject(out, REJECT_CRC, line, "truncated")
                i = end
                continue
            i = end + 1
            item = self._decode_line(line, out)
            if item is not None:
                out.append(item)
        return out

    def _decode_line(self, line: bytes, out: list[Decoded]) -> Decoded | None:
        star = line.rfind(b"*")
        if star < 0 or len(line) - star - 1 != 4 or not _HEX4.fullmatch(line[star + 1 :]):
            self.counters.truncated += 1
            self._reject(out, REJECT_CRC, line, "no *CRC")
            return None
        body = line[1:star]
        expected, actual = int(line[star + 1 :], 16), crc16(body)
        if actual != expected:
            self.counters.bad_checksum += 1
            self._reject(out, REJECT_CRC, line, f"bad CRC {expected:04X} (computed {actual:04X})")
            return None
        try:
            text = body.decode("ascii")
            if not all(" " <= c <= "~" for c in text) or "*" in text:
                raise ValueError("characters other than printable ASCII")
            parts = text.split(",")
            item: Decoded
            if parts[0] == FRAME_TALKER:
                item = _parse_qrf(parts)
                self.counters.frames += 1
            elif parts[0] == MEASUREMENT_TALKER:
                item = _parse_qrm(parts)
                self.counters.answers += 1
            elif parts[0] == ANSWER_TALKER:
                item = _parse_qra(parts)
                self.counters.answers += 1
            else:
                if not _TALKER.fullmatch(parts[0]):
                    raise ValueError(f"talker {parts[0]!r} is not 1-8 characters A-Z 0-9")
                item = ControllerCommand(parts[0], tuple(parts[1:]))
                self.counters.commands += 1
            return item
        except ValueError as exc:  # includes UnicodeDecodeError
            self.counters.malformed += 1
            self._reject(out, REJECT_FORMAT, line, f"malformed ({exc})")
            return None
