"""The mirror branch of a pose as a pose of its own: what a stream reports when its history picks it.

A solver's answer carries the other candidate of the planar ambiguity as ``alternative`` without
an uncertainty of its own (docs/uncertainty.md). :func:`mirror_result` makes that candidate a full
:class:`~qrfield.solvers.PoseResult`: its own position, angles, rotation, vertices and reprojection
(the solver's, unchanged), its standard uncertainty propagated from the same corners the same way
as any answer's (:func:`qrfield.solvers.uncertainty.with_uncertainties`), ``chi2`` of its own branch
and ``mirror_chi2`` of the answer's (the mirror test run from its side), and the answer as its
``alternative``. Conventions: docs/conventions.md (mm, degrees, V1..V4).

IPPE's mirror candidate is not always a minimum of its own: near frontal its refinement slides
towards the answer, and the solver keeps the closed-form second solution, 1-3 degrees from the
answer with a chi-square only 0-6 above it (qrfield.solvers.ippe). :func:`refined_mirror_result`
refines it first, by the chi-square of the mirror test itself; when it ends on the answer's
minimum there is no distinct mirror (None), as when the numerical model's mirror search slides
back to its answer. The answer of :func:`qrfield.solvers.solve` is not changed by any of this.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import rotation_from_vector, rotation_vector
from qrfield.lens import has_distortion
from qrfield.linalg import small_solve
from qrfield.solvers.checks import check_camera, check_corners_single, check_side
from qrfield.solvers.rays import normalised_single
from qrfield.solvers.result import PoseResult
from qrfield.solvers.uncertainty import (
    block_diagonal,
    check_corners_cov,
    information_blocks,
    with_uncertainties,
)
from qrfield.solvers.uncertainty_single import normalised_cov_single, rigid_projection_single

#: Two refinements (:func:`chi2_minimum`) that end closer than this, measured by the chi-square's
#: curvature at the answer's end (d^T H d: a tenth of a standard deviation apart), ended on one
#: minimum. On the stream benchmark's tuning seeds (1, 2, 11-13, 41-43; 584 ambiguous IPPE
#: frames) the two ends were either under 2e-4 apart so measured or 8.8 and more (distinct minima).
SAME_MINIMUM_CHI2 = 1e-2
#: The refinement has settled when a Gauss-Newton step would lower the chi-square by less than
#: this (its units: the corners' variance; about a thousandth of a deviation from the minimum). It
#: is given up after REFINE_ITERATIONS steps: near the fold the chi-square's valley is flat and
#: Gauss-Newton approaches its floor slowly (there, 99 % of the refinements settled within 50).
SETTLED_CHI2 = 1e-6
REFINE_ITERATIONS = 100


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


def chi2_minimum(
    rotation: np.ndarray, position: np.ndarray, n_obs: np.ndarray, info: np.ndarray, side: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The rigid square's pose refined by Levenberg-Marquardt to the nearest minimum of the
    chi-square r^T W r of its normalised projection (the mirror test's chi-square,
    qrfield.solvers.uncertainty.branch_chi2), from ``rotation`` (3, 3) and ``position`` (3,) mm.

    ``n_obs`` (8,): the corners' normalised ideal coordinates (x1, y1, ..., x4, y4); ``info``
    (8, 8) their information matrix W. Steps are p = (omega rad, t mm), R -> exp([omega]x) R.
    Returns (R (3, 3), t (3,) mm, H (6, 6) = J^T W J there), or None when a vertex goes behind the
    camera or the chi-square has not settled (SETTLED_CHI2) within REFINE_ITERATIONS steps.
    """

    def at(r: np.ndarray, t: np.ndarray) -> tuple[float, np.ndarray, np.ndarray] | None:
        proj, jac, nearest = rigid_projection_single(r.tolist(), t.tolist(), side)
        if not nearest > 0.0:
            return None
        res = n_obs - np.array(proj)
        return float(res @ info @ res), res, np.array(jac).reshape(8, 6)

    r, t = np.asarray(rotation, dtype=float), np.asarray(position, dtype=float).reshape(3)
    now = at(r, t)
    damping = 1e-3
    for _ in range(REFINE_ITERATIONS):
        if now is None:
            return None
        chi2, res, jac = now
        jtw = jac.T @ info
        hessian, gradient = jtw @ jac, jtw @ res
        try:
            if float(gradient @ small_solve(hessian, gradient, symmetric=True)) < SETTLED_CHI2:
                return r, t, hessian
            step = small_solve(hessian + damping * np.diag(np.diag(hessian)), gradient, symmetric=True)
        except np.linalg.LinAlgError:
            return None
        r_new, t_new = rotation_from_vector(step[:3]) @ r, t + step[3:]
        new = at(r_new, t_new)
        if new is not None and new[0] <= chi2:
            r, t, now, damping = r_new, t_new, new, max(damping / 10.0, 1e-9)
        else:
            damping *= 10.0
    return None


def corners_information(
    corners_px: np.ndarray, camera: CameraModel, corners_cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(n_obs (8,), W (8, 8)): the corners V1..V4 (4, 2) px as the normalised ideal coordinates
    (x1, y1, ..., x4, y4) the mirror test's chi-square is taken on, and their information matrix
    (the inverse of their covariance, from ``corners_cov`` (4, 2, 2) px^2 through the undistortion),
    as :func:`chi2_minimum` takes them."""
    corners, flat = check_corners_single(corners_px)
    x, y = normalised_single(corners, flat, camera)
    info = block_diagonal(
        information_blocks(normalised_cov_single(corners_cov, x, y, camera, has_distortion(camera)))
    )
    return np.array([v for pair in zip(x, y, strict=True) for v in pair]), info


def refined_mirror_result(
    result: PoseResult, camera: CameraModel, side_mm: float, corners_cov: np.ndarray | None
) -> PoseResult | None:
    """:func:`mirror_result`, or None when the mirror candidate of ``result`` is no minimum of its
    own: refined by the mirror test's chi-square (:func:`chi2_minimum`) it ends where the answer,
    refined the same way, ends (within SAME_MINIMUM_CHI2). Then the corners have one branch here
    and the frame's rise to the candidate (mirror_chi2 - chi2) is only how far the candidate lies
    up the answer's slope. Arguments as :func:`mirror_result`; without ``corners_cov``, or when
    either refinement does not settle, it is :func:`mirror_result`."""
    if not has_mirror(result):
        return None
    if corners_cov is None:
        return mirror_result(result, camera, side_mm, corners_cov)
    cam = check_camera(camera)
    side = check_side(side_mm)
    cov = check_corners_cov(corners_cov)
    n_obs, info = corners_information(result.corners_px, cam, cov)
    answer = chi2_minimum(result.rotation, result.position_mm, n_obs, info, side)
    mirror = chi2_minimum(result.alternative.rotation, result.alternative.position_mm, n_obs, info, side)
    if answer is not None and mirror is not None:
        step = np.concatenate([rotation_vector(mirror[0] @ answer[0].T), mirror[1] - answer[1]])
        if float(step @ answer[2] @ step) < SAME_MINIMUM_CHI2:
            return None
    return mirror_result(result, cam, side, cov)


def mirror_start(result: PoseResult) -> np.ndarray | None:
    """(3, 3) rotation of the mirror candidate of ``result`` (None without one): where
    :func:`refined_mirror_result`'s refinement starts, and the plane continuity compares with the
    history when that refinement ends on the answer."""
    return np.array(result.alternative.rotation, dtype=float) if has_mirror(result) else None
