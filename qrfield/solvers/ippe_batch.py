"""IPPE for square targets over N corner sets at once, in numpy (no per-pose OpenCV call).

The closed form of Collins and Bartoli's Infinitesimal Plane-based Pose Estimation (IJCV 2014),
following the steps of OpenCV's ``modules/calib3d/src/ippe.cpp`` (``solveSquare``,
``homographyFromSquarePoints``, ``solveCanonicalForm``, ``computeRotations``,
``computeTranslation``), written here for arrays and directly in the marker frame of
docs/conventions.md (V1 (-L/2, -L/2), V2 (L/2, -L/2), V3 (L/2, L/2), V4 (-L/2, L/2); +Z into the
card), so no conversion to OpenCV's IPPE frame and no rotation vector is ever made:

1. the homography H from the marker plane (mm) to normalised image coordinates (x, y) of the
   undistorted corners, in closed form for a square (the projective map of the unit square onto the
   quadrilateral, composed with the marker's scaling), normalised to H[2, 2] = 1;
2. its Jacobian J (2 x 2) at the marker centre and the centre's image v = (H[0, 2], H[1, 2]);
3. the two rotations: Rv turns the optical axis onto the line of sight (v, 1); with
   B = [[1, 0, -v0], [0, 1, -v1]] Rv[:, :2] and A = B^-1 J, the largest singular value gamma of A
   scales A / gamma into the top 2 x 2 block of the rotation (in Rv's frame); the third row is
   +-(sqrt(1 - |column|^2)) (the planar ambiguity), the third column the cross product;
4. the translation of each rotation by linear least squares on the four lines of sight;
5. each candidate refined by Levenberg-Marquardt on the reprojection error in (ideal) pixels,
   the error OpenCV's ``solvePnPRefineLM`` minimises in :mod:`qrfield.solvers.ippe`;
6. candidates behind the camera or facing away dropped; the answer is the one with the smaller
   RMS reprojection error on the corners as given (distortion included).

Why not OpenCV: it has no vectorised IPPE, and one call costs about 0.7 ms per pose through Python.
OpenCV 5.0's IPPE also returns wrong poses whenever its rotation is a half turn (its ``rot2vec``
divides by sin(pi)); its frame is ours turned 180 degrees about X, so that is every pose whose
rotation axis lies in the marker's Y-Z plane: a square-on card, a tilt about Y alone, a turn in
the card's plane alone (gamma, including gamma = 180). The single path works around it with a
third start; this path has no rotation vectors and needs none. Rows agree with
:func:`qrfield.solvers.solve` (method "ippe") to far below 1e-6 mm and 1e-6 degrees on exact
corners (both reach the truth) and to the LM stopping rules on noisy ones (tests/test_solvers_ippe_batch.py).
"""

from __future__ import annotations

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import angles_from_rotation, marker_vertices, project_points
from qrfield.solvers.ippe import checked_settings
from qrfield.solvers.rays import normalised_batch
from qrfield.solvers.result import BatchResult, SolverError

#: Levenberg-Marquardt updates at most (each candidate); exact corners need none, noisy ones 2-4.
LM_MAX_ITER = 100
#: A row stops when a step predicts less than this share of its squared error as gain (the minimum
#: to rounding), or when its squared error is below COST_FLOOR_PX2 (exact corners).
LM_RELATIVE_GAIN = 1e-14
COST_FLOOR_PX2 = 1e-18
#: Damping (relative to diag(J^T J)): the start, its factors on a rejected / accepted step, and the
#: value beyond which no step lowers the error any more (the row has settled).
LM_LAMBDA0 = 1e-6
LM_LAMBDA_UP, LM_LAMBDA_DOWN = 10.0, 10.0
LM_LAMBDA_MAX = 1e6
#: Rows solved per pass: numpy temporaries stay in the CPU cache.
BATCH_CHUNK = 8192


def square_homography(x: np.ndarray, y: np.ndarray, side: float) -> np.ndarray:
    """(N, 3, 3) homographies from the marker plane (qx, qy in mm) to normalised coordinates.

    ``x``, ``y``: (N, 4) normalised coordinates of V1..V4. H[2, 2] = 1; rows whose corners admit
    no homography (three collinear) come out NaN/inf.
    """
    # Projective map of the unit square (u, v) in {0, 1}^2 onto the quadrilateral V1 V2 V3 V4
    # (V1 at (0, 0), V2 at (1, 0), V3 at (1, 1), V4 at (0, 1)): Heckbert's closed form.
    x0, x1, x2, x3 = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
    y0, y1, y2, y3 = y[:, 0], y[:, 1], y[:, 2], y[:, 3]
    sx = x0 - x1 + x2 - x3
    sy = y0 - y1 + y2 - y3
    dx1, dx2 = x1 - x2, x3 - x2
    dy1, dy2 = y1 - y2, y3 - y2
    den = dx1 * dy2 - dx2 * dy1
    g = (sx * dy2 - dx2 * sy) / den
    k = (dx1 * sy - sx * dy1) / den
    unit = np.empty((x.shape[0], 3, 3))
    unit[:, 0, 0] = x1 - x0 + g * x1
    unit[:, 0, 1] = x3 - x0 + k * x3
    unit[:, 0, 2] = x0
    unit[:, 1, 0] = y1 - y0 + g * y1
    unit[:, 1, 1] = y3 - y0 + k * y3
    unit[:, 1, 2] = y0
    unit[:, 2, 0] = g
    unit[:, 2, 1] = k
    unit[:, 2, 2] = 1.0
    # Marker coordinates to the unit square: u = qx / L + 1/2, v = qy / L + 1/2.
    to_unit = np.array([[1.0 / side, 0.0, 0.5], [0.0, 1.0 / side, 0.5], [0.0, 0.0, 1.0]])
    h = unit @ to_unit
    return h / h[:, 2:3, 2:3]


def ippe_rotations(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two IPPE rotations (N, 3, 3) (marker to camera) from homographies with H[2, 2] = 1."""
    v0, v1 = h[:, 0, 2], h[:, 1, 2]
    j00 = h[:, 0, 0] - h[:, 2, 0] * v0
    j01 = h[:, 0, 1] - h[:, 2, 1] * v0
    j10 = h[:, 1, 0] - h[:, 2, 0] * v1
    j11 = h[:, 1, 1] - h[:, 2, 1] * v1
    # Rv: the rotation that takes the optical axis (0, 0, 1) onto the unit line of sight s of the
    # centre (the transpose of OpenCV's rotateVec2ZAxis; s is never opposite to the axis here).
    norm = np.sqrt(v0 * v0 + v1 * v1 + 1.0)
    ax, ay, az = v0 / norm, v1 / norm, 1.0 / norm
    d = 1.0 / (1.0 + az)
    rv = np.empty((h.shape[0], 3, 3))
    rv[:, 0, 0] = 1.0 - ax * ax * d
    rv[:, 0, 1] = -ax * ay * d
    rv[:, 0, 2] = ax
    rv[:, 1, 0] = -ax * ay * d
    rv[:, 1, 1] = 1.0 - ay * ay * d
    rv[:, 1, 2] = ay
    rv[:, 2, 0] = -ax
    rv[:, 2, 1] = -ay
    rv[:, 2, 2] = 1.0 - (ax * ax + ay * ay) * d
    b00 = rv[:, 0, 0] - v0 * rv[:, 2, 0]
    b01 = rv[:, 0, 1] - v0 * rv[:, 2, 1]
    b10 = rv[:, 1, 0] - v1 * rv[:, 2, 0]
    b11 = rv[:, 1, 1] - v1 * rv[:, 2, 1]
    inv_det = 1.0 / (b00 * b11 - b01 * b10)
    # A = B^-1 J
    a00 = inv_det * (b11 * j00 - b01 * j10)
    a01 = inv_det * (b11 * j01 - b01 * j11)
    a10 = inv_det * (-b10 * j00 + b00 * j10)
    a11 = inv_det * (-b10 * j01 + b00 * j11)
    ata00 = a00 * a00 + a01 * a01
    ata01 = a00 * a10 + a01 * a11
    ata11 = a10 * a10 + a11 * a11
    gamma = np.sqrt(0.5 * (ata00 + ata11 + np.sqrt((ata00 - ata11) ** 2 + 4.0 * ata01 * ata01)))
    r00, r01, r10, r11 = a00 / gamma, a01 / gamma, a10 / gamma, a11 / gamma
    # Rounding can push 1 - |column|^2 a hair below zero for a square-on card: it is zero there.
    b0 = np.sqrt(np.maximum(1.0 - r00 * r00 - r10 * r10, 0.0))
    b1 = np.sqrt(np.maximum(1.0 - r01 * r01 - r11 * r11, 0.0))
    b1 = np.where(-r00 * r01 - r10 * r11 < 0.0, -b1, b1)
    out = []
    for sign in (1.0, -1.0):
        c0 = np.stack([r00, r10, sign * b0], axis=-1)
        c1 = np.stack([r01, r11, sign * b1], axis=-1)
        local = np.stack([c0, c1, np.cross(c0, c1)], axis=-1)  # columns: marker X, Y, Z in Rv's frame
        out.append(rv @ local)
    return out[0], out[1]


def least_squares_translation(rotation: np.ndarray, x: np.ndarray, y: np.ndarray, side: float) -> np.ndarray:
    """(N, 3) t minimising the algebraic error of the four lines of sight for a given rotation.

    Vertex i is R q_i + t; on its line of sight x_i (R q_i + t)_z = (R q_i + t)_x, and the same
    for y: two equations linear in t per vertex, solved by the 3 x 3 normal equations.
    """
    q = marker_vertices(side)
    w = np.matmul(q, rotation.transpose(0, 2, 1))  # (N, 4, 3): R q_i
    n = x.shape[0]
    a = np.zeros((n, 8, 3))
    a[:, 0::2, 0] = 1.0
    a[:, 0::2, 2] = -x
    a[:, 1::2, 1] = 1.0
    a[:, 1::2, 2] = -y
    b = np.empty((n, 8))
    b[:, 0::2] = x * w[..., 2] - w[..., 0]
    b[:, 1::2] = y * w[..., 2] - w[..., 1]
    ata = np.einsum("nki,nkj->nij", a, a)
    atb = np.einsum("nki,nk->ni", a, b)
    return np.linalg.solve(ata, atb[..., None])[..., 0]


def _rotation_step(omega: np.ndarray) -> np.ndarray:
    """exp([omega]x) for (M, 3) rotation vectors (radians), by Rodrigues' formula."""
    theta2 = np.einsum("ni,ni->n", omega, omega)
    theta = np.sqrt(theta2)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    s = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    c = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    k = np.zeros((omega.shape[0], 3, 3))
    k[:, 0, 1], k[:, 0, 2] = -omega[:, 2], omega[:, 1]
    k[:, 1, 0], k[:, 1, 2] = omega[:, 2], -omega[:, 0]
    k[:, 2, 0], k[:, 2, 1] = -omega[:, 1], omega[:, 0]
    return np.eye(3) + s[:, None, None] * k + c[:, None, None] * (k @ k)


def _residuals(
    rotation: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray, q: np.ndarray, fx: float, fy: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, 8) pixel residuals u_model - u, the camera-frame vertices (M, 4, 3) and R q (M, 4, 3)."""
    w = np.matmul(q, rotation.transpose(0, 2, 1))
    p = w + t[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.empty((p.shape[0], 8))
        r[:, 0::2] = fx * (p[..., 0] / p[..., 2] - x)
        r[:, 1::2] = fy * (p[..., 1] / p[..., 2] - y)
    return r, p, w


def _jacobian(p: np.ndarray, w: np.ndarray, fx: float, fy: float) -> np.ndarray:
    """(M, 8, 6) d residual / d (w, t): the rotation update w (rad, camera frame), then t (mm).

    d(X/Z)/dp = (1, 0, -u) / Z and d(Y/Z)/dp = (0, 1, -v) / Z with u = X/Z, v = Y/Z;
    dp/dw = -[R q]x and dp/dt = I. Filled in a (u or v, parameter, M, vertex) layout, so that
    every write is contiguous, then reordered once.
    """
    inv_z = 1.0 / p[..., 2]
    u = p[..., 0] * inv_z
    v = p[..., 1] * inv_z
    wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
    fu, fv = fx * inv_z, fy * inv_z
    jac = np.empty((2, 6, p.shape[0], 4))
    jac[0, 0] = -fu * u * wy
    jac[0, 1] = fu * (wz + u * wx)
    jac[0, 2] = -fu * wy
    jac[0, 3] = fu
    jac[0, 4] = 0.0
    jac[0, 5] = -fu * u
    jac[1, 0] = -fv * (wz + v * wy)
    jac[1, 1] = fv * v * wx
    jac[1, 2] = fv * wx
    jac[1, 3] = 0.0
    jac[1, 4] = fv
    jac[1, 5] = -fv * v
    return jac.transpose(2, 3, 0, 1).reshape(p.shape[0], 8, 6)


def refine(
    rotation: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray, side: float, fx: float, fy: float
) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on the pixel reprojection error of the square, all rows at once.

    Args: rotations (M, 3, 3) and translations (M, 3) (mm) to start from; normalised coordinates
    x, y (M, 4) of V1..V4; the side (mm); the focal lengths (px). The error is measured on ideal
    (undistorted) pixels, fx (X/Z - x_i) and fy (Y/Z - y_i), as cv2.solvePnPRefineLM does on the
    undistorted corners. Rotation updates are applied on the left, R <- exp([w]x) R (w in the
    camera frame). Returns the refined (R, t). A row stops when its error is at the rounding floor,
    when the decrease a step predicts is negligible (the minimum, to rounding), when damping can
    no longer lower its error, or after LM_MAX_ITER updates.
    """
    rotation, t = rotation.copy(), t.copy()
    q = marker_vertices(side)
    r, p, w = _residuals(rotation, t, x, y, q, fx, fy)
    cost = np.einsum("ni,ni->n", r, r)
    active = np.flatnonzero(np.isfinite(cost) & np.all(p[..., 2] > 0.0, axis=1) & (cost > COST_FLOOR_PX2))
    lam = np.full(active.size, LM_LAMBDA0)
    for _ in range(LM_MAX_ITER):
        if active.size == 0:
            break
        ra = r[active]
        jac = _jacobian(p[active], w[active], fx, fy)
        jac_t = jac.transpose(0, 2, 1)
        jtj = jac_t @ jac
        jtr = (jac_t @ ra[..., None])[..., 0]
        diag = np.maximum(jtj.reshape(-1, 36)[:, ::7], 1e-300)
        # Marquardt's scaling: damping proportional to diag(J^T J) (rotation and translation differ in units).
        damped = jtj.copy()
        damped.reshape(-1, 36)[:, ::7] += lam[:, None] * diag
        step = -np.linalg.solve(damped, jtr[..., None])[..., 0]
        # The decrease of the squared error the linear model predicts for this step (>= 0).
        predicted = -(2.0 * np.einsum("ni,ni->n", jtr, step) + np.einsum("ni,nij,nj->n", step, jtj, step))
        new_rot = _rotation_step(step[:, :3]) @ rotation[active]
        new_t = t[active] + step[:, 3:]
        nr, npts, nw = _residuals(new_rot, new_t, x[active], y[active], q, fx, fy)
        new_cost = np.einsum("ni,ni->n", nr, nr)
        old_cost = cost[active]
        better = np.isfinite(new_cost) & (new_cost <= old_cost) & np.all(npts[..., 2] > 0.0, axis=1)
        rows = active[better]
        rotation[rows], t[rows] = new_rot[better], new_t[better]
        r[rows], p[rows], w[rows] = nr[better], npts[better], nw[better]
        cost[rows] = new_cost[better]
        lam = np.where(better, lam / LM_LAMBDA_DOWN, lam * LM_LAMBDA_UP)
        gained = old_cost - new_cost
        settled = ~(predicted > LM_RELATIVE_GAIN * old_cost)  # also NaN
        settled |= better & ~(gained > LM_RELATIVE_GAIN * old_cost)
        settled |= cost[active] <= COST_FLOOR_PX2
        settled |= ~better & (lam > LM_LAMBDA_MAX)
        keep = ~settled
        active, lam = active[keep], lam[keep]
    return rotation, t


def solve_ippe_vectorised(
    corners: np.ndarray, valid: np.ndarray, camera: CameraModel, side: float, settings=None
) -> BatchResult:
    """N poses by IPPE (closed form, both candidates, LM-refined, best by reprojection), vectorised.

    Args: ``corners`` (N, 4, 2) pixels of V1..V4 (distorted, as seen); ``valid`` (N,) rows that
    passed :func:`qrfield.solvers.checks.check_corners_batch`; the camera; the side L (mm);
    IppeSettings (``refine`` "lm" or "none"; "vvs", OpenCV's virtual visual servoing, reaches the
    same minimum and is run as "lm"). Returns a :class:`BatchResult` like the single path's:
    ``converged`` where a candidate lies in front of the camera facing it, ``iterations`` 0,
    ``residual_mm`` the largest distance of a vertex from its line of sight.
    """
    s = checked_settings(settings)
    if corners.ndim != 3 or corners.shape[1:] != (4, 2):
        raise SolverError(f"batch corners must have shape (N, 4, 2), got {corners.shape}")
    count = corners.shape[0]
    parts = [
        _solve_chunk(
            corners[i : i + BATCH_CHUNK], valid[i : i + BATCH_CHUNK], camera, side, s.refine != "none"
        )
        for i in range(0, count, BATCH_CHUNK)
    ] or [_solve_chunk(corners, valid, camera, side, s.refine != "none")]
    fields = (
        "position_mm",
        "angles_deg",
        "rotation",
        "converged",
        "iterations",
        "residual_mm",
        "reprojection_px",
    )
    return BatchResult(
        method="ippe",
        valid=valid.copy(),
        **{name: np.concatenate([getattr(p, name) for p in parts]) for name in fields},
    )


def _candidate_errors(
    rotation: np.ndarray, t: np.ndarray, corners: np.ndarray, camera: CameraModel, side: float
) -> np.ndarray:
    """RMS reprojection error (px) on the given corners; inf where invisible or not finite."""
    q = marker_vertices(side)
    p = np.einsum("nij,kj->nki", rotation, q) + t[:, None, :]
    in_front = np.all(p[..., 2] > 0.0, axis=1)
    facing = np.einsum("ni,ni->n", rotation[:, :, 2], t) > 0.0
    with np.errstate(all="ignore"):
        safe = np.where(in_front[:, None, None], p, 1.0)
        err = np.sqrt(np.sum((project_points(safe, camera) - corners) ** 2, axis=(1, 2)) / 4.0)
    ok = in_front & facing & np.isfinite(err)
    return np.where(ok, err, np.inf)


def _solve_chunk(
    corners: np.ndarray, valid: np.ndarray, camera: CameraModel, side: float, refined: bool
) -> BatchResult:
    count = corners.shape[0]
    position = np.full((count, 3), np.nan)
    angles = np.full((count, 3), np.nan)
    rotation_out = np.full((count, 3, 3), np.nan)
    residual = np.full(count, np.nan)
    reproj = np.full(count, np.nan)
    converged = np.zeros(count, bool)
    idx = np.flatnonzero(valid)
    if idx.size:
        xn, yn = normalised_batch(corners[idx], camera)
        with np.errstate(all="ignore"):
            h = square_homography(xn, yn, side)
            finite = np.all(np.isfinite(h), axis=(1, 2))
            best_err = np.full(idx.size, np.inf)
            best_rot = np.full((idx.size, 3, 3), np.nan)
            best_t = np.full((idx.size, 3), np.nan)
            if finite.any():
                rows, rot, t = _closed_form_candidates(h, finite, xn, yn, side, camera, refined)
                if refined:
                    rot, t = refine(rot, t, xn[rows], yn[rows], side, camera.fx, camera.fy)
                err = _candidate_errors(rot, t, corners[idx[rows]], camera, side)
                # Rows hold candidate A of every pose, then candidate B: A wins ties, as it does in
                # the single path (OpenCV's first candidate).
                for part in (slice(0, rows.size // 2), slice(rows.size // 2, rows.size)):
                    r_part = rows[part]
                    better = err[part] < best_err[r_part]
                    best_err[r_part[better]] = err[part][better]
                    best_rot[r_part[better]] = rot[part][better]
                    best_t[r_part[better]] = t[part][better]
        found = np.isfinite(best_err)
        rows = idx[found]
        converged[rows] = True
        rotation_out[rows] = best_rot[found]
        position[rows] = best_t[found]
        angles[rows] = angles_from_rotation(best_rot[found])
        reproj[rows] = best_err[found]
        residual[rows] = _line_of_sight_distance(best_rot[found], best_t[found], xn[found], yn[found], side)
    return BatchResult(
        method="ippe",
        position_mm=position,
        angles_deg=angles,
        rotation=rotation_out,
        converged=converged,
        iterations=np.zeros(count, int),
        residual_mm=residual,
        reprojection_px=reproj,
        valid=valid.copy(),
    )


def _closed_form_candidates(
    h: np.ndarray,
    finite: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    side: float,
    camera: CameraModel,
    refined: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Both IPPE candidates of every row with a finite homography, stacked for one refinement.

    Returns (rows, R, t): rows index x / y, first every row's candidate A, then candidate B
    (both halves have the same rows). Where one candidate already reprojects exactly (squared
    error below COST_FLOOR_PX2) both halves hold it and nothing is refined: refining can only
    lower the other's error, never below zero, so the exact one is the answer either way.
    """
    ok = np.flatnonzero(finite)
    rot_a, rot_b = ippe_rotations(h[ok])
    good = np.all(np.isfinite(rot_a), axis=(1, 2)) & np.all(np.isfinite(rot_b), axis=(1, 2))
    ok, rot_a, rot_b = ok[good], rot_a[good], rot_b[good]
    t_a = least_squares_translation(rot_a, x[ok], y[ok], side)
    t_b = least_squares_translation(rot_b, x[ok], y[ok], side)
    if refined:
        q = marker_vertices(side)
        res_a, _, _ = _residuals(rot_a, t_a, x[ok], y[ok], q, camera.fx, camera.fy)
        res_b, _, _ = _residuals(rot_b, t_b, x[ok], y[ok], q, camera.fx, camera.fy)
        exact_a = np.einsum("ni,ni->n", res_a, res_a) <= COST_FLOOR_PX2
        exact_b = ~exact_a & (np.einsum("ni,ni->n", res_b, res_b) <= COST_FLOOR_PX2)
        rot_b[exact_a], t_b[exact_a] = rot_a[exact_a], t_a[exact_a]
        rot_a[exact_b], t_a[exact_b] = rot_b[exact_b], t_b[exact_b]
    return np.concatenate([ok, ok]), np.concatenate([rot_a, rot_b]), np.concatenate([t_a, t_b])


def _line_of_sight_distance(
    rotation: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray, side: float
) -> np.ndarray:
    """(M,) the largest distance (mm) of a vertex of the square at (R, t) from its corner's line of sight."""
    p = np.einsum("nij,kj->nki", rotation, marker_vertices(side)) + t[:, None, :]
    rays = np.stack([x, y, np.ones_like(x)], axis=-1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    along = np.einsum("nki,nki->nk", p, rays)
    off = p - along[..., None] * rays
    return np.max(np.linalg.norm(off, axis=-1), axis=1)
