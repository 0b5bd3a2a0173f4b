"""Which rotation combination a ground-truth pose belongs to, from the signs of its angles.

The simulation (qrfield/simulation/combinations.py) tilts the card by a magnitude t >= 0 along a
combination's multipliers: (alpha, beta, gamma) = t * (m_alpha, m_beta, m_gamma), degrees,
R = Rx(alpha) Ry(beta) Rz(gamma) (docs/conventions.md). So a pose belongs to a combination when
each angle has the sign of its multiplier: alpha > 0, beta < 0, gamma = 0 is ``alpha+beta-``.
A hand-measured angle within :data:`ZERO_ANGLE_DEG` of 0 counts as 0 (a protractor reads to
about a degree). A pose with every angle at 0 (t = 0) belongs to every combination.

The app suggests the combination from the angles typed (or followed from the virtual bench) and
asks before it logs a row whose label disagrees with its angles.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

#: |angle| (deg) at or below which a hand-measured angle counts as no tilt about its axis.
ZERO_ANGLE_DEG = 1.0
SYMBOLS = ("α", "β", "γ")

Signs = tuple[int, int, int]


def _sign(value: float, zero: float) -> int:
    return 0 if abs(value) <= zero else (1 if value > 0 else -1)


def angle_signs(angles_deg: Sequence[float], zero_deg: float = ZERO_ANGLE_DEG) -> Signs:
    """(s_alpha, s_beta, s_gamma) in {-1, 0, 1} of alpha, beta, gamma in degrees."""
    values = [float(a) for a in angles_deg]
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"three finite angles alpha, beta, gamma (deg) expected, got {angles_deg!r}")
    return (_sign(values[0], zero_deg), _sign(values[1], zero_deg), _sign(values[2], zero_deg))


def signs_text(signs: Signs) -> str:
    """E.g. ``α+ β− γ0``."""
    marks = {1: "+", -1: "−", 0: "0"}
    return " ".join(f"{s}{marks[v]}" for s, v in zip(SYMBOLS, signs, strict=True))


def sign_table(source: str = "default") -> dict[str, tuple[float, float, float]] | None:
    """The simulation's combinations (``source``: "default" or a combinations CSV) as
    {name: (m_alpha, m_beta, m_gamma)}; None when they cannot be read (no suggestion then)."""
    try:
        from qrfield.simulation.combinations import load_combinations
    except ImportError:
        return None
    try:
        return {c.name: c.multipliers for c in load_combinations(source)}
    except (ValueError, OSError):
        return None


def _multiplier_signs(multipliers: Sequence[float]) -> Signs:
    return angle_signs(multipliers, zero_deg=0.0)


def suggest_combination(
    angles_deg: Sequence[float], table: Mapping[str, Sequence[float]] | None
) -> str | None:
    """The combination whose multipliers have the signs of the angles (deg); None when every
    angle is about 0 (any combination fits) or no combination has those signs. Of several with
    the same signs, the one whose direction is nearest (largest cosine) to the angles."""
    if not table:
        return None
    signs = angle_signs(angles_deg)
    if signs == (0, 0, 0):
        return None
    matches = [name for name, m in table.items() if _multiplier_signs(m) == signs]
    if len(matches) <= 1:
        return matches[0] if matches else None
    a = [float(v) for v in angles_deg]

    def cosine(name: str) -> float:
        m = [float(v) for v in table[name]]
        return sum(x * y for x, y in zip(a, m, strict=True)) / math.hypot(*m)

    return max(matches, key=cosine)


def combination_mismatch(
    name: str, angles_deg: Sequence[float], table: Mapping[str, Sequence[float]] | None
) -> str:
    """Why the label ``name`` disagrees with the angles (deg), or "" when it agrees (or when the
    label or the list is unknown, or every angle is about 0)."""
    if not table or name not in table:
        return ""
    signs = angle_signs(angles_deg)
    if signs == (0, 0, 0):
        return ""
    wanted = _multiplier_signs(table[name])
    if wanted == signs:
        return ""
    shown = ", ".join(f"{float(v):g}" for v in angles_deg)
    suggestion = suggest_combination(angles_deg, table)
    fits = f"they fit '{suggestion}'" if suggestion else "no combination of the list has these signs"
    return (
        f"the angles ({shown}) deg have the signs {signs_text(signs)}, but '{name}' means "
        f"{signs_text(wanted)}; {fits}"
    )
