"""The numerical model's answer checked against the corners' own best fit: an honest std near frontal.

docs/uncertainty.md, "Ninth pass (issue 25s)". The numerical model (the thesis' length fit) is a
function p_N(n) of the eight normalised corner coordinates; its first-order covariance
C_N = A_N Sigma A_N^T (:mod:`qrfield.solvers.uncertainty`) holds while A_N stays about the same over
the corners' noise. Near frontal it does not: there the length fit's tilt is a strongly nonlinear
function of the corners (its linearised std of alpha is 1.6 degrees at a 450 mm card's true pose
and 0.4 degree at an answer 2 degrees off it, on the same corners), so a frame whose corner error
carried the tilt away from frontal is reported with a std several times too small.

The corners' own best fit on the same branch, p_W (the rigid square's pose at the nearest minimum of
the reprojection chi-square r^T W r, W the corners' information: the mirror test's chi-square,
:func:`qrfield.solvers.mirror.chi2_minimum`), is the efficient estimate: to first order its
covariance is the Cramer-Rao bound H^-1 = (J^T W J)^-1, and for any estimator p_N that returns the
pose from exact corners (A_N J = I) its error is uncorrelated with the difference d = p_N - p_W
(Cov(e_W, d) = A_W Sigma A_N^T - H^-1 = H^-1 (A_N J)^T - H^-1 = 0; Hausman's test rests on it). So,
given the frame, the numerical answer's error e_N = e_W + d has mean d and covariance H^-1: its mean
square about the truth is H^-1 + d d^T, whatever the length fit's own linearisation says. The
reported covariance is raised to at least that (:func:`crosscheck_widening`), per block (the
rotation, rad^2; the position, mm^2: the positive part of the difference, as the near-fold
widening does), with H^-1 scaled as the frame's covariance is when its fit is worse than its
corners' covariance allows (:func:`qrfield.stream.continuity.fit_scale`). Where the length fit's
own covariance is larger (the common case near frontal: it is the unconditional one) it stands.

Only the reported std changes (not the pose, the branch or the flag), and only in a stream from its
second frame on: a stream's first frame is a single image, which keeps the solvers' std (the issue:
single images behave exactly as now). Conventions: docs/conventions.md (mm, degrees, camera frame;
rotations as small rotation vectors w of the camera frame, R -> exp([w]x) R).
"""

from __future__ import annotations

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import rotation_vector
from qrfield.solvers.mirror import chi2_minimum, corners_information
from qrfield.solvers.result import PoseResult
from qrfield.solvers.uncertainty import check_corners_cov
from qrfield.stream.continuity import fit_scale, raise_to
from qrfield.stream.poses import vector_cov


def crosscheck_widening(
    pose: PoseResult, camera: CameraModel, side_mm: float, corners_cov: np.ndarray | None
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """What raises ``pose``'s covariance to at least the corners' best fit's H^-1 + d d^T (see the
    module doc): (added to the rotation block, (3, 3) rad^2 over w; added to the position block,
    (3, 3) mm^2), each None when nothing is added.

    Args:
        pose: a converged answer of one corner set (``corners_px`` (4, 2) px, V1..V4) with its
            ``pose_cov`` (as reported so far: scaled by the fit, if it was).
        camera, side_mm: the camera model and QR side (mm) it was solved with.
        corners_cov: the corners' covariance (4, 2, 2) px^2 it was solved with; None: nothing
            (the best fit's weights are unknown).

    Nothing is added either when the fit does not settle (:func:`chi2_minimum`) or the pose has
    no finite covariance.
    """
    cov = vector_cov(pose)
    if corners_cov is None or cov is None:
        return None, None
    n_obs, info = corners_information(pose.corners_px, camera, check_corners_cov(corners_cov))
    fit = chi2_minimum(pose.rotation, pose.position_mm, n_obs, info, side_mm)
    if fit is None:
        return None, None
    rotation, position, hessian = fit
    try:
        bound = np.linalg.inv(hessian) * fit_scale(pose)  # over (w rad, t mm)
    except np.linalg.LinAlgError:
        return None, None
    turn = rotation_vector(np.asarray(pose.rotation, dtype=float) @ rotation.T)
    shift = np.asarray(pose.position_mm, dtype=float) - position
    if not (np.all(np.isfinite(bound)) and np.all(np.isfinite(turn)) and np.all(np.isfinite(shift))):
        return None, None
    return (
        raise_to(bound[:3, :3] + np.outer(turn, turn), cov[3:, 3:]),
        raise_to(bound[3:, 3:] + np.outer(shift, shift), cov[:3, :3]),
    )
