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

from qrfield.methods import METHODS


class SolverError(ValueError):
    """Bad input to a solver (API misuse): the message says what is wrong."""


def _nan(shape: tuple[int, ...]) -> np.ndarray:
    return np.full(shape, np.nan)


def _unknown(shape: tuple[int, ...]) -> np.ndarray:
    """A read-only NaN array: the shared default of an uncertainty field that was not computed."""
    out = _nan(shape)
    out.setflags(write=False)
    return out


_UNKNOWN_4, _UNKNOWN_3, _UNKNOWN_6X6 = _unknown((4,)), _unknown((3,)), _unknown((6, 6))


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
        alternative: the other (mirror) candidate of the planar ambiguity, when the method found one
            (its own uncertainty fields are not computed: NaN).
        ambiguity: both methods alike (``uncertainty.ambiguity_ratio``): the RMS reprojection error
            of the better-fitting of this result and its alternative over that of the worse, in
            [0, 1]; near 1 the corners cannot tell the two poses apart. Which one fits better:
            compare ``reprojection_px`` of the two. None without an alternative. A number to show,
            not a verdict: whether the pose may be the mirror is ``ambiguous``.
        corners_px: (4, 2) the corners as given (pixels, V1..V4, before undistortion).
        corners_std_px: (4,) per corner V1..V4 the RMS radius of its uncertainty, sqrt(trace) of
            its 2x2 covariance, px (NaN when no corner covariance was given).
        position_std_mm: (3,) standard uncertainty of x, y, z, mm, propagated from the corner
            covariance (docs/uncertainty.md); NaN when unknown (no covariance, not converged).
        angles_std_deg: (3,) the same for alpha, beta, gamma, degrees (NaN also at beta = +-90).
        pose_cov: (6, 6) covariance of (x, y, z, alpha, beta, gamma) in mm and degrees (NaN when
            unknown); the std fields are the square roots of its diagonal.
        ambiguous: True when the mirror pose of the planar ambiguity explains the corners within
            their uncertainty, or better than this pose (a flip risk; then the std fields do not
            describe the error, which may be the mirror's). With a corner covariance: chi-square
            test (``mirror_chi2`` below the 0.999 quantile of chi-square with 2 degrees of
            freedom, or below ``chi2``); without one: ``ambiguity`` >= 0.5
            (``uncertainty.AMBIGUITY_FALLBACK``) or the mirror fits better.
        chi2: chi-square of this pose's branch against the corners under their covariance (at its
            chi-square optimum; about chi-square(2) distributed when the covariance is right), NaN
            without a covariance.
        mirror_chi2: the same for the mirror's branch (NaN without a covariance or a mirror).
        misfit (property): ``chi2`` exceeds ``uncertainty.FIT_CHI2`` (9.21, the 0.99 quantile of
            chi-square with 2 degrees of freedom): the corners are further off the pose's projection
            than their covariance allows (a wrong camera model, side or corners), and the std
            fields, which assume it does, are too small. False without a covariance.
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
    corners_std_px: np.ndarray = field(default_factory=lambda: _UNKNOWN_4)
    position_std_mm: np.ndarray = field(default_factory=lambda: _UNKNOWN_3)
    angles_std_deg: np.ndarray = field(default_factory=lambda: _UNKNOWN_3)
    pose_cov: np.ndarray = field(default_factory=lambda: _UNKNOWN_6X6)
    ambiguous: bool = False
    chi2: float = math.nan
    mirror_chi2: float = math.nan

    @property
    def misfit(self) -> bool:
        """The fit's chi-square exceeds FIT_CHI2 (docstring of the class; docs/uncertainty.md)."""
        from qrfield.solvers.uncertainty import is_misfit

        return is_misfit(self.chi2)

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
            "corners_std_px": [_plain(v) for v in self.corners_std_px],
            "position_std_mm": [_plain(v) for v in self.position_std_mm],
            "angles_std_deg": [_plain(v) for v in self.angles_std_deg],
            "ambiguous": bool(self.ambiguous),
            "chi2": _plain(self.chi2),
            "misfit": self.misfit,
        }


#: The keys of a pose's JSON, in order (``qrfield solve --json``; each method's in ``qrfield run
#: --json-lines``, null where a frame has no pose): read from :meth:`PoseResult.to_json_dict` itself,
#: so the list and the writer cannot differ.
POSE_JSON_KEYS = tuple(PoseResult.failed(METHODS[0], np.zeros((4, 2)), "").to_json_dict())


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
        corners_std_px, position_std_mm, angles_std_deg: (N, 4), (N, 3), (N, 3) as in
            :class:`PoseResult` (NaN where unknown; all NaN without a corner covariance). The batch
            runs no mirror search, so it has no ``ambiguous`` flag.
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
    corners_std_px: np.ndarray | None = None
    position_std_mm: np.ndarray | None = None
    angles_std_deg: np.ndarray | None = None

    def __post_init__(self) -> None:
        count = len(self)
        for name, width in (("corners_std_px", 4), ("position_std_mm", 3), ("angles_std_deg", 3)):
            if getattr(self, name) is None:  # a solver that computes no uncertainty: unknown
                object.__setattr__(self, name, _nan((count, width)))

    def __len__(self) -> int:
        return int(self.converged.shape[0])
