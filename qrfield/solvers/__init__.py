"""Pose solvers: the thesis' numerical model and OpenCV's closed-form IPPE, side by side.

Entry points:
  - :func:`solve` one corner set -> :class:`PoseResult`;
  - :func:`solve_batch` N corner sets -> :class:`BatchResult` (vectorised in numpy for both).

Conventions (docs/conventions.md): corners are pixels (u, v), OpenCV convention, in the order V1 top-left,
V2 top-right, V3 bottom-right, V4 bottom-left of the code (clockwise on screen); the side L is the
symbol's side in mm (quiet zone excluded); poses are the QR centre in mm in the camera frame and
alpha, beta, gamma in degrees with R = Rx(alpha) Ry(beta) Rz(gamma) (marker to camera).
Bad input raises :class:`SolverError` (a ValueError); a pose that cannot be found is returned with
``converged`` False and a ``reason``, never raised. Given the corners' covariance (``corners_cov``,
px^2), each pose carries its standard uncertainty and the mirror (flip) test:
:mod:`qrfield.solvers.uncertainty`, docs/uncertainty.md.
"""

from __future__ import annotations

import numpy as np

from qrfield.camera import CameraModel
from qrfield.methods import METHODS, NUMERICAL
from qrfield.solvers.checks import check_camera, check_corners_batch, check_corners_single, check_side
from qrfield.solvers.ippe import IppeSettings
from qrfield.solvers.numerical import SEED_SETTINGS, NumericalSettings
from qrfield.solvers.rays import normalised_single
from qrfield.solvers.registry import POSE_METHODS, pose_method, settings_class, settings_classes
from qrfield.solvers.result import BatchResult, PoseResult, SolverError
from qrfield.solvers.uncertainty import check_corners_cov, with_uncertainties

__all__ = [
    "METHODS",
    "POSE_METHODS",
    "SEED_SETTINGS",
    "BatchResult",
    "IppeSettings",
    "NumericalSettings",
    "PoseResult",
    "SolverError",
    "pose_method",
    "settings_class",
    "settings_classes",
    "solve",
    "solve_batch",
    "solve_methods",
]


def solve(
    corners_px: np.ndarray,
    camera: CameraModel,
    side_mm: float,
    method: str = NUMERICAL,
    settings: NumericalSettings | IppeSettings | None = None,
    corners_cov: np.ndarray | None = None,
) -> PoseResult:
    """The pose of one QR code from its four corner pixels, with its uncertainty.

    Args:
        corners_px: (4, 2) pixels (u, v) of V1..V4 (top-left, top-right, bottom-right, bottom-left),
            as seen in the image (distorted); undistorted here when the camera has distortion.
        camera: the camera model (focal lengths, principal point, distortion).
        side_mm: the QR symbol's side L in mm (quiet zone excluded), > 0.
        method: "numerical" (the thesis' model, our reconstruction) or "ippe" (OpenCV IPPE_SQUARE).
        settings: NumericalSettings or IppeSettings matching ``method``; None for the defaults.
        corners_cov: (4, 2, 2) covariance of V1..V4 in px^2 (as seen, distorted; corners
            independent), e.g. ``Detection.corners_cov`` or ``uncertainty.isotropic_cov(0.1)``;
            None when unknown. Propagated to ``position_std_mm``, ``angles_std_deg`` and
            ``pose_cov`` and used by the mirror test ``ambiguous`` (docs/uncertainty.md).

    Raises SolverError for bad input (shape, NaN/inf, collinear, self-intersecting, concave or
    counter-clockwise corners, non-positive side, no camera model, settings of the wrong class or
    z_min_mm >= z_max_mm) and qrfield.settings.SettingError for a setting outside its limits (both
    are ValueErrors); otherwise returns a PoseResult, with ``converged`` False and a ``reason`` when
    no pose was found.
    """
    return solve_methods(corners_px, camera, side_mm, (method,), {method: settings}, corners_cov)[method]


def solve_methods(
    corners_px: np.ndarray,
    camera: CameraModel,
    side_mm: float,
    methods: tuple[str, ...] | list[str],
    settings: dict[str, NumericalSettings | IppeSettings | None] | None = None,
    corners_cov: np.ndarray | None = None,
) -> dict[str, PoseResult]:
    """:func:`solve` for each of ``methods`` on the same corners, in that order: method -> PoseResult.

    The same numbers as :func:`solve` method by method; what they share is done once (the input
    checks, the undistortion, the uncertainty's vectorised pass). ``settings``: method -> its
    settings (missing: the defaults). Raises as :func:`solve` does.
    """
    settings = settings or {}
    specs = [pose_method(method) for method in methods]  # SolverError naming the known ones
    cam = check_camera(camera)
    side = check_side(side_mm)
    corners, flat = check_corners_single(corners_px)
    cov = None if corners_cov is None else check_corners_cov(corners_cov)
    xy = normalised_single(corners, flat, cam)
    results = [spec.solve_single(corners, flat, cam, side, settings.get(spec.name), xy) for spec in specs]
    return dict(zip(methods, with_uncertainties(results, corners, flat, cam, side, cov, xy), strict=True))


def solve_batch(
    corners_px: np.ndarray,
    camera: CameraModel,
    side_mm: float,
    method: str = NUMERICAL,
    settings: NumericalSettings | IppeSettings | None = None,
    corners_cov: np.ndarray | None = None,
) -> BatchResult:
    """Poses of N QR codes at once from corners (N, 4, 2) (pixels, V1..V4 each).

    The arguments of :func:`solve`, in its order (``method`` before ``settings``), batched.

    "numerical" is vectorised in numpy and gives, row by row, the same numbers as :func:`solve`
    (depths and iteration counts bit for bit; the mirror search is not run). "ippe" is the
    vectorised IPPE of :mod:`qrfield.solvers.ippe_batch` (rows agree with :func:`solve` to far
    below 1e-6 mm and 1e-6 deg on exact corners; ``refine="vvs"`` runs as "lm" there).
    ``corners_cov`` (N, 4, 2, 2), or one (4, 2, 2) for every row, in px^2: propagated to the std
    fields as :func:`solve` does (vectorised; no mirror test, so no ``ambiguous`` flag).
    Raises SolverError for a wrong overall shape, side, camera or settings (SettingError, also a
    ValueError, for a setting outside its limits); rows with unusable
    corners (NaN/inf, degenerate or wrongly ordered) come back not converged with ``valid`` False.
    """
    if not isinstance(method, str):
        # Before, settings came fourth: a settings object here is a caller of that order.
        raise SolverError(
            f"solve_batch(corners, camera, side_mm, method, settings): method must be a name, got "
            f"{type(method).__name__}; pass settings=... by keyword"
        )
    spec = pose_method(method)
    cam = check_camera(camera)
    side = check_side(side_mm)
    corners, valid = check_corners_batch(corners_px)
    cov = None if corners_cov is None else check_corners_cov(corners_cov, batch=corners.shape[0])
    return spec.solve_batch(corners, valid, cam, side, settings, cov)
