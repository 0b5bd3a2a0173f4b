"""Settings of experiment sessions: the acceptance criteria and how many frames make one row.

The criteria are the seed's (docs/conventions.md): each of alpha, beta, gamma within 2 degrees of the ground
truth (inclusive) and the position within 5 mm (Euclidean, strict), with at least one converged
frame. They are settings so that a study can tighten or loosen them; the values used are saved in
every session's ``session.json``.

The one home of the rule: :func:`pose_errors` (how far a pose is from its truth) and
:meth:`AcceptanceCriteria.judge` (whether that passes), used by a session row
(:func:`qrfield.sessions.averaging.judge_row`), the simulation study, the benchmarks and the app's
verdict against the virtual bench's true pose; and :meth:`AcceptanceCriteria.grade`, the colour of
a guided experiment's live difference to its target (:data:`GOOD`, :data:`NEAR`, :data:`FAR`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.geometry import angle_difference
from qrfield.settings import setting

#: Grades of a difference to the target (the guide's colours): within the criteria; within
#: NEAR_FACTOR times them; beyond (or unknown).
GOOD, NEAR, FAR = "good", "near", "far"
NEAR_FACTOR = 2.0


def pose_errors(
    position_mm: Any, angles_deg: Any, truth_position_mm: Any, truth_angles_deg: Any
) -> tuple[np.ndarray, np.ndarray]:
    """Errors of poses against their truth: the Euclidean position error (mm, shape (...)) and the
    signed angle errors (degrees, measured minus truth, wrapped to (-180, 180], shape (..., 3)).

    Each argument is (3,) or (N, 3): x, y, z in mm (camera frame) or alpha, beta, gamma in degrees;
    a single truth broadcasts over N poses. NaN in a pose gives NaN errors.
    """
    pos = np.asarray(position_mm, dtype=float)
    ang = np.asarray(angles_deg, dtype=float)
    truth_pos = np.asarray(truth_position_mm, dtype=float)
    truth_ang = np.asarray(truth_angles_deg, dtype=float)
    for name, arr in (("position_mm", pos), ("angles_deg", ang), ("truth position", truth_pos)):
        if arr.ndim not in (1, 2) or arr.shape[-1] != 3:
            raise ValueError(f"{name}: (3,) or (N, 3) expected, got shape {arr.shape}")
    if truth_ang.ndim not in (1, 2) or truth_ang.shape[-1] != 3:
        raise ValueError(f"truth angles: (3,) or (N, 3) expected, got shape {truth_ang.shape}")
    with np.errstate(invalid="ignore"):
        err_pos = np.linalg.norm(pos - truth_pos, axis=-1)
        err_ang = np.asarray(angle_difference(ang, truth_ang), dtype=float)
    return err_pos, err_ang


@dataclass(frozen=True)
class Grades:
    """:meth:`AcceptanceCriteria.grade` of a difference: GOOD, NEAR or FAR per axis and for the
    Euclidean distance (mm), and whether the difference passes the criteria."""

    position: tuple[str, str, str]
    angles: tuple[str, str, str]
    distance: str
    distance_mm: float
    passes: bool


@dataclass(frozen=True)
class AcceptanceCriteria:
    """When a measured pose counts as a pass against its ground truth."""

    max_angle_error_deg: float = setting(
        2.0,
        label="largest angle error",
        unit="deg",
        minimum=0.0,
        maximum=180.0,
        help="pass needs |error| <= this on each of alpha, beta, gamma (seed: 2 degrees)",
    )
    max_position_error_mm: float = setting(
        5.0,
        label="largest position error",
        unit="mm",
        minimum=0.0,
        maximum=10000.0,
        help="pass needs the Euclidean position error < this (seed: 5 mm)",
    )

    def passes(self, err_pos_mm: float, err_angles_deg: np.ndarray | list[float]) -> bool:
        """True when the errors (mm; alpha, beta, gamma in degrees) meet the criteria.

        NaN errors (no pose) never pass.
        """
        angles = np.abs(np.asarray(err_angles_deg, dtype=float).reshape(-1))
        if angles.shape != (3,):
            raise ValueError(f"three angle errors (alpha, beta, gamma, deg) expected, got {angles.size}")
        return bool(self.meets(err_pos_mm, np.max(angles)))

    def meets(self, err_pos_mm: Any, max_angle_error_deg: Any) -> np.ndarray:
        """The rule for any batch: position error (mm, Euclidean) and the largest absolute angle
        error (deg) of each pose, same shapes; True where both are within the criteria (NaN fails)."""
        pos = np.asarray(err_pos_mm, dtype=float)
        ang = np.abs(np.asarray(max_angle_error_deg, dtype=float))
        with np.errstate(invalid="ignore"):
            return (pos < self.max_position_error_mm) & (ang <= self.max_angle_error_deg)

    def judge(
        self, position_mm: Any, angles_deg: Any, truth_position_mm: Any, truth_angles_deg: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Poses against their truth (shapes as :func:`pose_errors`): (passed, position error in mm,
        largest absolute angle error in degrees), each of shape (...) (a (3,) pose gives 0-d
        arrays). A pose with NaN never passes."""
        err_pos, err_ang = pose_errors(position_mm, angles_deg, truth_position_mm, truth_angles_deg)
        with np.errstate(invalid="ignore"):
            worst = np.max(np.abs(err_ang), axis=-1)
        passed = self.meets(err_pos, worst) & np.isfinite(err_pos) & np.isfinite(worst)
        return passed, err_pos, worst

    def grade(self, position_diff_mm: Any, angle_diff_deg: Any) -> Grades:
        """Grades of a pose's difference to its target, measured minus target: x, y, z in mm and
        alpha, beta, gamma in degrees (each (3,); angles wrapped here).

        Each angle: GOOD when |d| <= the angle limit, NEAR when <= NEAR_FACTOR times it, else FAR.
        The distance (Euclidean, the rule that decides) and each position axis: GOOD when below
        the position limit, NEAR below NEAR_FACTOR times it, else FAR. So every axis GOOD does not
        make the distance GOOD (three axes of 4 mm are 6.9 mm apart): ``distance`` says that.
        NaN grades FAR. ``passes`` is the criteria's verdict on these differences.
        """
        pos = np.asarray(position_diff_mm, dtype=float).reshape(-1)
        ang = np.asarray(angle_diff_deg, dtype=float).reshape(-1)
        if pos.shape != (3,) or ang.shape != (3,):
            raise ValueError(
                f"differences of x, y, z (3, mm) and alpha, beta, gamma (3, deg) expected, "
                f"got {pos.size} and {ang.size}"
            )
        ang = np.asarray(angle_difference(ang, 0.0), dtype=float)
        with np.errstate(invalid="ignore"):
            distance = float(np.linalg.norm(pos))

        def below(value: float, limit: float, inclusive: bool) -> str:
            size = abs(value)
            if not math.isfinite(size):
                return FAR
            within = (lambda a, b: a <= b) if inclusive else (lambda a, b: a < b)
            if within(size, limit):
                return GOOD
            return NEAR if within(size, NEAR_FACTOR * limit) else FAR

        p, a = self.max_position_error_mm, self.max_angle_error_deg
        grades_pos = tuple(below(v, p, False) for v in pos)
        grades_ang = tuple(below(v, a, True) for v in ang)
        return Grades(
            position=grades_pos,  # type: ignore[arg-type]
            angles=grades_ang,  # type: ignore[arg-type]
            distance=below(distance, p, False),
            distance_mm=distance,
            passes=bool(math.isfinite(distance) and self.passes(distance, ang)),
        )

    def label(self) -> str:
        """The criteria in a few characters for screens and reports, e.g. "2°/5 mm"."""
        return f"{self.max_angle_error_deg:g}°/{self.max_position_error_mm:g} mm"


@dataclass(frozen=True)
class SessionSettings:
    """How the app logs one row, and how long it waits for frames."""

    frames_per_row: int = setting(
        10,
        label="frames per row",
        unit="frames",
        minimum=1,
        maximum=1000,
        help="'Log row' averages this many consecutive frames into one row",
    )
    frame_timeout_s: float = setting(
        3.0,
        label="frame timeout",
        unit="s",
        minimum=0.5,
        maximum=60.0,
        decimals=1,
        help="no frame for this long: 'Log row' waits, and a row being collected is given up "
        "(nothing logged)",
    )
