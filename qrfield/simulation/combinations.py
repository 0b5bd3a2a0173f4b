"""Rotation combinations of the simulation study: which angles the swept tilt drives, and with what sign.

A combination is a name and three multipliers (m_alpha, m_beta, m_gamma): at swept magnitude t
(degrees) the card's angles are (alpha, beta, gamma) = t * (m_alpha, m_beta, m_gamma), with
R = Rx(alpha) Ry(beta) Rz(gamma) (docs/conventions.md). The seed simulated 12 combinations without listing
them; our default set (``qrfield/data/combinations-default.csv``) is the single axes, the three pairs
with equal and with opposite signs, and the triples (+,+,+), (+,+,-), (+,-,+).

File format (CSV, UTF-8): lines starting with ``#`` are comments; a header ``name,alpha,beta,gamma``;
then one combination per line, e.g. ``alpha+beta-,1,-1,0``.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from qrfield.files import FileFormatError, csv_text_reader, read_text
from qrfield.geometry import ANGLE_NAMES
from qrfield.limits import LimitError, as_number

#: The ``combinations`` study value that names the shipped default set.
DEFAULT_NAME = "default"
HEADER = ("name", "alpha", "beta", "gamma")


class CombinationError(ValueError):
    """A combinations file that cannot be used; the message names the file, line and field."""


@dataclass(frozen=True)
class Combination:
    """One rotation combination: ``angles(t) = t * multipliers`` (degrees)."""

    name: str
    multipliers: tuple[float, float, float]

    def angles_deg(self, magnitudes_deg: np.ndarray) -> np.ndarray:
        """(A, 3) alpha, beta, gamma in degrees for swept magnitudes (A,) in degrees."""
        t = np.asarray(magnitudes_deg, dtype=float).reshape(-1, 1)
        return t * np.asarray(self.multipliers, dtype=float)

    def describe(self) -> str:
        """E.g. ``alpha=+t, beta=-t`` (zero multipliers left out)."""
        parts = []
        for axis, m in zip(ANGLE_NAMES, self.multipliers, strict=True):
            if m == 0:
                continue
            sign = "+" if m > 0 else "-"
            factor = "" if abs(m) == 1 else f"{abs(m):g}"
            parts.append(f"{axis}={sign}{factor}t")
        return ", ".join(parts)


def default_path() -> Path:
    """The shipped default combinations file."""
    return Path(str(resources.files("qrfield.data") / "combinations-default.csv"))


def load_combinations(source: str | Path) -> list[Combination]:
    """Combinations from a CSV file (``"default"`` = the shipped set); CombinationError if unusable."""
    path = default_path() if str(source) == DEFAULT_NAME else Path(source)
    try:  # qrfield.files: bounded, a spreadsheet's byte-order mark accepted
        text = read_text(path, "combinations file", max_bytes=1024 * 1024)
    except FileFormatError as exc:
        raise CombinationError(str(exc)) from None
    return parse_combinations(text, where=f"combinations file {path}")


def parse_combinations(text: str, where: str = "combinations") -> list[Combination]:
    """Parse the CSV text of a combinations file (see the module docstring)."""
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip()]
    lines = [(n, line) for n, line in lines if not line.lstrip().startswith("#")]
    if not lines:
        raise CombinationError(f"{where}: no header and no combinations")
    try:
        rows = list(csv_text_reader("\n".join(line for _, line in lines)))
    except csv.Error as exc:  # a field longer than the csv module's limit, a NUL byte
        raise CombinationError(f"{where}: not CSV ({exc})") from None
    if len(rows) != len(lines):  # a quoted field spanning lines
        raise CombinationError(f"{where}: a quoted field spans lines; one combination per line")
    header = tuple(cell.strip().lower() for cell in rows[0])
    if header != HEADER:
        raise CombinationError(
            f"{where}, line {lines[0][0]}: header must be {','.join(HEADER)}, got {','.join(header)}"
        )
    out: list[Combination] = []
    names: set[str] = set()
    for (lineno, _), row in zip(lines[1:], rows[1:], strict=True):
        if len(row) != 4:
            raise CombinationError(
                f"{where}, line {lineno}: expected 4 fields name,alpha,beta,gamma, got {len(row)}"
            )
        name = row[0].strip()
        if not name:
            raise CombinationError(f"{where}, line {lineno}: empty name")
        if name in names:
            raise CombinationError(f"{where}, line {lineno}: name {name!r} used twice")
        values = []
        for field, cell in zip(HEADER[1:], row[1:], strict=True):
            try:
                float(cell)
            except ValueError:
                raise CombinationError(
                    f"{where}, line {lineno}: field '{field}' must be a number (+1, -1, 0), "
                    f"got {cell.strip()[:40]!r}"
                ) from None
            try:
                value = as_number(cell, f"{where}, line {lineno}: field '{field}'", "the multiplier")
            except LimitError as exc:
                raise CombinationError(str(exc)) from None
            values.append(value + 0.0)  # no negative zero
        if not any(values):
            raise CombinationError(f"{where}, line {lineno}: combination {name!r} rotates about no axis")
        names.add(name)
        out.append(Combination(name, (values[0], values[1], values[2])))
    if not out:
        raise CombinationError(f"{where}: no combinations after the header")
    return out
