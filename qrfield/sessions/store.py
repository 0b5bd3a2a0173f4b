"""Experiment sessions on disk: ``<YYYYmmdd-HHMMSS>-<name>/session.json`` + ``rows.csv``.

Format: docs/conventions.md, "Experiment sessions on disk".

``session.json`` (written atomically: temp file, fsync, os.replace) records the camera model, QR
side, solver and its settings, acceptance criteria, frames per row, app version, operator, notes,
creation time, and the frame the rows' poses are in (``pose_frame``: camera, or tool / base with
the hand-eye calibration that took them there in ``handeye``, docs/handeye.md). ``rows.csv`` is
UTF-8 with a header row: the required columns in the order of docs/conventions.md, then
EXTRA_COLUMNS. Values in mm and degrees with 3 decimals, empty where unknown (no converged frame);
``time`` is local ISO 8601 time with its UTC offset; ``pass`` is 1 or 0; ``x``..``gamma`` are the
means over the converged frames (angles: circular means), ``err_*`` are measured minus ground
truth (angles wrapped to (-180, 180]), ``err_pos`` the Euclidean distance.

Crash safety: each record is one physical line (notes are kept to one line), appended with one
``write`` on an O_APPEND descriptor and fsynced before :meth:`Session.log` reports "logged".
Killing the process at any moment leaves every confirmed row and at most one unfinished last
line, which opening the session moves aside to ``rows.csv.partial-<time>`` with a warning.
A failed write (full disk, lost permission, read-only medium) never raises from ``log``: the
record stays in :attr:`Session.pending` with a message and is written, in order, by
:meth:`Session.retry` or before the next record.

Withdrawal ("undo") never deletes or rewrites a line: it appends a withdrawal record, a line
whose ``row`` is empty, whose ``withdraws`` column holds the number of the withdrawn row and whose
note says so. Row numbers keep counting after withdrawn rows. One process logs to a session at a
time (an advisory lock on rows.csv).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import datetime as dt
import errno
import io
import json
import math
import os
import re
import stat
from array import array
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import qrfield
from qrfield.camera import CameraModel, CameraModelError
from qrfield.files import (
    MAX_FIELD_CHARS,
    Fields,
    FileFormatError,
    check_field_sizes,
    csv_text_reader,
    describe_error,
    make_folder,
    read_json,
)
from qrfield.geometry import ANGLE_NAMES
from qrfield.handeye.setups import FRAMES
from qrfield.limits import SIDE_MM, LimitError
from qrfield.methods import METHODS
from qrfield.sessions.averaging import Measurement
from qrfield.sessions.criteria import AcceptanceCriteria, SessionSettings
from qrfield.sessions.files import FileOps, atomic_write, fsync_dir, unique_path
from qrfield.settings import SettingError, from_dict, to_dict
from qrfield.texts import TextError, check_text

try:  # advisory lock: POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)

#: docs/conventions.md's required columns, in order.
REQUIRED_COLUMNS = (
    "row",
    "time",
    "combo",
    "gt_x",
    "gt_y",
    "gt_z",
    "gt_alpha",
    "gt_beta",
    "gt_gamma",
    "x",
    "y",
    "z",
    "alpha",
    "beta",
    "gamma",
    "n_frames",
    "n_converged",
    "err_pos",
    "err_alpha",
    "err_beta",
    "err_gamma",
    "pass",
    "note",
)
#: Our extra columns: ``std_*`` the frame-to-frame sample standard deviations over the converged
#: frames (mm, deg: how much the frames scattered), mean solver iterations, mean RMS reprojection
#: error (px), the solver method, ``withdraws`` (set only on withdrawal records: the number of the
#: row they withdraw), ``sigma_*`` the mean per-frame uncertainty (mm, deg: each frame's
#: propagated std from its corners, docs/conventions.md "Pose uncertainty"; empty when unknown),
#: ``sem_*`` the standard uncertainty of the row's mean (mm, deg: calibrated on still cards, whose
#: frames share most of their error: qrfield.sessions.averaging, docs/uncertainty.md), ``filtered``
#: 1 when the row's frames were the stream filter's (``--filter-s`` on), else 0, and
#: ``resolved_by_history`` the number of its frames whose flip the stream's history resolved
#: (docs/conventions.md, "The live stream"), and ``n_misfit`` the number of its averaged frames
#: whose pose misfits their corners (``PoseResult.misfit``: chi-square above FIT_CHI2; most of
#: them: the camera model, side or corners are wrong, :attr:`AveragedPose.mostly_misfit`).
EXTRA_COLUMNS = (
    "std_x",
    "std_y",
    "std_z",
    "std_alpha",
    "std_beta",
    "std_gamma",
    "mean_iterations",
    "reprojection_px",
    "method",
    "withdraws",
    "sigma_x",
    "sigma_y",
    "sigma_z",
    "sigma_alpha",
    "sigma_beta",
    "sigma_gamma",
    "sem_x",
    "sem_y",
    "sem_z",
    "sem_alpha",
    "sem_beta",
    "sem_gamma",
    "filtered",
    "resolved_by_history",
    "n_misfit",
)
COLUMNS = REQUIRED_COLUMNS + EXTRA_COLUMNS
SESSION_FILE = "session.json"
ROWS_FILE = "rows.csv"
#: Largest session.json read (bytes); it holds a camera model and settings, a few KB.
MAX_INFO_BYTES = 1024 * 1024
#: Largest rows.csv read (bytes): some 800,000 rows, years of bench work.
MAX_ROWS_BYTES = 256 * 1024 * 1024
#: ``pass`` texts read as a pass or a fail besides the 1 and 0 qrfield writes (a hand-edited file);
#: each is named in a warning. Anything else counts as a fail, with a warning too.
PASS_WORDS = {"1": "1", "0": "0", "yes": "1", "no": "0", "true": "1", "false": "0", "pass": "1", "fail": "0"}
FORMAT = "qrfield-session/1"
#: Decimals written for mm and degree values.
DECIMALS = 3
_STAMP = "%Y%m%d-%H%M%S"
_FOLDER = re.compile(r"^\d{8}-\d{6}-.+$")


class SessionError(ValueError):
    """A session that cannot be created or opened, or misuse of one; the message says why."""


# ---------------------------------------------------------------------------------------- metadata
@dataclass(frozen=True)
class SessionInfo:
    """The contents of session.json."""

    name: str
    created: str
    camera: CameraModel
    side_mm: float
    solver: str
    solver_settings: dict[str, Any]
    criteria: AcceptanceCriteria
    frames_per_row: int
    operator: str = ""
    notes: str = ""
    app_version: str = qrfield.__version__
    #: The frame of the rows' poses and ground truth (qrfield.handeye.FRAMES), and the contents of
    #: the hand-eye file that took them there (empty for the camera frame).
    pose_frame: str = "camera"
    handeye: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        extra: dict[str, Any] = {"handeye": dict(self.handeye)} if self.handeye else {}
        return {
            "format": FORMAT,
            "name": self.name,
            "created": self.created,
            "operator": self.operator,
            "notes": self.notes,
            "app_version": self.app_version,
            "camera": self.camera.to_dict(),
            "side_mm": self.side_mm,
            "solver": {"method": self.solver, "settings": dict(self.solver_settings)},
            "criteria": to_dict(self.criteria),
            "frames_per_row": self.frames_per_row,
            "columns": list(COLUMNS),
            "pose_frame": self.pose_frame,
            **extra,
        }

    @classmethod
    def from_dict(cls, data: Any, where: str) -> SessionInfo:
        """Read the fields of session.json; SessionError naming ``where`` and the field for a missing
        one, a value of the wrong type (e.g. ``"side_mm": "50"``) or one outside its limits."""
        try:
            fields = Fields(data, where)
            camera = CameraModel.from_dict(fields.mapping("camera"), where=f"{where} camera")
            side = SIDE_MM.check(fields.number("side_mm"), f"{where}: field 'side_mm'")
            solver = Fields(fields.mapping("solver", {}), f"{where} solver")
            method = solver.text("method", "")
            settings = solver.mapping("settings", {})
            criteria = from_dict(AcceptanceCriteria, fields.mapping("criteria", {}), strict=False)
            frames = from_dict(
                SessionSettings, {"frames_per_row": fields.integer("frames_per_row", 10)}
            ).frames_per_row
            texts = {
                key: fields.text(key, "") for key in ("name", "created", "operator", "notes", "app_version")
            }
            pose_frame = fields.text("pose_frame", "camera")
            if pose_frame not in FRAMES:
                raise SessionError(
                    f"{where}: field 'pose_frame' must be one of {', '.join(FRAMES)}, got {pose_frame!r}"
                )
            handeye = fields.mapping("handeye", {})
        except (FileFormatError, CameraModelError, SettingError, LimitError) as exc:
            raise SessionError(str(exc) if str(exc).startswith(where) else f"{where}: {exc}") from None
        return cls(
            name=texts["name"],
            created=texts["created"],
            camera=camera,
            side_mm=side,
            solver=method,
            solver_settings=settings,
            criteria=criteria,
            frames_per_row=int(frames),
            operator=texts["operator"],
            notes=texts["notes"],
            app_version=texts["app_version"],
            pose_frame=pose_frame,
            handeye=handeye,
        )


def sanitize_name(name: str) -> str:
    """A folder-safe session name: letters, digits, '.', '_', '-'; other runs become '-'."""
    if not isinstance(name, str):
        raise SessionError(f"session name must be text, got {name!r}")
    cleaned = re.sub(r"[^A-Za-z0-9._-]+", "-", name.strip())
    cleaned = re.sub(r"-{2,}", "-", cleaned).strip("-.")[:60].strip("-.")
    if not cleaned:
        if any(ch.isalnum() for ch in name):  # letters or digits, but none of them ASCII
            raise SessionError(
                f"session name {name!r} has no ASCII letters or digits: folder names are ASCII-only "
                "(A-Z, a-z, 0-9, '.', '_', '-'); give a name with some, e.g. 'bench-1' (the notes "
                "may be in any script)"
            )
        raise SessionError(f"session name {name!r} has no letters or digits to make a folder name from")
    return cleaned


# ---------------------------------------------------------------------------------------- rows
@dataclass
class LoggedRow:
    """One measurement row as the table shows it: CSV texts by column, and its state.

    ``confirmed``: on disk (fsynced); False while it waits in the pending queue.
    ``withdrawn``: a withdrawal record for it exists (confirmed or pending).
    """

    number: int
    values: dict[str, str]
    confirmed: bool = True
    withdrawn: bool = False

    def number_or_nan(self, column: str) -> float:
        """The column's value as a float (NaN when empty or not a number)."""
        text = self.values.get(column, "")
        try:
            return float(text) if text != "" else math.nan
        except ValueError:
            return math.nan

    @property
    def passed(self) -> bool:
        return self.values.get("pass", "") == "1"

    @property
    def combo(self) -> str:
        return self.values.get("combo", "")


@dataclass(frozen=True)
class LogOutcome:
    """What a log/undo/retry call achieved.

    status: "logged" (everything asked is on disk), "pending" (kept in memory, will be retried).
    row: the row number concerned (the new row; for undo the withdrawn row; None for retry).
    logged: rows and withdrawal records written by this call ("w7" = withdrawal of row 7).
    pending: what still waits, in order. message: one line for the operator of the app (which
    keeps the records and retries them). reason: why the write failed, without advice ("" when
    logged), for a front end that words its own advice (the command line, which is exiting).
    """

    status: str
    row: int | None
    logged: tuple[str, ...]
    pending: tuple[str, ...]
    message: str
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "logged"


@dataclass
class _Record:
    label: str  # "7" or "w7"
    line: bytes
    row: LoggedRow | None = None
    withdraws: int | None = None


def _fmt(value: float, decimals: int = DECIMALS) -> str:
    value = float(value)
    if not math.isfinite(value):
        return ""
    text = f"{value:.{decimals}f}"
    return "0." + "0" * decimals if text.lstrip("-").strip("0.") == "" and decimals else text


def _one_line(text: str) -> str:
    """Notes are kept to one physical line so that every record is exactly one line."""
    return re.sub(r"[\x00-\x1f\x7f\x85\u2028\u2029]+", " ", text or "").strip()


def measurement_values(measurement: Measurement, number: int, time_text: str) -> dict[str, str]:
    """The CSV texts of a measurement row (mm and degrees; empty where there is no pose)."""
    t = measurement.truth
    a = measurement.average
    j = measurement.judgement
    values = {
        "row": str(number),
        "time": time_text,
        "combo": _one_line(t.combo),
        "gt_x": _fmt(t.x),
        "gt_y": _fmt(t.y),
        "gt_z": _fmt(t.z),
        "gt_alpha": _fmt(t.alpha),
        "gt_beta": _fmt(t.beta),
        "gt_gamma": _fmt(t.gamma),
        "n_frames": str(a.n_frames),
        "n_converged": str(a.n_converged),
        "err_pos": _fmt(j.err_pos_mm),
        "pass": "1" if j.passed else "0",
        "note": _one_line(measurement.note),
        "mean_iterations": _fmt(a.mean_iterations, 2),
        "reprojection_px": _fmt(a.mean_reprojection_px),
        "method": _one_line(measurement.method),
        "withdraws": "",
        "filtered": "1" if a.filtered else "0",
        "resolved_by_history": str(a.n_resolved_by_history),
        "n_misfit": str(a.n_misfit),
    }
    for k, axis in enumerate("xyz"):
        values[axis] = _fmt(a.position_mm[k])
        values[f"std_{axis}"] = _fmt(a.std_position_mm[k])
        values[f"sigma_{axis}"] = _fmt(a.sigma_position_mm[k])
        values[f"sem_{axis}"] = _fmt(a.sem_position_mm[k])
    for k, angle in enumerate(ANGLE_NAMES):
        values[angle] = _fmt(a.angles_deg[k])
        values[f"std_{angle}"] = _fmt(a.std_angles_deg[k])
        values[f"sigma_{angle}"] = _fmt(a.sigma_angles_deg[k])
        values[f"sem_{angle}"] = _fmt(a.sem_angles_deg[k])
        values[f"err_{angle}"] = _fmt(j.err_angles_deg[k])
    return values


def _csv_line(values: dict[str, str], columns: Sequence[str]) -> bytes:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([values.get(c, "") for c in columns])
    return buf.getvalue().encode("utf-8")


def _now_text() -> str:
    return dt.datetime.now().astimezone().isoformat(timespec="seconds")


#: Bytes read at a time when rows.csv is scanned or iterated.
READ_CHUNK = 1 << 20
#: Longest line read (bytes): every column at the csv module's field limit would be 39 x 128 KiB;
#: a longer line is damaged and skipped with a warning, so that one line never fills the memory.
MAX_LINE_BYTES = 8 << 20
#: Most warnings kept about the lines of one rows.csv (the rest are counted in a last one).
MAX_ROW_WARNINGS = 100
#: Most bytes of an unfinished last line kept in :attr:`RowsContent.partial`.
MAX_PARTIAL_KEPT = 1 << 20


class _Source:
    """Where rows.csv's bytes come from: a file read by position (never loaded whole), or bytes."""

    def __init__(self, path: Path | None = None, data: bytes | None = None, follow: bool = True) -> None:
        self.path, self.data, self.follow = path, data, follow

    def size(self) -> int:
        if self.data is not None:
            return len(self.data)
        with self._open() as fd:
            return os.fstat(fd).st_size

    @contextlib.contextmanager
    def _open(self) -> Any:
        assert self.path is not None
        flags = os.O_RDONLY | _CLOEXEC | (0 if self.follow else _NOFOLLOW)
        fd = os.open(self.path, flags)
        try:
            yield fd
        finally:
            os.close(fd)

    def chunks(self, start: int, end: int) -> Any:
        """The bytes start..end in chunks of :data:`READ_CHUNK` (what a reader holds at a time)."""
        if self.data is not None:
            for at in range(start, end, READ_CHUNK):
                yield self.data[at : min(end, at + READ_CHUNK)]
            return
        with self._open() as fd:
            at = start
            while at < end:
                chunk = os.pread(fd, min(READ_CHUNK, end - at), at)
                if not chunk:
                    raise SessionError(
                        f"{self.path}: shorter than when it was read; changed by another program"
                    )
                yield chunk
                at += len(chunk)

    def read(self, offset: int, length: int) -> bytes:
        if self.data is not None:
            return self.data[offset : offset + length]
        with self._open() as fd:
            return os.pread(fd, length, offset)


def _lines(source: _Source, end: int, where: str) -> Any:
    """(offset, bytes without the newline) of every line of bytes 0..end (which ends with a
    newline); a line longer than :data:`MAX_LINE_BYTES` comes as (offset, None)."""
    pending = bytearray()
    start = 0  # offset of pending's first byte
    skipping = False
    at = 0
    for chunk in source.chunks(0, end):
        pos = 0
        while pos < len(chunk):
            cut = chunk.find(b"\n", pos)
            if cut < 0:
                if not skipping:
                    pending += chunk[pos:]
                    if len(pending) > MAX_LINE_BYTES:
                        pending.clear()
                        skipping = True
                break
            if skipping:
                yield start, None
                skipping = False
            else:
                pending += chunk[pos:cut]
                yield start, bytes(pending)
                pending.clear()
            start = at + cut + 1
            pos = cut + 1
        at += len(chunk)


def _decode_line(data: bytes, offset: int, where: str) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SessionError(f"{where}: not UTF-8 text (byte {offset + exc.start})") from None


def _fields(line: str) -> list[str]:
    """The fields of one record (one line); csv.Error if it is not CSV. A line without quotes or
    carriage returns, as qrfield writes nearly every one, is split on its commas (what the csv
    module would return, several times faster); any other goes through the csv module."""
    if '"' not in line and "\r" not in line and len(line) <= MAX_FIELD_CHARS:
        return line.split(",")
    return next(csv_text_reader(line), [])


def _row_values(header: list[str], line: str) -> tuple[dict[str, str], int]:
    """The values of one record by column, and its field count; csv.Error if it is not CSV."""
    fields = _fields(line)
    return dict(zip(header, fields, strict=False)), len(fields)


def _normal_pass(verdict: str) -> str | None:
    return PASS_WORDS.get(verdict.strip().lower())


class RowList(Sequence[LoggedRow]):
    """The measurement rows of rows.csv, read from the file when asked for, never held whole.

    The scan that opens a session keeps, per row, only where its line is (offset and length) and
    its number (some 20 bytes a row: 800,000 rows are 16 MB instead of gigabytes of dicts);
    ``rows[i]`` reads and parses that one line, iterating reads the file in order, a chunk at a
    time. ``withdrawn`` is the set of withdrawn row numbers, shared with the session, so a row read
    after its withdrawal says so. Rows logged by this process are appended (kept as objects: their
    ``confirmed`` flag changes).
    """

    def __init__(self, source: _Source, header: list[str], where: str, withdrawn: set[int]) -> None:
        self._source = source
        self._header = header
        self._where = where
        self.withdrawn = withdrawn
        # 4 bytes each a row: rows.csv is at most MAX_ROWS_BYTES (< 4 GiB), row numbers are counted
        # from 1 (a number beyond 32 bits, from a hand-edited file, is kept aside in _large).
        self._offsets = array("I")
        self._numbers = array("i")
        self._large: dict[int, int] = {}
        self._end = 0  # where the line of the last row ends (its newline included)
        self._added: list[LoggedRow] = []

    # -------------------------------------------------------------- built by the scan
    def _keep(self, offset: int, length: int, number: int) -> None:
        if -(2**31) <= number < 2**31:
            self._numbers.append(number)
        else:
            self._large[len(self._numbers)] = number
            self._numbers.append(0)
        self._offsets.append(offset)
        self._end = offset + length + 1

    def _number(self, index: int) -> int:
        return self._large.get(index, self._numbers[index])

    # -------------------------------------------------------------- Sequence
    def __len__(self) -> int:
        return len(self._offsets) + len(self._added)

    def __getitem__(self, index: Any) -> Any:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        n = len(self)
        if index < 0:
            index += n
        if not 0 <= index < n:
            raise IndexError("row index out of range")
        stored = len(self._offsets)
        if index >= stored:
            row = self._added[index - stored]
            row.withdrawn = row.number in self.withdrawn
            return row
        offset = self._offsets[index]
        return self._row(self._line_at(offset), offset, index)

    def __iter__(self) -> Any:
        if self._offsets:
            index = 0
            for offset, data in _lines(self._source, self._end, self._where):
                if index < len(self._offsets) and offset == self._offsets[index]:
                    assert data is not None
                    yield self._row(data, offset, index)
                    index += 1
        for row in self._added:
            row.withdrawn = row.number in self.withdrawn
            yield row

    def __reversed__(self) -> Any:
        for index in range(len(self) - 1, -1, -1):
            yield self[index]

    def __eq__(self, other: object) -> bool:
        if isinstance(other, (list, tuple, RowList)):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other, strict=True))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"<RowList of {len(self)} rows of {self._where}>"

    # -------------------------------------------------------------- rows
    def append(self, row: LoggedRow) -> None:
        """A row logged by this process (kept as it is while its ``confirmed`` flag may change:
        until :meth:`stored`)."""
        self._added.append(row)

    def stored(self, row: LoggedRow, offset: int, length: int) -> None:
        """``row``, logged by this process, is on disk now, its line at ``offset`` (``length`` bytes
        without the newline): from now on it is read from there like the rows before it, not kept
        (a row kept a logged row's values, some 5 KB, for as long as the session was open: a day of
        rows grew without bound). Rows are stored in the order they were logged."""
        if self._added and self._added[0] is row and offset >= self._end:
            del self._added[0]
            self._keep(offset, length, row.number)

    def max_number(self) -> int:
        """The largest row number (0 without rows), without reading a line."""
        numbers = [r.number for r in self._added] + list(self._large.values())
        if len(self._numbers):
            numbers.append(max(self._numbers))
        return max(numbers, default=0)

    def by_number(self, number: int) -> LoggedRow | None:
        """The (last) row of that number, reading only its line; None when there is none."""
        for row in reversed(self._added):
            if row.number == number:
                row.withdrawn = row.number in self.withdrawn
                return row
        for index in range(len(self._numbers) - 1, -1, -1):
            if self._number(index) == number:
                return self[index]
        return None

    def _line_at(self, offset: int) -> bytes:
        """The line starting at ``offset``, without its newline (read in growing pieces)."""
        length = 4096
        while True:
            data = self._source.read(offset, length)
            cut = data.find(b"\n")
            if cut >= 0:
                return data[:cut]
            if len(data) < length or length > MAX_LINE_BYTES:
                raise SessionError(f"{self._where}: changed by another program since it was read")
            length *= 4

    def _row(self, data: bytes, offset: int, index: int) -> LoggedRow:
        text = _decode_line(data, offset, self._where)
        if offset == 0 and text.startswith("\ufeff"):  # pragma: no cover - the header is line 1
            text = text[1:]
        values, _ = _row_values(self._header, text)
        values["pass"] = _normal_pass(values.get("pass", "")) or "0"
        number = self._number(index)
        return LoggedRow(number, values, withdrawn=number in self.withdrawn)


@dataclass
class RowsContent:
    """rows.csv as read: header, measurement rows (withdrawn flagged), warnings, the complete part's size.

    ``rows`` is a :class:`RowList` (read from the file row by row); ``partial`` holds the first
    :data:`MAX_PARTIAL_KEPT` bytes of an unfinished last line, ``partial_size`` its length.
    """

    columns: list[str]
    rows: RowList
    warnings: list[str]
    good_size: int
    partial: bytes = b""
    withdrawn: set[int] = field(default_factory=set)
    partial_size: int = 0


def parse_rows(data: bytes, where: str = ROWS_FILE) -> RowsContent:
    """Parse rows.csv bytes; an unfinished last line (no newline) is returned in ``partial``, not parsed."""
    return _scan_rows(_Source(data=data), len(data), where)


def _scan_rows(source: _Source, size: int, where: str) -> RowsContent:
    """One pass over rows.csv (a chunk at a time): the header, where each row's line is, the
    withdrawals, the warnings, and the size of the complete part (up to its last newline)."""
    good_size = _complete_size(source, size)
    warnings: list[str] = []
    more = 0

    def warn(text: str) -> None:
        nonlocal more
        if len(warnings) < MAX_ROW_WARNINGS:
            warnings.append(text)
        else:
            more += 1

    lines = _lines(source, good_size, where)
    header = _read_header(lines, where)
    withdrawn: set[int] = set()
    rows = RowList(source, header, where, withdrawn)
    # Only these three columns matter to the scan (the first of equal names, as dict(zip()) keeps the
    # last: none of them is repeated in a header qrfield wrote).
    at_row = 0  # the header starts with REQUIRED_COLUMNS
    at_pass = header.index("pass")
    at_withdraws = len(header) - 1 - header[::-1].index("withdraws") if "withdraws" in header else -1
    seen: set[int] | None = None  # row numbers, built only if they stop increasing
    highest: int | None = None
    for lineno, (offset, data) in enumerate(lines, start=2):
        if data is None:
            warn(f"{where} line {lineno}: longer than {MAX_LINE_BYTES} bytes (damaged); ignored")
            continue
        line = _decode_line(data, offset, where)
        if not line.strip():
            continue
        if "\x00" in line:
            warn(f"{where} line {lineno}: contains NUL bytes (damaged); ignored")
            continue
        try:
            fields = _fields(line)
        except csv.Error as exc:  # e.g. a field over MAX_FIELD_CHARS written by another program
            warn(f"{where} line {lineno}: not a CSV record ({exc}); ignored")
            continue
        count = len(fields)
        if count != len(header):
            warn(f"{where} line {lineno}: {count} fields, the header has {len(header)}")
        row_text = fields[at_row].strip() if count > at_row else ""
        target = fields[at_withdraws].strip() if 0 <= at_withdraws < count else ""
        if row_text:
            try:
                number = int(row_text)
            except ValueError:
                warn(f"{where} line {lineno}: row {row_text[:40]!r} is not a number; ignored")
                continue
            if highest is not None and number <= highest:
                if seen is None:
                    seen = {rows._number(i) for i in range(len(rows._numbers))}
                if number in seen:
                    warn(f"{where} line {lineno}: row {number} appears twice; both kept")
            if seen is not None:
                seen.add(number)
            highest = number if highest is None else max(highest, number)
            verdict = fields[at_pass] if count > at_pass else ""
            normal = _normal_pass(verdict)
            if normal is None:
                warn(
                    f"{where} line {lineno}: row {number} has pass {verdict!r}, not 1 or 0; counted as failed"
                )
            elif normal != verdict:
                shown = "passed" if normal == "1" else "failed"
                warn(f"{where} line {lineno}: row {number} has pass {verdict!r}, read as {shown}")
            rows._keep(offset, len(data), number)
        elif target:
            try:
                withdrawn.add(int(target))
            except ValueError:
                warn(f"{where} line {lineno}: withdraws {target[:40]!r} is not a row number; ignored")
        else:
            warn(f"{where} line {lineno}: neither a row nor a withdrawal record; ignored")
    if more:
        warnings.append(
            f"{where}: {more} more line(s) with problems (only the first {MAX_ROW_WARNINGS} are listed)"
        )
    partial = source.read(good_size, min(size - good_size, MAX_PARTIAL_KEPT)) if size > good_size else b""
    return RowsContent(header, rows, warnings, good_size, partial, withdrawn, size - good_size)


def _read_header(lines: Iterator[tuple[int, bytes | None]], where: str) -> list[str]:
    """The header of rows.csv from the first of ``lines`` ((offset, bytes or None when too long)),
    its names stripped; SessionError when there is none or it does not start with REQUIRED_COLUMNS."""
    first = next(lines, None)
    if first is None:
        raise SessionError(f"{where}: no header row")
    offset, data = first
    if data is None:
        raise SessionError(f"{where}: the header row is longer than {MAX_LINE_BYTES} bytes")
    head = _decode_line(data, offset, where)
    head = head[1:] if head.startswith("\ufeff") else head  # a spreadsheet's "CSV UTF-8"
    try:
        header = next(csv_text_reader(head), [])  # an empty first line has no fields
    except csv.Error as exc:
        raise SessionError(f"{where}: the header row is not CSV ({exc})") from None
    header = [name.strip() for name in header]
    if tuple(header[: len(REQUIRED_COLUMNS)]) != REQUIRED_COLUMNS:
        raise SessionError(
            f"{where}: the header does not start with the required columns {','.join(REQUIRED_COLUMNS)}"
        )
    return header


def _complete_size(source: _Source, size: int) -> int:
    """The size of rows.csv up to and including its last newline (0 when it has none)."""
    end = size
    while end > 0:
        start = max(0, end - READ_CHUNK)
        chunk = source.read(start, end - start)
        cut = chunk.rfind(b"\n")
        if cut >= 0:
            return start + cut + 1
        end = start
    return 0


def _read_folder(folder: Path, *, follow: bool = True) -> tuple[SessionInfo, Path, RowsContent]:
    """A session folder's info, the path of its rows.csv and its rows (read a chunk at a time, never
    whole); SessionError if unreadable. ``follow=False``: a symbolic link at rows.csv is refused."""
    info = _read_info(folder)
    rows_path = folder / ROWS_FILE
    where = str(rows_path)
    try:
        mode = os.stat(rows_path, follow_symlinks=follow).st_mode
    except FileNotFoundError:
        raise SessionError(f"{folder}: no {ROWS_FILE}") from None
    except OSError as exc:
        raise SessionError(f"rows file {rows_path}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISLNK(mode):
        raise SessionError(_symlink_refusal(rows_path))
    if stat.S_ISDIR(mode):
        raise SessionError(f"rows file {rows_path}: is a folder, not a file")
    if not stat.S_ISREG(mode):  # a FIFO, a device: it may never end
        raise SessionError(f"rows file {rows_path}: not a regular file")
    source = _Source(path=rows_path, follow=follow)
    try:
        size = source.size()
        if size > MAX_ROWS_BYTES:
            raise SessionError(
                f"rows file {rows_path}: larger than {MAX_ROWS_BYTES // (1024 * 1024)} MiB; "
                "not a file qrfield wrote"
            )
        return info, rows_path, _scan_rows(source, size, where)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise SessionError(_symlink_refusal(rows_path)) from None
        raise SessionError(f"rows file {rows_path}: cannot read ({exc.strerror or exc})") from None


def _symlink_refusal(rows_path: Path) -> str:
    return (
        f"{rows_path} is a symbolic link, not the session's own file; not writing through it "
        "(replace it with the file it points to)"
    )


def read_session(path: str | os.PathLike[str]) -> tuple[SessionInfo, RowsContent]:
    """Read a session without changing anything (for analysis): its info and rows.

    An unfinished last line is reported in the warnings and left where it is.
    """
    folder = Path(path)
    info, rows_path, content = _read_folder(folder)
    if content.partial_size:
        content.warnings.append(
            f"{rows_path}: ends with an unfinished line of {content.partial_size} bytes "
            "(a crash while logging; never confirmed); ignored"
        )
    return info, content


def _read_info(folder: Path) -> SessionInfo:
    if not folder.is_dir():
        if folder.exists():
            raise SessionError(
                f"{folder}: is a file, not a session folder (give the folder that holds {SESSION_FILE})"
            )
        raise SessionError(f"{folder}: no such session folder")
    path = folder / SESSION_FILE
    try:
        data = read_json(path, "session file", max_bytes=MAX_INFO_BYTES)
    except FileFormatError as exc:
        if exc.kind == "missing":
            raise SessionError(f"{folder}: not a session (no {SESSION_FILE})") from None
        raise SessionError(str(exc)) from None
    return SessionInfo.from_dict(data, str(path))


# ---------------------------------------------------------------------------------------- session


def _checked_new_session(
    name: str,
    operator: str,
    notes: str,
    pose_frame: str,
    handeye: dict[str, Any] | None,
    camera: CameraModel,
    side_mm: float,
    solver: str,
    solver_settings: Any,
    frames_per_row: int | None,
) -> tuple[str, float, dict[str, Any], int]:
    """The fields of :meth:`Session.create` checked (SessionError naming the bad one): the folder-safe
    name, the side (mm), the solver's settings as a checked dict, the frames per row."""
    try:  # session.json is UTF-8: a text that is not would be written as an escape no reader takes
        for label, text in (("session name", name), ("operator", operator), ("notes", notes or "")):
            check_text(text, label)
    except TextError as exc:
        raise SessionError(str(exc)) from None
    if pose_frame not in FRAMES:
        raise SessionError(f"pose frame {pose_frame!r} is not one of {', '.join(FRAMES)}")
    if (pose_frame == "camera") != (not handeye):
        raise SessionError(
            f"pose frame {pose_frame}: a hand-eye calibration goes with the tool or base frame only"
        )
    safe = sanitize_name(name)
    if not isinstance(camera, CameraModel):
        raise SessionError(f"camera must be a CameraModel, got {type(camera).__name__}")
    try:
        side = float(side_mm)
    except (TypeError, ValueError):
        raise SessionError(f"QR side must be a length in mm, got {side_mm!r}") from None
    if not math.isfinite(side) or side <= 0:
        raise SessionError(f"QR side must be a positive length in mm, got {side_mm!r}")
    if solver not in METHODS:
        raise SessionError(f"solver {solver!r} is not one of {', '.join(METHODS)}")
    if solver_settings is None:
        settings_dict: dict[str, Any] = {}
    elif isinstance(solver_settings, dict):
        settings_dict = dict(solver_settings)
    else:
        settings_dict = to_dict(solver_settings)
    settings_dict = _checked_solver_settings(solver, settings_dict)
    frames = from_dict(
        SessionSettings,
        {} if frames_per_row is None else {"frames_per_row": frames_per_row},
    ).frames_per_row
    return safe, side, settings_dict, frames


def _new_session_folder(root_path: Path, safe: str, now: dt.datetime | None) -> tuple[Path, dt.datetime]:
    """``root_path/<YYYYmmdd-HHMMSS>-<safe>/`` made (never an existing one: the next free second is
    taken for the stamp), and the time of its stamp."""
    try:
        make_folder(root_path, "sessions folder")  # never the folders above one the user named
    except OSError as exc:
        raise SessionError(describe_error(exc)) from None
    stamp_time = now or dt.datetime.now()
    for _ in range(3600):
        folder = root_path / f"{stamp_time.strftime(_STAMP)}-{safe}"
        try:
            folder.mkdir()
            break
        except FileExistsError:
            stamp_time += dt.timedelta(seconds=1)
    else:
        raise SessionError(f"{root_path}: no free folder name for session {safe!r}")
    fsync_dir(root_path)
    return folder, stamp_time


class Session:
    """An open experiment session: log rows, withdraw them, retry pending writes.

    Create with :meth:`create`, reopen (resume) with :meth:`open`. ``log``, ``undo``, ``withdraw``
    and ``retry`` never raise for a failed write: they return a :class:`LogOutcome`.
    """

    def __init__(self, path: Path, info: SessionInfo, content: RowsContent, file_ops: FileOps | None):
        self.path = path
        self.info = info
        self.columns = list(content.columns)
        self.rows: RowList = content.rows  # read from rows.csv when asked for, never held whole
        self.warnings: list[str] = list(content.warnings)
        self.pending: list[_Record] = []
        self.next_row = self.rows.max_number() + 1
        self._ops = file_ops or FileOps()
        self._fd: int | None = None
        self._good_size = content.good_size
        self._withdrawn = content.withdrawn  # the same set the rows read their flag from
        dropped = [c for c in COLUMNS if c not in self.columns]
        if dropped:
            self.warnings.append(
                f"{self.rows_path}: has no column(s) {', '.join(dropped)}; those values are not written"
            )

    # ------------------------------------------------------------------ create / open
    @classmethod
    def create(
        cls,
        root: str | os.PathLike[str],
        name: str,
        *,
        camera: CameraModel,
        side_mm: float,
        solver: str,
        solver_settings: Any = None,
        criteria: AcceptanceCriteria | None = None,
        frames_per_row: int | None = None,
        operator: str = "",
        notes: str = "",
        now: dt.datetime | None = None,
        file_ops: FileOps | None = None,
        pose_frame: str = "camera",
        handeye: dict[str, Any] | None = None,
    ) -> Session:
        """Make ``root/<YYYYmmdd-HHMMSS>-<name>/`` with session.json and rows.csv (header only).

        Never overwrites: when the folder exists, the next free second is taken for the stamp.
        ``solver_settings``: the solver's settings dataclass or a dict (saved as a dict).
        ``pose_frame``, ``handeye``: the frame the rows are measured in and the hand-eye file's
        contents that take poses there (``qrfield.handeye.HandEyeCalibration.to_dict``).
        """
        safe, side, settings_dict, frames = _checked_new_session(
            name,
            operator,
            notes,
            pose_frame,
            handeye,
            camera,
            side_mm,
            solver,
            solver_settings,
            frames_per_row,
        )
        folder, stamp_time = _new_session_folder(Path(root), safe, now)
        info = SessionInfo(
            name=_one_line(name),
            created=stamp_time.astimezone().isoformat(timespec="seconds"),
            camera=camera,
            side_mm=side,
            solver=solver,
            solver_settings=settings_dict,
            criteria=criteria or AcceptanceCriteria(),
            frames_per_row=int(frames),
            operator=_one_line(operator),
            notes=notes or "",
            pose_frame=pose_frame,
            handeye=dict(handeye or {}),
        )
        atomic_write(folder / SESSION_FILE, (json.dumps(info.to_dict(), indent=2) + "\n").encode("utf-8"))
        atomic_write(folder / ROWS_FILE, _csv_line({c: c for c in COLUMNS}, COLUMNS))
        return cls.open(folder, file_ops=file_ops)

    @classmethod
    def open(cls, path: str | os.PathLike[str], *, file_ops: FileOps | None = None) -> Session:
        """Open (resume) a session for logging; numbering continues after the last row.

        An unfinished last line left by a crash is moved to ``rows.csv.partial-<time>`` (see
        ``warnings``). When rows.csv cannot be opened for writing (read-only folder), the session
        still opens; the reason is in ``warnings`` and rows wait in ``pending`` until writing works.
        Raises SessionError when the folder is not a readable session or another process logs to it.
        """
        folder = Path(path)
        info, rows_path, content = _read_folder(folder, follow=False)  # never through a planted link
        session = cls(folder, info, content, file_ops)
        try:
            session._connect()
            session._repair_tail()
        except SessionError:
            session.close()
            raise
        except OSError as exc:
            session.close()
            session.warnings.append(f"{rows_path}: cannot open for writing ({_explain(exc)}); rows will wait")
        return session

    @property
    def rows_path(self) -> Path:
        return self.path / ROWS_FILE

    @property
    def writable(self) -> bool:
        return self._fd is not None

    def close(self) -> None:
        """Release rows.csv (pending records, if any, stay unwritten: check ``pending`` first)."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                self._ops.close(self._fd)
            self._fd = None

    def export_pending(self, path: str | os.PathLike[str]) -> int:
        """Save the pending records (header + lines, as rows.csv would get them) to another file.

        For when rows.csv cannot be written and the app must close: the operator saves the rows
        elsewhere (another drive) instead of losing them. Returns how many records were saved.
        """
        if not self.pending:
            return 0
        data = _csv_line({c: c for c in self.columns}, self.columns) + b"".join(r.line for r in self.pending)
        atomic_write(Path(path), data)
        return len(self.pending)

    def update_notes(self, notes: str, operator: str | None = None) -> None:
        """Change the notes (and operator) in session.json, atomically. Raises OSError if it cannot,
        TextError (a ValueError) for a text that is not UTF-8."""
        check_text(notes or "", "notes")
        if operator is not None:
            check_text(operator, "operator")
        changes: dict[str, Any] = {"notes": notes or ""}
        if operator is not None:
            changes["operator"] = _one_line(operator)
        info = dataclasses.replace(self.info, **changes)
        atomic_write(self.path / SESSION_FILE, (json.dumps(info.to_dict(), indent=2) + "\n").encode("utf-8"))
        self.info = info

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ logging
    def log(self, measurement: Measurement, *, time_text: str | None = None) -> LogOutcome:
        """Number, append and fsync one measurement row; "logged" only once it is on disk.

        Raises SessionError (nothing numbered, nothing written) for a value longer than
        MAX_FIELD_CHARS characters, which no CSV reader could read back.
        """
        number = self.next_row
        values = measurement_values(measurement, number, time_text or _now_text())
        try:  # refused before it is numbered: a field the csv module cannot read back, or not UTF-8
            check_field_sizes(values, f"row {number}")
            for column, text in values.items():
                check_text(text, f"row {number}: {column}")
        except (FileFormatError, TextError) as exc:
            raise SessionError(str(exc)) from None
        self.next_row += 1
        row = LoggedRow(number, values, confirmed=False)
        self.rows.append(row)
        self.pending.append(_Record(str(number), _csv_line(values, self.columns), row=row))
        return self._flush(number, f"row {number}")

    def undo(self) -> LogOutcome:
        """Withdraw the last row not yet withdrawn (appends a withdrawal record)."""
        for row in reversed(self.rows):
            if not row.withdrawn:
                return self.withdraw(row.number)
        raise SessionError("nothing to undo: no row left that is not withdrawn")

    def withdraw(self, number: int, reason: str = "undo") -> LogOutcome:
        """Append a record withdrawing row ``number``; the row's own line stays as it is."""
        row = self.rows.by_number(number)
        if row is None:
            raise SessionError(f"no row {number} in this session")
        if row.withdrawn:
            raise SessionError(f"row {number} is already withdrawn")
        values = dict.fromkeys(self.columns, "")
        values.update(time=_now_text(), note=f"withdraws row {number} ({_one_line(reason)[:1000]})")
        values["withdraws"] = str(number)
        row.withdrawn = True
        self._withdrawn.add(number)
        self.pending.append(_Record(f"w{number}", _csv_line(values, self.columns), withdraws=number))
        return self._flush(number, f"withdrawal of row {number}")

    def retry(self) -> LogOutcome:
        """Write what is pending, in order."""
        return self._flush(None, "pending records")

    # ------------------------------------------------------------------ internals
    def _flush(self, row: int | None, what: str) -> LogOutcome:
        logged: list[str] = []
        error: OSError | SessionError | None = None
        while self.pending:
            record = self.pending[0]
            offset = self._good_size  # where the record's line goes (after the confirmed ones)
            try:
                self._append(record.line)
            except (OSError, SessionError) as exc:
                error = exc
                self.close()  # reconnect (and re-check the file's end) on the next attempt
                break
            self.pending.pop(0)
            if record.row is not None:
                record.row.confirmed = True
                self.rows.stored(record.row, offset, len(record.line) - 1)
            logged.append(record.label)
        waiting = tuple(r.label for r in self.pending)
        if error is None:
            message = (
                f"logged {what}"
                if row is not None
                else (f"logged {len(logged)} pending record(s)" if logged else "nothing pending")
            )
            return LogOutcome("logged", row, tuple(logged), waiting, message)
        explained = _explain(error) if isinstance(error, OSError) else str(error)
        reason = f"cannot write {self.rows_path} ({explained})"
        message = (
            f"NOT logged yet: {reason}. "
            f"{len(waiting)} record(s) kept in memory and retried before the next row; "
            "free space or fix permissions, then Retry. Do not close the app until they are written."
        )
        return LogOutcome("pending", row, tuple(logged), waiting, message, reason)

    def _connect(self) -> None:
        """Open rows.csv for appending and lock it (the end of the file is checked by each append)."""
        if self._fd is not None:
            return
        try:  # never through a symbolic link planted at rows.csv (it would append elsewhere)
            fd = self._ops.open(str(self.rows_path), os.O_RDWR | os.O_APPEND | _NOFOLLOW | _CLOEXEC)
        except OSError as exc:
            if exc.errno == errno.ELOOP or self.rows_path.is_symlink():
                raise SessionError(_symlink_refusal(self.rows_path)) from None
            raise
        try:
            if fcntl is not None:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    raise SessionError(
                        f"{self.path}: another process is logging to this session; close it there first"
                    ) from None
                except OSError:
                    pass  # a file system without locks: carry on unlocked
            self._fd = fd
        except BaseException:
            self._fd = None
            with contextlib.suppress(OSError):
                self._ops.close(fd)
            raise

    def _repair_tail(self, expected: bytes = b"") -> bool:
        """Bring rows.csv back to the confirmed size; True when its extra bytes are exactly ``expected``.

        Bytes beyond the last confirmed record are either the record being retried, fully written
        but not confirmed (fsync failed): kept; or an unfinished line: moved aside, then cut off.
        """
        assert self._fd is not None
        size = self._ops.size(self._fd)
        if size == self._good_size:
            return False
        if size < self._good_size:
            raise SessionError(
                f"{self.rows_path} is shorter than the rows confirmed so far ({size} < {self._good_size} "
                "bytes): changed by another program; not writing to it"
            )
        tail = self._ops.pread(self._fd, size - self._good_size, self._good_size)
        if expected and tail == expected:
            return True
        stamp = dt.datetime.now().strftime(_STAMP)
        aside = unique_path(self.path / f"{ROWS_FILE}.partial-{stamp}")
        atomic_write(aside, tail)
        self._ops.truncate(self._fd, self._good_size)
        self._ops.fsync(self._fd)
        self.warnings.append(
            f"{self.rows_path}: ended with an unfinished line of {len(tail)} bytes (a crash or failed "
            f"write while logging; never confirmed as logged); moved to {aside.name}"
        )
        return False

    def _append(self, line: bytes) -> None:
        self._connect()
        assert self._fd is not None
        try:
            if not self._repair_tail(expected=line):
                written = self._ops.write(self._fd, line)
                if written != len(line):
                    raise OSError(errno.ENOSPC, f"short write: {written} of {len(line)} bytes")
            self._ops.fsync(self._fd)
        except OSError:
            self._cut_back()
            raise
        self._good_size += len(line)

    def _cut_back(self) -> None:
        """After a failed append: cut rows.csv back to its last confirmed record, so that no torn
        line stays at its end (best effort: a medium that fails this too is repaired on reopening)."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            if self._ops.size(self._fd) > self._good_size:
                self._ops.truncate(self._fd, self._good_size)
                self._ops.fsync(self._fd)


def _checked_solver_settings(solver: str, settings: dict[str, Any]) -> dict[str, Any]:
    """The solver's settings validated by its own declaration."""
    try:
        from qrfield.solvers import settings_class  # the solvers load only when a session is made

        return to_dict(from_dict(settings_class(solver), settings))
    except SettingError as exc:
        raise SessionError(f"solver settings: {exc}") from None


def _explain(exc: OSError) -> str:
    names = {
        errno.ENOSPC: "disk full",
        errno.EDQUOT: "disk quota exceeded",
        errno.EACCES: "permission denied",
        errno.EPERM: "operation not permitted",
        errno.EROFS: "read-only file system",
        errno.EIO: "input/output error (medium removed?)",
    }
    label = names.get(exc.errno or -1, exc.strerror or str(exc))
    detail = exc.strerror or ""
    return label if not detail or detail.lower() == label else f"{label}: {detail}"


def session_folders(root: str | os.PathLike[str]) -> list[Path]:
    """Session folders under ``root`` (named by the stamp rule, holding session.json), oldest first."""
    base = Path(root)
    if not base.is_dir():
        return []
    return sorted(
        p for p in base.iterdir() if p.is_dir() and _FOLDER.match(p.name) and (p / SESSION_FILE).exists()
    )
