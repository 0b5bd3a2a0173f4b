"""Experiment plans: a CSV of target poses, generated from the study's combinations or written by hand.

Format (docs/conventions.md, "Guided experiments and the session report"): UTF-8 CSV (a
spreadsheet's byte-order mark accepted), a header row naming the columns :data:`PLAN_COLUMNS`
(``x,y,z`` in mm, the QR centre in the camera frame; ``alpha,beta,gamma`` in degrees,
R = Rx(alpha) Ry(beta) Rz(gamma); ``combo``, the rotation combination; ``note``, optional), in any
order, then one target per line. Lines starting with ``#`` are comments. Target K is the K-th data
line (1-based): the number the guide, the progress file and the report use.

Every value is read by the ground-truth rules (:func:`qrfield.sessions.validate_field`: a unit
after the number is allowed, a decimal comma too, ranges checked), and ``combo`` must be a known
combination whose signs the angles have (:mod:`qrfield.sessions.combo_signs`). Each problem is
reported as ``<file> line L (target K), column 'beta': <why>``; all of a file's problems are
collected in one :class:`PlanError` (``problems``), so a hand-written plan is fixed in one pass.

:func:`generate_plan` makes the plan of the simulation study's combinations (its data file,
``qrfield/data/combinations-default.csv`` by default): for each combination and each tilt
magnitude t, the angles t x the combination's multipliers at one position.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from qrfield.sessions.combo_signs import combination_mismatch
from qrfield.sessions.groundtruth import ANGLE_FIELDS, POSITION_FIELDS, GroundTruth, validate_field

#: The plan's columns, in the order a generated plan writes them.
PLAN_COLUMNS = (*POSITION_FIELDS, *ANGLE_FIELDS, "combo", "note")
#: Columns a plan must have (``note`` may be left out).
REQUIRED_PLAN_COLUMNS = PLAN_COLUMNS[:-1]
#: Most targets in one plan (a day at the bench is a few hundred).
MAX_TARGETS = 10_000
#: Largest plan file read, bytes.
MAX_PLAN_BYTES = 4 * 1024 * 1024
#: Problems listed in a PlanError's message (all of them are in ``problems``).
SHOWN_PROBLEMS = 8
#: Longest note, characters.
MAX_NOTE_CHARS = 1000


class PlanError(ValueError):
    """A plan that cannot be used; ``problems`` lists each one (file, line, target, column, why)."""

    def __init__(self, problems: Sequence[str]) -> None:
        self.problems = list(problems)
        shown = self.problems[:SHOWN_PROBLEMS]
        more = len(self.problems) - len(shown)
        text = "; ".join(shown) + (f"; and {more} more problem(s)" if more > 0 else "")
        super().__init__(text)


@dataclass(frozen=True)
class PlanTarget:
    """One target pose of a plan: ``number`` (1-based), the pose as a ground truth, a note."""

    number: int
    truth: GroundTruth
    note: str = ""

    @property
    def combo(self) -> str:
        return self.truth.combo

    @property
    def tilt_deg(self) -> float:
        """The largest |angle| (degrees): the magnitude t the study sweeps for ±1 multipliers."""
        return max(abs(a) for a in self.truth.angles_deg)

    def describe(self) -> str:
        """E.g. ``target 3: alpha+beta- at x 0, y 0, z 300 mm, alpha 10, beta -10, gamma 0 deg``."""
        t = self.truth
        return (
            f"target {self.number}: {t.combo} at x {t.x:g}, y {t.y:g}, z {t.z:g} mm, "
            f"alpha {t.alpha:g}, beta {t.beta:g}, gamma {t.gamma:g} deg"
        )


def _signs(combinations_source: str) -> dict[str, tuple[float, float, float]]:
    from qrfield.simulation.combinations import load_combinations

    return {c.name: c.multipliers for c in load_combinations(combinations_source)}


def parse_plan(text: str, where: str = "plan", combinations: str = "default") -> list[PlanTarget]:
    """The targets of a plan's CSV text (see the module doc); PlanError listing every problem.

    ``combinations``: the combinations file the ``combo`` names come from ("default" = the study's).
    """
    table = _signs(combinations)
    lines = text.removeprefix("\ufeff").splitlines()
    numbered = [(n, line) for n, line in enumerate(lines, start=1) if line.strip()]
    numbered = [(n, line) for n, line in numbered if not line.lstrip().startswith("#")]
    if not numbered:
        raise PlanError([f"{where}: empty (no header row {','.join(PLAN_COLUMNS)})"])
    try:
        rows = [next(csv.reader(io.StringIO(line)), []) for _, line in numbered]
    except csv.Error as exc:
        raise PlanError([f"{where}: not CSV ({exc})"]) from None
    header_line, header = numbered[0][0], [cell.strip().lower() for cell in rows[0]]
    problems = _header_problems(header, f"{where} line {header_line}")
    if problems:
        raise PlanError(problems)
    if len(numbered) - 1 > MAX_TARGETS:
        raise PlanError([f"{where}: {len(numbered) - 1} targets, more than {MAX_TARGETS}"])
    targets: list[PlanTarget] = []
    for number, ((lineno, _), cells) in enumerate(zip(numbered[1:], rows[1:], strict=True), start=1):
        place = f"{where} line {lineno} (target {number})"
        target, row_problems = _parse_row(header, cells, number, place, table)
        problems += row_problems
        if target is not None:
            targets.append(target)
    if not problems and not targets:
        problems.append(f"{where}: no targets after the header")
    if problems:
        raise PlanError(problems)
    return targets


def _header_problems(header: list[str], place: str) -> list[str]:
    problems = []
    for name in header:
        if name not in PLAN_COLUMNS:
            problems.append(f"{place}: unknown column {name!r} (columns: {','.join(PLAN_COLUMNS)})")
    for name in REQUIRED_PLAN_COLUMNS:
        if name not in header:
            problems.append(f"{place}: no column {name!r} (a plan needs {','.join(REQUIRED_PLAN_COLUMNS)})")
    twice = sorted({name for name in header if header.count(name) > 1})
    if twice:
        problems.append(f"{place}: column(s) {', '.join(twice)} named twice")
    return problems


def _parse_row(
    header: list[str],
    cells: list[str],
    number: int,
    place: str,
    table: dict[str, tuple[float, float, float]],
) -> tuple[PlanTarget | None, list[str]]:
    if len(cells) > len(header):
        return None, [f"{place}: {len(cells)} values, the header has {len(header)} columns"]
    values = dict(zip(header, cells, strict=False))
    problems: list[str] = []
    parsed: dict[str, object] = {}
    for name in REQUIRED_PLAN_COLUMNS:
        text = values.get(name, "")
        value, message = validate_field(name, text, list(table))
        if message:
            problems.append(f"{place}, column {name!r}: {message}")
        else:
            parsed[name] = value
    note = values.get("note", "").strip()
    if any(ch in note for ch in "\r\n") or len(note) > MAX_NOTE_CHARS:
        problems.append(f"{place}, column 'note': must be one line of at most {MAX_NOTE_CHARS} characters")
    if problems:
        return None, problems
    truth = GroundTruth(**parsed)  # type: ignore[arg-type]
    mismatch = combination_mismatch(truth.combo, truth.angles_deg, table)
    if mismatch:
        return None, [f"{place}, column 'combo': {mismatch}"]
    return PlanTarget(number, truth, note), []


def read_plan(path: str | os.PathLike[str], combinations: str = "default") -> list[PlanTarget]:
    """The targets of the plan file ``path``; PlanError (naming the file, line and column) if unusable."""
    from qrfield.files import FileFormatError, read_text

    try:
        text = read_text(path, "plan", max_bytes=MAX_PLAN_BYTES)
    except FileFormatError as exc:
        raise PlanError([str(exc)]) from None
    return parse_plan(text, where=str(path), combinations=combinations)


def _number_text(value: float) -> str:
    text = f"{float(value):.3f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def plan_text(targets: Sequence[PlanTarget]) -> str:
    """The CSV text of a plan: the header :data:`PLAN_COLUMNS`, one line per target (0.001 steps)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(PLAN_COLUMNS)
    for target in targets:
        t = target.truth
        numbers = [_number_text(v) for v in (*t.position_mm, *t.angles_deg)]
        writer.writerow([*numbers, t.combo, target.note])
    return buf.getvalue()


def write_plan(
    path: str | os.PathLike[str], targets: Sequence[PlanTarget], *, overwrite: bool = False
) -> Path:
    """Write a plan all or nothing (never over an existing file unless ``overwrite``); its path."""
    from qrfield.files import atomic_write

    return atomic_write(path, plan_text(targets), overwrite=overwrite)


def generate_plan(
    combos: str | Sequence[str],
    angles_deg: Sequence[float],
    z_mm: float,
    x_mm: float = 0.0,
    y_mm: float = 0.0,
    combinations: str = "default",
) -> list[PlanTarget]:
    """The targets of the study's combinations at tilt magnitudes ``angles_deg`` (degrees) and
    position (x, y, z) in mm (camera frame): for each combination in the file's order, each
    magnitude t in the order given, angles = t x the combination's multipliers.

    ``combos``: "all" or names of the combinations file ``combinations`` ("default" = the shipped
    study's 12). ValueError naming the option for an unknown name, a negative or repeated
    magnitude, or an angle or position outside the ground-truth ranges.
    """
    from qrfield.simulation.combinations import load_combinations

    known = load_combinations(combinations)
    by_name = {c.name: c for c in known}
    if isinstance(combos, str):
        names = [c.name for c in known] if combos.strip().lower() == "all" else _split(combos)
    else:
        names = [str(n).strip() for n in combos]
    if not names:
        raise ValueError("--combos: name at least one combination, or 'all'")
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise ValueError(
            f"--combos: unknown combination(s) {', '.join(unknown)}; known: {', '.join(by_name)}"
        )
    if len(set(names)) != len(names):
        raise ValueError(f"--combos: a combination is named twice: {', '.join(names)}")
    magnitudes = [float(a) for a in angles_deg]
    if not magnitudes:
        raise ValueError("--angles: give at least one tilt magnitude in degrees, e.g. 10,20,30")
    if any(not math.isfinite(a) for a in magnitudes):
        raise ValueError(f"--angles: every magnitude must be a finite number of degrees, got {magnitudes}")
    if any(a < 0 for a in magnitudes):
        raise ValueError(
            f"--angles: magnitudes are >= 0 degrees (the study sweeps t from 0 up; each combination "
            f"gives the signs), got {', '.join(f'{a:g}' for a in magnitudes)}"
        )
    if len(set(magnitudes)) != len(magnitudes):
        raise ValueError(f"--angles: a magnitude is given twice: {magnitudes}")
    position = {"x": x_mm, "y": y_mm, "z": z_mm}
    for name, value in position.items():
        _, message = validate_field(name, value)
        if message:
            raise ValueError(f"--{name}-mm: {message}")
    targets = []
    for name in names:
        combo = by_name[name]
        for t in magnitudes:
            angles = [float(v) + 0.0 for v in combo.angles_deg([t])[0]]
            for axis, value in zip(ANGLE_FIELDS, angles, strict=True):
                _, message = validate_field(axis, value)
                if message:
                    raise ValueError(f"--angles {t:g}: {name} gives {axis} = {value:g} deg: {message}")
            truth = GroundTruth(float(x_mm), float(y_mm), float(z_mm), *angles, combo=name)
            targets.append(PlanTarget(len(targets) + 1, truth))
    if len(targets) > MAX_TARGETS:
        raise ValueError(f"{len(targets)} targets, more than {MAX_TARGETS}: fewer combinations or angles")
    return targets


def _split(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]
