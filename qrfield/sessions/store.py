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
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import qrfield
from qrfield.camera import CameraModel, CameraModelError
from qrfield.files import (
    Fields,
    FileFormatError,
    check_field_sizes,
    csv_text_reader,
    decode_text,
    make_folder,
    read_bytes,
    read_json,
)
from qrfield.handeye.setups import FRAMES
from qrfield.limits import SIDE_MM, LimitError
from qrfield.methods import METHODS
from qrfield.sessions.averaging import Measurement
from qrfield.sessions.criteria import AcceptanceCriteria, SessionSettings
from qrfield.sessions.files import FileOps, atomic_write, fsync_dir, unique_path
from qrfield.settings import SettingError, from_dict, to_dict

try:  # advisory lock: POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

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
#: (docs/conventions.md, "The live stream").
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
    pending: what still waits, in order. message: one line for the operator.
    """

    status: str
    row: int | None
    logged: tuple[str, ...]
    pending: tuple[str, ...]
    message: str

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
    }
    for k, axis in enumerate("xyz"):
        values[axis] = _fmt(a.position_mm[k])
        values[f"std_{axis}"] = _fmt(a.std_position_mm[k])
        values[f"sigma_{axis}"] = _fmt(a.sigma_position_mm[k])
        values[f"sem_{axis}"] = _fmt(a.sem_position_mm[k])
    for k, angle in enumerate(("alpha", "beta", "gamma")):
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


@dataclass
class RowsContent:
    """rows.csv as read: header, measurement rows (withdrawn flagged), warnings, the complete part's size."""

    columns: list[str]
    rows: list[LoggedRow]
    warnings: list[str]
    good_size: int
    partial: bytes = b""
    withdrawn: set[int] = field(default_factory=set)


def parse_rows(data: bytes, where: str = ROWS_FILE) -> RowsContent:
    """Parse rows.csv bytes; an unfinished last line (no newline) is returned in ``partial``, not parsed."""
    warnings: list[str] = []
    end = data.rfind(b"\n") + 1
    complete, partial = data[:end], data[end:]
    try:
        # A byte-order mark (a spreadsheet's "CSV UTF-8") is accepted; the sizes stay those of the bytes.
        text = decode_text(complete, where)
    except FileFormatError as exc:
        raise SessionError(str(exc)) from None
    lines = text.split("\n")[:-1]  # records end with "\n"; other line breaks may sit inside quoted notes
    if not lines:
        raise SessionError(f"{where}: no header row")
    try:
        header = next(csv_text_reader(lines[0]), [])  # an empty first line has no fields
    except csv.Error as exc:
        raise SessionError(f"{where}: the header row is not CSV ({exc})") from None
    header = [name.strip() for name in header]
    if tuple(header[: len(REQUIRED_COLUMNS)]) != REQUIRED_COLUMNS:
        raise SessionError(
            f"{where}: the header does not start with the required columns {','.join(REQUIRED_COLUMNS)}"
        )
    rows: list[LoggedRow] = []
    by_number: dict[int, LoggedRow] = {}
    withdrawn: set[int] = set()
    for lineno, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        if "\x00" in line:
            warnings.append(f"{where} line {lineno}: contains NUL bytes (damaged); ignored")
            continue
        try:
            fields = next(csv_text_reader(line), [])
        except csv.Error as exc:  # e.g. a field over MAX_FIELD_CHARS written by another program
            warnings.append(f"{where} line {lineno}: not a CSV record ({exc}); ignored")
            continue
        values = dict(zip(header, fields, strict=False))
        if len(fields) != len(header):
            warnings.append(f"{where} line {lineno}: {len(fields)} fields, the header has {len(header)}")
        row_text = values.get("row", "").strip()
        target = values.get("withdraws", "").strip()
        if row_text:
            try:
                number = int(row_text)
            except ValueError:
                warnings.append(f"{where} line {lineno}: row {row_text!r} is not a number; ignored")
                continue
            if number in by_number:
                warnings.append(f"{where} line {lineno}: row {number} appears twice; both kept")
            verdict = values.get("pass", "")
            normal = PASS_WORDS.get(verdict.strip().lower())
            if normal is None:
                warnings.append(
                    f"{where} line {lineno}: row {number} has pass {verdict!r}, not 1 or 0; counted as failed"
                )
                normal = "0"
            elif normal != verdict:
                shown = "passed" if normal == "1" else "failed"
                warnings.append(f"{where} line {lineno}: row {number} has pass {verdict!r}, read as {shown}")
            values["pass"] = normal
            row = LoggedRow(number, values)
            rows.append(row)
            by_number[number] = row
        elif target:
            try:
                withdrawn.add(int(target))
            except ValueError:
                warnings.append(f"{where} line {lineno}: withdraws {target!r} is not a row number; ignored")
        else:
            warnings.append(f"{where} line {lineno}: neither a row nor a withdrawal record; ignored")
    for row in rows:
        row.withdrawn = row.number in withdrawn
    return RowsContent(header, rows, warnings, len(complete), partial, withdrawn)


def _read_folder(folder: Path) -> tuple[SessionInfo, Path, RowsContent]:
    """A session folder's info, the path of its rows.csv and its parsed rows; SessionError if unreadable."""
    info = _read_info(folder)
    rows_path = folder / ROWS_FILE
    try:
        data = read_bytes(rows_path, "rows file", MAX_ROWS_BYTES)
    except FileFormatError as exc:
        if exc.kind == "missing":
            raise SessionError(f"{folder}: no {ROWS_FILE}") from None
        raise SessionError(str(exc)) from None
    return info, rows_path, parse_rows(data, str(rows_path))


def read_session(path: str | os.PathLike[str]) -> tuple[SessionInfo, RowsContent]:
    """Read a session without changing anything (for analysis): its info and rows.

    An unfinished last line is reported in the warnings and left where it is.
    """
    folder = Path(path)
    info, rows_path, content = _read_folder(folder)
    if content.partial:
        content.warnings.append(
            f"{rows_path}: ends with an unfinished line of {len(content.partial)} bytes "
            "(a crash while logging; never confirmed); ignored"
        )
    return info, content


def _read_info(folder: Path) -> SessionInfo:
    if not folder.is_dir():
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
class Session:
    """An open experiment session: log rows, withdraw them, retry pending writes.

    Create with :meth:`create`, reopen (resume) with :meth:`open`. ``log``, ``undo``, ``withdraw``
    and ``retry`` never raise for a failed write: they return a :class:`LogOutcome`.
    """

    def __init__(self, path: Path, info: SessionInfo, content: RowsContent, file_ops: FileOps | None):
        self.path = path
        self.info = info
        self.columns = list(content.columns)
        self.rows: list[LoggedRow] = content.rows
        self.warnings: list[str] = list(content.warnings)
        self.pending: list[_Record] = []
        self.next_row = max((r.number for r in self.rows), default=0) + 1
        self._ops = file_ops or FileOps()
        self._fd: int | None = None
        self._good_size = content.good_size
        self._withdrawn = set(content.withdrawn)
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
        root_path = Path(root)
        try:
            make_folder(root_path, "sessions folder")  # never the folders above one the user named
        except OSError as exc:
            raise SessionError(str(exc)) from None
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
        info, rows_path, content = _read_folder(folder)
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
        """Change the notes (and operator) in session.json, atomically. Raises OSError if it cannot."""
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
        try:  # refused before it is numbered: a field the csv module cannot read back
            check_field_sizes(values, f"row {number}")
        except FileFormatError as exc:
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
        row = next((r for r in self.rows if r.number == number), None)
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
            try:
                self._append(record.line)
            except (OSError, SessionError) as exc:
                error = exc
                self.close()  # reconnect (and re-check the file's end) on the next attempt
                break
            self.pending.pop(0)
            if record.row is not None:
                record.row.confirmed = True
            logged.append(record.label)
        waiting = tuple(r.label for r in self.pending)
        if error is None:
            message = (
                f"logged {what}"
                if row is not None
                else (f"logged {len(logged)} pending record(s)" if logged else "nothing pending")
            )
            return LogOutcome("logged", row, tuple(logged), waiting, message)
        reason = _explain(error) if isinstance(error, OSError) else str(error)
        message = (
            f"NOT logged yet: cannot write {self.rows_path} ({reason}). "
            f"{len(waiting)} record(s) kept in memory and retried before the next row; "
            "free space or fix permissions, then Retry. Do not close the app until they are written."
        )
        return LogOutcome("pending", row, tuple(logged), waiting, message)

    def _connect(self) -> None:
        """Open rows.csv for appending and lock it (the end of the file is checked by each append)."""
        if self._fd is not None:
            return
        fd = self._ops.open(str(self.rows_path), os.O_RDWR | os.O_APPEND)
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
        if not self._repair_tail(expected=line):
            written = self._ops.write(self._fd, line)
            if written != len(line):
                raise OSError(errno.ENOSPC, f"short write: {written} of {len(line)} bytes")
        self._ops.fsync(self._fd)
        self._good_size += len(line)


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
