"""The mirror branch of a pose as a pose of its own: what a stream reports when its history picks it.

A solver's answer carries the other candidate of the planar ambiguity as ``alternative`` without
an uncertainty of its own (docs/uncertainty.md). :func:`mirror_result` makes that candidate a full
:class:`~qrfield.solvers.PoseResult`: its own position, angles, rotation, vertices and reprojection
(the solver's, unchanged), its standard uncertainty propagated from the same corners the same way
as any answer's (:func:`qrfield.solvers.uncertainty.with_uncertainties`), ``chi2`` of its own branch
and ``mirror_chi2`` of the answer's (the mirror test run from its side), and the answer as its
``alternative``. Conventions: docs/conventions.md (mm, degrees, V1..V4).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from qrfield.camera import CameraModel
from qrfield.solvers.checks import check_camera, check_corners_single, check_side
from qrfield.solvers.rays import normalised_single
from qrfield.solvers.result import PoseResult
from qrfield.solvers.uncertainty import check_corners_cov, with_uncertainties


def has_mirror(result: PoseResult) -> bool:
    """``result`` carries a converged mirror candidate with a finite pose (``alternative``)."""
    alternative = result.alternative
    if alternative is None or not alternative.converged:
        return False
    return bool(np.all(np.isfinite(alternative.rotation)) and np.all(np.isfinite(alternative.position_mm)))


def mirror_result(
    result: PoseResult, camera: CameraModel, side_mm: float, corners_cov: np.ndarray | None
) -> PoseResult | None:
    """The mirror branch of ``result`` as a full PoseResult (see the module doc), or None when it has
    no converged mirror candidate (:func:`has_mirror`).

    Args:
        result: a solver's converged answer for one corner set (``corners_px`` (4, 2) px, V1..V4).
        camera, side_mm: the camera model and QR side (mm) it was solved with.
        corners_cov: the corners' covariance (4, 2, 2) px^2 it was solved with, or None (then the
            std fields stay NaN and ``ambiguous`` falls back on the reprojection ratio, as for
            any answer).

    The answer's own ``alternative`` is dropped from the copy kept as the mirror's alternative (no
    cycle). Raises SolverError for corners, camera, side or covariance a solver would refuse.
    """
    if not has_mirror(result):
        return None
    cam = check_camera(camera)
    side = check_side(side_mm)
    corners, flat = check_corners_single(result.corners_px)
    cov = None if corners_cov is None else check_corners_cov(corners_cov)
    answer = replace(result, alternative=None)
    # The ambiguity ratio is symmetric (better over worse); the mirror test is run afresh.
    start = replace(result.alternative, alternative=answer, ambiguity=result.ambiguity, ambiguous=False)
    xy = normalised_single(corners, flat, cam)
    mirror = with_uncertainties([start], corners, flat, cam, side, cov, xy)[0]
    if not math.isfinite(float(mirror.reprojection_px)):
        return None
    return mirror


def reflected_rotation(result: PoseResult, camera: CameraModel) -> np.ndarray | None:
    """(3, 3) rotation of the plane of ``result`` reflected about the line of sight to its centre:
    where the numerical model's mirror search starts (and the mirror test with it, when the search
    finds no distinct mirror), or None when that plane lies behind the camera or the pose is not finite."""
    from qrfield.solvers.numerical import reflected_pose_single

    if not (np.all(np.isfinite(result.rotation)) and np.all(np.isfinite(result.position_mm))):
        return None
    corners, flat = check_corners_single(result.corners_px)
    x, y = normalised_single(corners, flat, check_camera(camera))
    plane = reflected_pose_single(result.rotation.tolist(), result.position_mm.tolist(), x, y)
    return None if plane is None else np.array(plane[0], dtype=float)
