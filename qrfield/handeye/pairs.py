"""Hand-eye pairs: read from ``pairs.csv``, or collected from a running frame loop.

``pairs.csv`` (docs/conventions.md, "Hand-eye"): UTF-8 (a byte-order mark is accepted), a header
row naming the columns ``x,y,z,qw,qx,qy,qz,image`` in any order (more columns are ignored), one row
per robot pose: the tool frame's position in the base frame (mm) and its orientation as a unit
quaternion (qw, qx, qy, qz), and the image taken there (a path relative to the CSV's folder).
Blank lines and lines starting with ``#`` are skipped. A bad value is one line naming the file,
the line and the column (:func:`read_pairs_csv`).

:class:`PairCollector` records pairs from the frame loop (a sink: ``on_result``): armed with a
tool pose (:meth:`PairCollector.expect`), it takes the next result captured after that whose pose
converged and is not ambiguous (:func:`qrfield.handeye.measure.pair_problem`); :meth:`PairCollector.solve`
solves the pairs so far. It is the core of serial protocol 2's ``$QRC,TOOL`` and ``$QRC,HANDEYE``
(:mod:`qrfield.serial.handeye`: :meth:`PairCollector.expect`, :meth:`PairCollector.solve`), docs/handeye.md.
"""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.files import csv_text_reader, read_text
from qrfield.handeye.measure import pair_problem, pair_problem_kind
from qrfield.handeye.rigid import transform_from_quaternion
from qrfield.handeye.setups import HandEyeError
from qrfield.handeye.solve import HandEyeResult, Pair, solve_handeye
from qrfield.limits import TOOL_POSITION_MM, LimitError
from qrfield.seams import BaseSink

#: The columns pairs.csv must have.
COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz", "image")
#: Most rows read from one pairs.csv (a calibration takes 5-50).
MAX_ROWS = 10_000


@dataclass(frozen=True)
class ToolRow:
    """One row of pairs.csv: the tool pose T_base_tool (4, 4, mm), the image's path (relative ones
    resolved against the CSV's folder), the image as written (the pair's label) and the line number."""

    tool_in_base: np.ndarray
    image: Path
    label: str
    line: int


def read_pairs_csv(path: str | os.PathLike[str]) -> list[ToolRow]:
    """The rows of a pairs.csv; HandEyeError (one line: file, line, column) for anything wrong."""
    path = Path(path)
    text = read_text(path, "pairs file")  # FileFormatError (a ValueError) names the file
    rows = [(n, row) for n, row in enumerate(csv_text_reader(text), start=1)]
    rows = [
        (n, row) for n, row in rows if any(c.strip() for c in row) and not row[0].lstrip().startswith("#")
    ]
    if not rows:
        raise HandEyeError(f"pairs file {path}: empty; expected a header row {','.join(COLUMNS)}")
    line, header = rows[0]
    names = [c.strip().lower() for c in header]
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        raise HandEyeError(
            f"pairs file {path} line {line}: the header lacks the column(s) {', '.join(missing)} "
            f"(expected {','.join(COLUMNS)})"
        )
    index = {c: names.index(c) for c in COLUMNS}
    if len(rows) - 1 > MAX_ROWS:
        raise HandEyeError(f"pairs file {path}: {len(rows) - 1} rows, more than {MAX_ROWS}")
    out = []
    for line, row in rows[1:]:
        where = f"pairs file {path} line {line}"
        if len(row) < len(names):
            raise HandEyeError(f"{where}: {len(row)} values, the header has {len(names)} columns")
        values = {}
        for column in COLUMNS[:-1]:
            text_value = row[index[column]].strip()
            try:
                values[column] = float(text_value)
            except ValueError:
                raise HandEyeError(
                    f"{where}: column {column}: expected a number, got {text_value!r}"
                ) from None
        try:
            for column in "xyz":
                TOOL_POSITION_MM.check(values[column], f"{where}: column {column}")
            tool = transform_from_quaternion(
                [values["x"], values["y"], values["z"]],
                [values["qw"], values["qx"], values["qy"], values["qz"]],
                f"{where}: qw,qx,qy,qz",
            )
        except (LimitError, ValueError) as exc:
            raise HandEyeError(str(exc)) from None
        label = row[index["image"]].strip()
        if not label:
            raise HandEyeError(f"{where}: column image is empty")
        image = Path(label).expanduser()
        out.append(ToolRow(tool, image if image.is_absolute() else path.parent / image, label, line))
    if not out:
        raise HandEyeError(f"pairs file {path}: a header and no rows")
    return out


#: A :attr:`PairCollector.last_problem` beside pair_problem_kind's: the frame's source is live and
#: the pairs so far are from a simulated one, or the other way round (never mixed in one set).
SOURCE_CHANGED = "source changed"


class PairCollector(BaseSink):
    """Hand-eye pairs from a frame loop (thread-safe: results arrive on the loop's thread, the
    rest is called from another, e.g. the serial command handler).

    ``method``: the pose method whose result makes the pair (None: the result's first). The pairs
    of one set all come from a live camera or all from a source that is not one (the virtual
    bench, a video, a folder: :attr:`simulated`); a frame of the other kind makes no pair
    (SOURCE_CHANGED) until :meth:`clear`.
    """

    def __init__(self, method: str | None = None) -> None:
        self.method = method
        self._lock = threading.Lock()
        self._pairs: list[Pair] = []
        self._simulated = False
        self._waiting: tuple[np.ndarray, str, float] | None = None
        self._done = threading.Event()
        #: Why the results seen while waiting made no pair (the latest last), for the caller's answer.
        self.passed_over: list[str] = []
        #: The kind (qrfield.handeye.measure.pair_problem_kind) of the latest of them ("" if none).
        self.last_problem = ""

    # ----- frame-loop sink (the loop's thread)
    def on_result(self, result: Any, simulated: bool) -> None:
        with self._lock:
            waiting = self._waiting
            if waiting is None:
                return
            tool, label, armed_at = waiting
            # Captured after the tool pose was given: the robot was there (t_capture: time.monotonic()
            # of the capture; else latency_ms, capture to the result).
            captured = float(getattr(result, "t_capture", math.nan))
            if not math.isfinite(captured):
                latency = float(getattr(result, "latency_ms", 0.0) or 0.0)
                captured = time.monotonic() - (latency / 1000.0 if math.isfinite(latency) else 0.0)
            if captured < armed_at:
                return
            if self._pairs and bool(simulated) != self._simulated:
                self.last_problem = SOURCE_CHANGED
                self.passed_over.append(
                    f"frame {result.index}: the source changed: the pairs so far are from "
                    f"{'a simulated source' if self._simulated else 'a live camera'}, this frame is not "
                    "(clear the pairs to start again)"
                )
                del self.passed_over[:-20]
                return
            pose = result.poses.get(self.method) if self.method else result.primary
            kind = pair_problem_kind(pose)
            if kind:
                self.last_problem = kind
                self.passed_over.append(f"frame {result.index}: {pair_problem(pose)}")
                del self.passed_over[:-20]
                return
            self._pairs.append(Pair.from_pose(tool, pose, label or f"frame {result.index}"))
            self._simulated = bool(simulated)
            self._waiting = None
            self._done.set()

    # ----- the caller's thread
    def expect(self, tool_in_base: np.ndarray, label: str = "") -> None:
        """Record a pair at tool pose T_base_tool (4, 4) with the next usable result captured from
        now on (replaces a pose still waiting)."""
        tool = Pair(tool_in_base, np.eye(4)).tool_in_base  # checked as a rigid transform
        with self._lock:
            self._waiting = (tool, label, time.monotonic())
            self.passed_over = []
            self.last_problem = ""
            self._done.clear()

    def wait(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the expected pair; True when it was recorded (False: still
        waiting, and :attr:`passed_over` says why the frames so far were not taken)."""
        return self._done.wait(timeout_s)

    def record(self, tool_in_base: np.ndarray, timeout_s: float, label: str = "") -> int:
        """:meth:`expect` then :meth:`wait`: the number of pairs once this one is recorded, or
        HandEyeError saying why no frame within ``timeout_s`` made one (what ``$QRC,TOOL`` answers)."""
        self.expect(tool_in_base, label)
        if not self.wait(timeout_s):
            self.cancel()
            why = self.passed_over[-1] if self.passed_over else "no frame measured"
            raise HandEyeError(f"no pair within {timeout_s:g} s: {why}")
        return len(self)

    def cancel(self) -> None:
        """Stop waiting for the expected pair."""
        with self._lock:
            self._waiting = None

    def add(self, pair: Pair, simulated: bool = False) -> int:
        """Add a pair made elsewhere; returns the number of pairs."""
        with self._lock:
            if self._pairs and simulated != self._simulated:
                raise HandEyeError("the pairs so far are from another kind of source (live or simulated)")
            self._pairs.append(pair)
            self._simulated = bool(simulated)
            return len(self._pairs)

    @property
    def simulated(self) -> bool:
        """The pairs come from a source that is not a live camera (False while there are none)."""
        with self._lock:
            return self._simulated and bool(self._pairs)

    @property
    def pairs(self) -> list[Pair]:
        with self._lock:
            return list(self._pairs)

    def __len__(self) -> int:
        with self._lock:
            return len(self._pairs)

    def clear(self) -> None:
        """Forget the pairs (and a pose still waiting): the next pair starts a new set."""
        with self._lock:
            self._pairs.clear()
            self._simulated = False
            self._waiting = None

    def solve(self, setup: str, **options: Any) -> HandEyeResult:
        """:func:`qrfield.handeye.solve_handeye` of the pairs so far (HandEyeError says what is missing)."""
        return solve_handeye(self.pairs, setup, **options)
