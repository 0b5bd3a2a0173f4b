"""What a pose solver returns: one :class:`PoseResult` per corner set, or a :class:`BatchResult`.

Frames, units and order follow docs/conventions.md: positions in mm in the OpenCV camera frame (+X right,
+Y down, +Z forward), angles (alpha, beta, gamma) in degrees with R = Rx(alpha) Ry(beta) Rz(gamma)
mapping marker to camera coordinates, vertices and corners in the order V1..V4 (top-left,
top-right, bottom-right, bottom-left of the symbol).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np


class SolverError(ValueError):
    """Bad input to a solver (API misuse): the message says what is wrong."""


def _nan(shape: tuple[int, ...]) -> np.ndarray:
    return np.full(shape, np.nan)


def _plain(value: float | None) -> float | None:
    """A JSON-ready float (None stays None; NaN and inf become None, which JSON can carry)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


@dataclass(frozen=True, eq=False)
class PoseResult:
    """The pose of one QR code from its four corner pixels.

    Attributes:
        method: "numerical" or "ippe".
        position_mm: (3,) QR centre in the camera frame, mm (NaN when unknown).
        angles_deg: (3,) alpha, beta, gamma in degrees (NaN when unknown).
        rotation: (3, 3) marker-to-camera rotation (NaN when unknown).
        vertices_mm: (4, 3) V1..V4 in the camera frame, mm. For "numerical" these are the solved
            points on the four lines of sight (not forced to be a rigid square); for "ippe" the
            rigid square placed by the pose.
        converged: the method met its own acceptance rule (numerical: every side and diagonal
            within the tolerance before n_max; ippe: OpenCV returned a finite pose).
        iterations: numerical: Gauss-Newton updates made; ippe: 0 (closed form, OpenCV does not
            expose the refinement's iteration count).
        residual_mm: numerical: the seed's max |diff_i|, the largest difference between the
            calculated and actual lengths of the four sides and two diagonals; ippe: the largest
            distance of a solved vertex from its line of sight. Both in mm.
        reprojection_px: RMS distance, in pixels, between the given corners and the corners the
            pose projects to through the camera model (distortion included).
        reason: "" when converged, else why not (always set when converged is False).
        alternative: the other (mirror) candidate of the planar ambiguity, when the method found one.
        ambiguity: reprojection error of this result divided by that of the alternative. ippe: best /
            second, in [0, 1]; near 1 the two poses explain the image equally well (a flip risk).
            numerical: this / mirror; above 1 the mirror explains the image better. None without
            an alternative.
        corners_px: (4, 2) the corners as given (pixels, V1..V4, before undistortion).
    """

    method: str
    position_mm: np.ndarray
    angles_deg: np.ndarray
    rotation: np.ndarray
    vertices_mm: np.ndarray
    converged: bool
    iterations: int
    residual_mm: float
    reprojection_px: float
    reason: str
    corners_px: np.ndarray
    alternative: PoseResult | None = None
    ambiguity: float | None = None

    @classmethod
    def failed(cls, method: str, corners_px: np.ndarray, reason: str, iterations: int = 0) -> PoseResult:
        """A result that carries no pose (every pose field NaN) and says why."""
        return cls(
            method=method,
            position_mm=_nan((3,)),
            angles_deg=_nan((3,)),
            rotation=_nan((3, 3)),
            vertices_mm=_nan((4, 3)),
            converged=False,
            iterations=iterations,
            residual_mm=math.nan,
            reprojection_px=math.nan,
            reason=reason,
            corners_px=np.array(corners_px, dtype=float),
        )

    def to_json_dict(self) -> dict[str, Any]:
        """Plain JSON types: mm and degrees; unknown numbers (NaN) become null."""
        return {
            "method": self.method,
            "position_mm": [_plain(v) for v in self.position_mm],
            "angles_deg": [_plain(v) for v in self.angles_deg],
            "converged": bool(self.converged),
            "iterations": int(self.iterations),
            "reprojection_px": _plain(self.reprojection_px),
            "corners": [[float(u), float(v)] for u, v in self.corners_px],
            "reason": self.reason,
            "ambiguity": _plain(self.ambiguity),
            "residual_mm": _plain(self.residual_mm),
        }


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Poses of N corner sets at once (index i is the i-th corner set).

    Attributes (numpy arrays; pose fields NaN where not converged and no pose was computed):
        method: "numerical" or "ippe".
        position_mm: (N, 3) mm, camera frame.
        angles_deg: (N, 3) alpha, beta, gamma in degrees.
        rotation: (N, 3, 3) marker to camera.
        converged: (N,) bool.
        iterations: (N,) int.
        residual_mm: (N,) as in :class:`PoseResult`.
        reprojection_px: (N,) RMS reprojection error, pixels.
        valid: (N,) bool, False where the corner set itself is unusable (NaN/inf, collinear,
            self-intersecting, concave or counter-clockwise): such rows are not converged.
    """

    method: str
    position_mm: np.ndarray
    angles_deg: np.ndarray
    rotation: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    residual_mm: np.ndarray
    reprojection_px: np.ndarray
    valid: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __len__(self) -> int:
        return int(self.converged.shape[0])
