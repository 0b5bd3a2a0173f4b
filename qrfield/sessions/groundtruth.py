"""Ground truth typed by the operator: parse and validate each field, with a message per field.

Fields (docs/conventions.md units): ``x``, ``y``, ``z`` in mm (the QR centre in the camera frame: +X right,
+Y down, +Z forward along the optical axis); ``alpha``, ``beta``, ``gamma`` in degrees
(R = Rx(alpha) Ry(beta) Rz(gamma), marker to camera); ``combo``, the rotation combination's name.

Rules (every one gives a message naming the field, never a half row):
  - a number, optionally followed by the field's own unit: ``300``, ``300 mm``, ``12.5deg``,
    ``12.5 °``. Another unit (``30 cm``, ``0.2 rad``) is refused rather than converted, so a
    slip is seen, not silently rescaled.
  - signs: ``-`` and ``+``, and the minus sign U+2212 and the full-width signs U+FF0D, U+FF0B
    (what an on-screen keyboard or a copied "−10" may give; full-width digits are read as digits).
  - decimal separator: the dot. A single comma is also read as the decimal separator
    (``12,5`` = 12.5, what a European keyboard gives) unless exactly three digits follow it
    (``1,000``), which could be a thousands separator and is refused as ambiguous. Digit grouping
    is never accepted.
  - ranges: |x|, |y| <= MAX_LATERAL_MM; 0 < z <= MAX_DEPTH_MM; beta in [-90, 90]; alpha and
    gamma in (-180, 180] (-180 is accepted and stored as 180, the same angle).
  - combo: one of the simulation's combination names when that list is given, else any
    non-empty text of one line.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from qrfield.files import describe_value
from qrfield.geometry import ANGLE_NAMES, POSITION_NAMES
from qrfield.limits import LimitError, as_number

#: Field names in form order, with their unit.
POSITION_FIELDS = POSITION_NAMES
ANGLE_FIELDS = ANGLE_NAMES
FIELDS = (*POSITION_FIELDS, *ANGLE_FIELDS, "combo")
UNITS = {"x": "mm", "y": "mm", "z": "mm", "alpha": "deg", "beta": "deg", "gamma": "deg", "combo": ""}

#: Largest |x| and |y| accepted (mm): far beyond any bench, so only slips are caught.
MAX_LATERAL_MM = 5000.0
#: Largest z accepted (mm).
MAX_DEPTH_MM = 10000.0
#: Longest combination name (characters).
MAX_COMBO_CHARS = 80

_UNIT_ALIASES = {
    "mm": ("mm", "millimetre", "millimetres", "millimeter", "millimeters"),
    "deg": ("deg", "degs", "degree", "degrees", "°", "º"),
}
#: Units recognised only to say "wrong unit" rather than "not a number".
_OTHER_UNITS = {u for aliases in _UNIT_ALIASES.values() for u in aliases} | {
    "cm",
    "m",
    "um",
    "µm",
    "in",
    "inch",
    "inches",
    '"',
    "ft",
    "rad",
    "mrad",
    "grad",
    "gon",
    "px",
}
#: Sign characters read as ASCII ``-`` / ``+``: the minus sign and the full-width minus and plus.
_SIGNS = str.maketrans({"\u2212": "-", "\uff0d": "-", "\uff0b": "+"})
_NUMBER = re.compile(r"^([+-]?(?:\d+(?:[.,]\d*)?|[.,]\d+)(?:[eE][+-]?\d+)?)\s*(.*)$")


class GroundTruthError(ValueError):
    """Ground truth that cannot be logged; ``errors`` maps each bad field to its message."""

    def __init__(self, errors: dict[str, str]):
        self.errors = dict(errors)
        super().__init__("; ".join(f"{name}: {message}" for name, message in self.errors.items()))


@dataclass(frozen=True)
class GroundTruth:
    """A hand-measured pose: position in mm (camera frame), angles in degrees, and its combination."""

    x: float
    y: float
    z: float
    alpha: float
    beta: float
    gamma: float
    combo: str

    @property
    def position_mm(self) -> tuple[float, float, float]:
        return (self.x, self.y, self.z)

    @property
    def angles_deg(self) -> tuple[float, float, float]:
        return (self.alpha, self.beta, self.gamma)

    def as_fields(self) -> dict[str, str]:
        """Texts for the form (what the form keeps for the next row), dots as decimal separators."""
        return truth_fields(self.position_mm, self.angles_deg, self.combo)


def truth_fields(
    position_mm: Sequence[float], angles_deg: Sequence[float], combo: str = ""
) -> dict[str, str]:
    """Form texts for a known pose (the virtual bench's true pose pre-fills the form with this).

    Position in mm (camera frame), angles (alpha, beta, gamma) in degrees; 0.001 mm and deg steps.
    """
    pos = [float(v) for v in position_mm]
    ang = [float(v) for v in angles_deg]
    if len(pos) != 3 or len(ang) != 3:
        raise ValueError(f"3 position values (mm) and 3 angles (deg) expected, got {len(pos)} and {len(ang)}")
    out = {name: _short(v) for name, v in zip((*POSITION_FIELDS, *ANGLE_FIELDS), (*pos, *ang), strict=True)}
    out["combo"] = combo
    return out


def _short(value: float) -> str:
    text = f"{value:.3f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def parse_number(text: Any, unit: str) -> float:
    """A finite number from ``text`` (see the module's rules); ValueError with a message otherwise.

    ``unit`` ("mm" or "deg") is the only unit accepted after the number.
    """
    if isinstance(text, bool):
        raise ValueError(f"expected a number in {unit}, got {text!r}")
    if isinstance(text, (int, float)):
        try:
            value = as_number(text, "the value", unit)  # a huge int would overflow float()
        except LimitError:
            raise ValueError(f"must be a finite number in {unit}, got {describe_value(text)}") from None
    else:
        if not isinstance(text, str):
            raise ValueError(f"expected a number in {unit}, got {text!r}")
        raw = text.strip()
        if not raw:
            raise ValueError(f"empty: type a number in {unit}")
        match = _NUMBER.match(raw.translate(_SIGNS))
        if match is None:
            raise ValueError(f"{raw!r} is not a number (expected e.g. 12.5 {unit})")
        number, rest = match.group(1), match.group(2).strip()
        if rest and rest.lower() not in _UNIT_ALIASES[unit]:
            if rest.lower() in _OTHER_UNITS:
                raise ValueError(f"{raw!r}: unit {rest!r} is not accepted here; type the value in {unit}")
            raise ValueError(f"{raw!r} is not a number (expected e.g. 12.5 {unit})")
        if "," in number:
            decimals = re.search(r",(\d*)", number)
            if decimals is not None and len(decimals.group(1)) == 3:
                raise ValueError(
                    f"{raw!r} is ambiguous (a thousands separator or a decimal comma?); "
                    f"type it with a dot, e.g. {number.replace(',', '.')} or {number.replace(',', '')}"
                )
            number = number.replace(",", ".")
        value = float(number)
    if not math.isfinite(value):
        raise ValueError(f"must be a finite number in {unit}, got {text!r}")
    return value


def _check_range(name: str, value: float) -> float:
    if name in ("x", "y"):
        if abs(value) > MAX_LATERAL_MM:
            raise ValueError(f"{value:g} mm is outside -{MAX_LATERAL_MM:g}..{MAX_LATERAL_MM:g} mm")
    elif name == "z":
        if value <= 0:
            raise ValueError(f"{value:g} mm: z must be > 0 (the card is in front of the camera)")
        if value > MAX_DEPTH_MM:
            raise ValueError(f"{value:g} mm is beyond {MAX_DEPTH_MM:g} mm")
    elif name == "beta":
        if abs(value) > 90.0:
            raise ValueError(f"{value:g} deg is outside -90..90 deg (beta = asin(R[0,2]))")
    elif name in ("alpha", "gamma"):
        if value < -180.0 or value > 180.0:
            raise ValueError(f"{value:g} deg is outside (-180, 180] deg (-180 is taken as 180)")
        if value == -180.0:
            value = 180.0  # the same angle; the convention's range is (-180, 180]
    return value


def validate_field(name: str, text: Any, combinations: Sequence[str] | None = None) -> tuple[Any, str]:
    """(value, "") for a good field, (None, message) for a bad one: for live checks in the form.

    ``name`` is one of FIELDS; positions come back in mm, angles in degrees, combo as stripped text.
    """
    if name not in FIELDS:
        raise KeyError(f"unknown ground-truth field {name!r}; fields are {', '.join(FIELDS)}")
    if name == "combo":
        return _validate_combo(text, combinations)
    try:
        value = parse_number(text, UNITS[name])
        return _check_range(name, value), ""
    except ValueError as exc:
        return None, str(exc)


def _validate_combo(text: Any, combinations: Sequence[str] | None) -> tuple[str | None, str]:
    if not isinstance(text, str) or not text.strip():
        if combinations:
            return None, f"empty: choose a combination ({', '.join(combinations)})"
        return None, "empty: name the rotation combination"
    name = text.strip()
    if any(ch in name for ch in "\r\n\t") or not name.isprintable():
        return None, "must be one line of printable text"
    if len(name) > MAX_COMBO_CHARS:
        return None, f"longer than {MAX_COMBO_CHARS} characters"
    if combinations and name not in combinations:
        return None, f"{name!r} is not a known combination ({', '.join(combinations)})"
    return name, ""


def check_ground_truth(
    fields: Mapping[str, Any], combinations: Sequence[str] | None = None
) -> tuple[GroundTruth | None, dict[str, str]]:
    """Validate every field: (GroundTruth, {}) or (None, {field: message, ...}).

    ``fields`` maps each of FIELDS to the text typed (or a number); a missing field is an error.
    ``combinations``: the allowed combination names (the simulation's list), or None for free text.
    """
    values: dict[str, Any] = {}
    errors: dict[str, str] = {}
    for name in FIELDS:
        if name not in fields:
            errors[name] = "missing"
            continue
        value, message = validate_field(name, fields[name], combinations)
        if message:
            errors[name] = message
        else:
            values[name] = value
    unknown = sorted(set(fields) - set(FIELDS))
    for name in unknown:
        errors[name] = f"unknown field (fields are {', '.join(FIELDS)})"
    if errors:
        return None, errors
    return GroundTruth(**values), {}


def parse_ground_truth(fields: Mapping[str, Any], combinations: Sequence[str] | None = None) -> GroundTruth:
    """Like :func:`check_ground_truth` but raises GroundTruthError (with ``.errors``) if any field is bad."""
    truth, errors = check_ground_truth(fields, combinations)
    if truth is None:
        raise GroundTruthError(errors)
    return truth


def known_combinations(source: str = "default") -> list[str] | None:
    """The simulation's combination names (``source``: "default" or a combinations CSV file),
    or None when the list cannot be read (free text then)."""
    from qrfield.simulation.combinations import load_combinations

    try:
        names = [c.name for c in load_combinations(source)]
    except (ValueError, OSError, AttributeError, TypeError):
        return None
    return names or None
