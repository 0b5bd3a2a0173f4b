"""Pose solvers: the thesis' numerical model and OpenCV's closed-form IPPE, side by side.

Entry points:
  - :func:`solve` one corner set -> :class:`PoseResult`;
  - :func:`solve_batch` N corner sets -> :class:`BatchResult` (vectorised in numpy for both).

Conventions (docs/conventions.md): corners are pixels (u, v), OpenCV convention, in the order V1 top-left,
V2 top-right, V3 bottom-right, V4 bottom-left of the code (clockwise on screen); the side L is the
symbol's side in mm (quiet zone excluded); poses are the QR centre in mm in the camera frame and
alpha, beta, gamma in degrees with R = Rx(alpha) Ry(beta) Rz(gamma) (marker to camera).
Bad input raises :class:`SolverError` (a ValueError); a pose that cannot be found is returned with
``converged`` False and a ``reason``, never raised.
"""

from __future__ import annotations

import numpy as np

from qrfield.camera import CameraModel
from qrfield.solvers.checks import check_camera, check_corners_batch, check_corners_single, check_side
from qrfield.solvers.ippe import IppeSettings, solve_ippe
from qrfield.solvers.ippe_batch import solve_ippe_vectorised
from qrfield.solvers.numerical import SEED_SETTINGS, NumericalSettings, solve_numerical
from qrfield.solvers.numerical_batch import solve_numerical_batch
from qrfield.solvers.result import BatchResult, PoseResult, SolverError

__all__ = [
    "METHODS",
    "SEED_SETTINGS",
    "BatchResult",
    "IppeSettings",
    "NumericalSettings",
    "PoseResult",
    "SolverError",
    "settings_class",
    "solve",
    "solve_batch",
]

#: Solver names accepted by :func:`solve` and :func:`solve_batch`.
METHODS = ("numerical", "ippe")


def settings_class(method: str) -> type:
    """The settings dataclass of a method: NumericalSettings or IppeSettings."""
    if method == "numerical":
        return NumericalSettings
    if method == "ippe":
        return IppeSettings
    raise SolverError(f"unknown solver method {method!r}; choose one of {', '.join(METHODS)}")


def solve(
    corners_px: np.ndarray,
    camera: CameraModel,
    side_mm: float,
    method: str = "numerical",
    settings: NumericalSettings | IppeSettings | None = None,
) -> PoseResult:
    """The pose of one QR code from its four corner pixels.

    Args:
        corners_px: (4, 2) pixels (u, v) of V1..V4 (top-left, top-right, bottom-right, bottom-left),
            as seen in the image (distorted); undistorted here when the camera has distortion.
        camera: the camera model (focal lengths, principal point, distortion).
        side_mm: the QR symbol's side L in mm (quiet zone excluded), > 0.
        method: "numerical" (the thesis' model, our reconstruction) or "ippe" (OpenCV IPPE_SQUARE).
        settings: NumericalSettings or IppeSettings matching ``method``; None for the defaults.

    Raises SolverError for bad input (shape, NaN/inf, collinear, self-intersecting, concave or
    counter-clockwise corners, non-positive side, no camera model, settings of the wrong class or
    z_min_mm >= z_max_mm) and qrfield.settings.SettingError for a setting outside its limits (both
    are ValueErrors); otherwise returns a PoseResult, with ``converged`` False and a ``reason`` when
    no pose was found.
    """
    settings_class(method)
    cam = check_camera(camera)
    side = check_side(side_mm)
    corners, flat = check_corners_single(corners_px)
    if method == "numerical":
        return solve_numerical(corners, flat, cam, side, settings)  # type: ignore[arg-type]
    return solve_ippe(corners, flat, cam, side, settings)  # type: ignore[arg-type]


def solve_batch(
    corners_px: np.ndarray,
    camera: CameraModel,
    side_mm: float,
    settings: NumericalSettings | IppeSettings | None = None,
    method: str = "numerical",
) -> BatchResult:
    """Poses of N QR codes at once from corners (N, 4, 2) (pixels, V1..V4 each).

    "numerical" is vectorised in numpy and gives, row by row, the same numbers as :func:`solve`
    (depths and iteration counts bit for bit; the mirror search is not run). "ippe" is the
    vectorised IPPE of :mod:`qrfield.solvers.ippe_batch` (rows agree with :func:`solve` to far
    below 1e-6 mm and 1e-6 deg on exact corners; ``refine="vvs"`` runs as "lm" there).
    Raises SolverError for a wrong overall shape, side, camera or settings (SettingError, also a
    ValueError, for a setting outside its limits); rows with unusable
    corners (NaN/inf, degenerate or wrongly ordered) come back not converged with ``valid`` False.
    """
    settings_class(method)
    cam = check_camera(camera)
    side = check_side(side_mm)
    corners, valid = check_corners_batch(corners_px)
    if method == "numerical":
        return solve_numerical_batch(corners, valid, cam, side, settings)  # type: ignore[arg-type]
    return solve_ippe_vectorised(corners, valid, cam, side, settings)  # type: ignore[arg-type]
