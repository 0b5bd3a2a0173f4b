"""Whether a set of robot poses turns enough, about enough axes, to fix a hand-eye transform.

The solve (:mod:`qrfield.handeye.solve`) compares motions between poses: A_ij, the robot's motion
from pose i to pose j, and B_ij, the camera's. The transform is unique only when the rotations of
those motions turn about at least two different axes (Tsai & Lenz 1989; Park & Martin 1994): turns
all about one axis leave the rotation about it, and the translation along it, undetermined.

The measure: the rotation vectors (axis * angle, degrees) of every A_ij, i < j, in the frame the
motion is expressed in (eye-in-hand: the tool frame, A_ij = T_tool_i^-1 T_tool_j; eye-to-hand: the
base frame, A_ij = T_tool_j T_tool_i^-1); their principal components give the RMS turn along the
main axis, the one across it and the third. A set is refused when the main one is below
``min_turn_deg`` (the tool hardly turns) or the second is below ``min_spread_deg`` (it turns about
one axis only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from qrfield.handeye.rigid import invert, rotation_log
from qrfield.handeye.setups import EYE_IN_HAND, HandEyeError, check_setup

#: The fewest pairs accepted (docs/conventions.md, "Hand-eye": N >= 5).
MIN_PAIRS = 5
#: Below this RMS turn between poses (degrees) along the main axis the tool hardly turns.
MIN_TURN_DEG = 5.0
#: Below this RMS turn (degrees) across the main axis the poses turn about one axis only. With the
#: code's pose known to ~0.05 deg, 5 deg of spread fixes the rotation about that axis to ~0.1 deg
#: over 15 poses; the solve's reported uncertainty says how well in each case.
MIN_SPREAD_DEG = 5.0

_AXIS_NAMES = ("X", "Y", "Z")


@dataclass(frozen=True)
class Spread:
    """How the robot's motions between poses turn.

    Attributes:
        turns_deg: (3,) RMS of the motions' rotation vectors along their principal axes, degrees,
            largest first.
        axes: (3, 3) the principal axes (rows, unit vectors) in ``frame``.
        frame: "tool" (eye-in-hand) or "base" (eye-to-hand): where the axes are expressed.
        largest_turn_deg: the largest rotation angle of any motion, degrees.
        motions: how many motions (pairs of poses) were compared.
    """

    turns_deg: np.ndarray
    axes: np.ndarray
    frame: str
    largest_turn_deg: float
    motions: int

    def describe(self) -> str:
        """One line: the RMS turns along the three principal axes."""
        a, b, c = self.turns_deg
        return f"RMS turn between poses {a:.1f}, {b:.1f}, {c:.1f} deg along the principal axes"


def motions(tool_in_base: np.ndarray, setup: str) -> np.ndarray:
    """(K, 4, 4) the robot's motions A_ij = M_j M_i^-1 for i < j, K = N (N - 1) / 2, with
    M = T_base_tool^-1 (eye-in-hand) or T_base_tool (eye-to-hand) (the model of qrfield.handeye.solve)."""
    m = np.asarray(tool_in_base, dtype=float)
    if m.ndim != 3 or m.shape[1:] != (4, 4):
        raise ValueError(f"tool poses must have shape (N, 4, 4), got {m.shape}")
    if check_setup(setup) == EYE_IN_HAND:
        m = invert(m)
    i, j = np.triu_indices(len(m), 1)
    return m[j] @ invert(m[i])


def rotation_spread(tool_in_base: np.ndarray, setup: str) -> Spread:
    """The :class:`Spread` of a set of tool poses T_base_tool (N, 4, 4), N >= 2."""
    a = motions(tool_in_base, setup)
    if len(a) == 0:
        raise HandEyeError("need at least 2 tool poses to compare")
    vectors = np.degrees(rotation_log(a[:, :3, :3]))
    # The principal axes from the 3x3 scatter matrix (its eigenvectors), not an SVD of all motions.
    values, vectors_3 = np.linalg.eigh(vectors.T @ vectors / len(vectors))
    order = np.argsort(values)[::-1]
    turns = np.sqrt(np.maximum(values[order], 0.0))
    vt = vectors_3[:, order].T
    frame = "tool" if setup == EYE_IN_HAND else "base"
    largest = float(np.linalg.norm(vectors, axis=1).max())
    return Spread(turns, vt, frame, largest, len(vectors))


def check_diversity(
    tool_in_base: np.ndarray,
    setup: str,
    *,
    min_pairs: int = MIN_PAIRS,
    min_turn_deg: float = MIN_TURN_DEG,
    min_spread_deg: float = MIN_SPREAD_DEG,
) -> Spread:
    """The spread of the tool poses (N, 4, 4), or HandEyeError saying what to add."""
    count = len(np.asarray(tool_in_base))
    if count < min_pairs:
        raise HandEyeError(
            f"{count} usable pairs; a hand-eye calibration needs at least {min_pairs} (15 or more "
            "recommended), at poses turned 15-30 deg about different axes",
            f"{count} pairs: at least {min_pairs} needed",
        )
    spread = rotation_spread(tool_in_base, setup)
    main, across, _ = spread.turns_deg
    if main < min_turn_deg:
        raise HandEyeError(
            f"the tool hardly turns between the {count} poses (RMS turn {main:.1f} deg, largest "
            f"{spread.largest_turn_deg:.1f} deg; at least {min_turn_deg:g} deg needed): add poses "
            f"turned 15-30 deg about the {spread.frame}'s X and Y axes",
            f"add 15-30 deg turns about {spread.frame} X and Y",
        )
    if across < min_spread_deg:
        axis = spread.axes[0] * np.sign(spread.axes[0][np.argmax(np.abs(spread.axes[0]))])
        other = _AXIS_NAMES[int(np.argmin(np.abs(axis)))]
        raise HandEyeError(
            f"the tool's turns between the {count} poses are all about one axis (({axis[0]:.2f}, "
            f"{axis[1]:.2f}, {axis[2]:.2f}) in the {spread.frame} frame; RMS turn across it "
            f"{across:.1f} deg, at least {min_spread_deg:g} deg needed): add poses turned 15-30 deg "
            f"about an axis across it, e.g. the {spread.frame}'s {other} axis",
            f"one turn axis: add turns about {spread.frame} {other}",
        )
    return spread
