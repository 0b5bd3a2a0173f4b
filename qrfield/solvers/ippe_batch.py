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

Why not OpenCV: it has no vectorised IPPE, and one call per pose through Python costs many times a
batch row (the figures: docs/benchmarks.md, "simulation").
OpenCV 5.0's IPPE also returns wrong poses whenever its rotation is a half turn (its ``rot2vec``
divides by sin(pi)); its frame is ours turned 180 degrees about X, so that is every pose whose
rotation axis lies in the marker's Y-Z plane: a square-on card, a tilt about Y alone, a turn in
the card's plane alone (gamma, including gamma = 180). The single path works around it with a
third start; this path has no rotation vectors and needs none. Rows agree with
:func:`qrfield.solvers.solve` (method "ippe") to far below 1e-6 mm and 1e-6 degrees on exact
corners (both reach the truth) and to the LM stopping rules on noisy ones (tests/test_solvers_ippe_batch.py).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import angles_from_rotation, marker_vertices, project_points
from qrfield.homography import square_to_quad
from qrfield.methods import IPPE
from qrfield.solvers.ippe import checked_settings
from qrfield.solvers.rays import normalised_batch
from qrfield.solvers.result import BatchResult, SolverError

#: Levenberg-Marquardt updates at most (each candidate); exact corners need none, noisy ones 2-4.
LM_MAX_ITER = 100
#: A row stops when a step predicts less than this share of its squared error as gain (the minimum
#: to rounding), or when its squared error is below COST_FLOOR_PX2 (exact corners).
LM_RELATIVE_GAIN = 1e-11
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
    # The unit square (V1 at (0, 0) .. V4 at (0, 1)) onto the quadrilateral V1 V2 V3 V4.
    unit = square_to_quad(x, y)
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
    for y: two equations linear in t per vertex (OpenCV's computeTranslation). Their 3 x 3 normal
    equations [[4, 0, -Sx], [0, 4, -Sy], [-Sx, -Sy, S2]] t = (Bx, By, Bz) (Sx = sum x_i, S2 =
    sum x_i^2 + y_i^2) are solved in closed form: eliminating tx, ty leaves tz over the spread of
    the points, sum |(x_i, y_i) - mean|^2, which is positive for any usable corner set.
    """
    w = np.matmul(marker_vertices(side), rotation.transpose(0, 2, 1))  # (N, 4, 3): R q_i
    bx = x * w[..., 2] - w[..., 0]
    by = y * w[..., 2] - w[..., 1]
    sx, sy = x.sum(axis=1), y.sum(axis=1)
    big_x, big_y = bx.sum(axis=1), by.sum(axis=1)
    big_z = -(x * bx + y * by).sum(axis=1)
    spread = (x * x + y * y).sum(axis=1) - (sx * sx + sy * sy) / 4.0
    tz = (big_z + (sx * big_x + sy * big_y) / 4.0) / spread
    return np.stack([(big_x + sx * tz) / 4.0, (big_y + sy * tz) / 4.0, tz], axis=1)


class _State:
    """Poses under refinement as structure-of-arrays: every quantity an (M,) or (4, M) array.

    r: the 9 entries of R row by row; t: tx, ty, tz; x, y: (4, M) normalised corners (vertex
    first, so that sums over the vertices are sums of contiguous rows); the squared pixel error
    ``cost`` and, per vertex, the rotated marker points w = R q and the camera-frame vertices
    p = w + t. Elementwise arithmetic on contiguous arrays is several times faster in numpy than
    stacks of 3 x 3 or 6 x 6 matrices.
    """

    def __init__(self, r: list[np.ndarray], t: list[np.ndarray], x: np.ndarray, y: np.ndarray) -> None:
        self.r, self.t, self.x, self.y = r, t, x, y

    def take(self, keep: np.ndarray) -> _State:
        out = _State([v[keep] for v in self.r], [v[keep] for v in self.t], self.x[:, keep], self.y[:, keep])
        out.cost = self.cost[keep]
        for name in ("w", "p", "res"):
            setattr(out, name, [v[:, keep] for v in getattr(self, name)])
        return out

    def evaluate(self, qx: np.ndarray, qy: np.ndarray, fx: float, fy: float) -> None:
        """Vertices, residuals (fx (X/Z - x), fy (Y/Z - y)) and squared error at the current pose."""
        r00, r01, _, r10, r11, _, r20, r21, _ = self.r
        qx, qy = qx[:, None], qy[:, None]
        wx = qx * r00 + qy * r01
        wy = qx * r10 + qy * r11
        wz = qx * r20 + qy * r21
        px, py, pz = wx + self.t[0], wy + self.t[1], wz + self.t[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            ru = fx * (px / pz - self.x)
            rv = fy * (py / pz - self.y)
            cost = (ru * ru + rv * rv).sum(axis=0)
        self.w, self.p, self.res = [wx, wy, wz], [px, py, pz], [ru, rv]
        self.cost = np.where(np.all(pz > 0.0, axis=0), cost, np.inf)


def _normal_equations(st: _State, fx: float, fy: float) -> tuple[list[list[np.ndarray]], list[np.ndarray]]:
    """J^T J (6 x 6, upper triangle filled) and J^T r of the pixel residuals, each entry (M,).

    Parameters: the rotation update w (rad, camera frame, R <- exp([w]x) R), then t (mm).
    With u = X/Z, v = Y/Z: d(X/Z)/dp = (1, 0, -u) / Z, d(Y/Z)/dp = (0, 1, -v) / Z, dp/dw = -[R q]x,
    dp/dt = I; per vertex the rows are fx / Z (-u wy, wz + u wx, -wy, 1, 0, -u) and
    fy / Z (-(wz + v wy), v wx, wx, 0, 1, -v).
    """
    wx, wy, wz = st.w
    px, py, pz = st.p
    inv_z = 1.0 / pz
    u, v = px * inv_z, py * inv_z
    fu, fv = fx * inv_z, fy * inv_z
    ju = [-fu * u * wy, fu * (wz + u * wx), -fu * wy, fu, None, -fu * u]
    jv = [-fv * (wz + v * wy), fv * v * wx, fv * wx, None, fv, -fv * v]
    ru, rv = st.res
    a: list[list[np.ndarray]] = [[None] * 6 for _ in range(6)]  # type: ignore[list-item]
    for i in range(6):
        for j in range(i, 6):
            total = 0.0
            if ju[i] is not None and ju[j] is not None:
                total = total + ju[i] * ju[j]
            if jv[i] is not None and jv[j] is not None:
                total = total + jv[i] * jv[j]
            # d(u)/d(ty) and d(v)/d(tx) are zero: J^T J[3][4] is zero.
            a[i][j] = total.sum(axis=0) if isinstance(total, np.ndarray) else np.zeros(pz.shape[1])
    g = []
    for i in range(6):
        total = 0.0
        if ju[i] is not None:
            total = total + ju[i] * ru
        if jv[i] is not None:
            total = total + jv[i] * rv
        g.append(total.sum(axis=0))
    return a, g


def _solve6(a: list[list[np.ndarray]], b: list[np.ndarray]) -> list[np.ndarray]:
    """Solve the symmetric positive definite 6 x 6 systems a x = b (upper triangle of a given) by
    Cholesky, elementwise over the rows; a row that is not positive definite comes out NaN."""
    n = 6
    low: list[list[np.ndarray]] = [[None] * n for _ in range(n)]  # type: ignore[list-item]
    with np.errstate(invalid="ignore", divide="ignore"):
        for j in range(n):
            d = a[j][j]
            for k in range(j):
                d = d - low[j][k] * low[j][k]
            low[j][j] = np.sqrt(d)
            inv = 1.0 / low[j][j]
            for i in range(j + 1, n):
                e = a[j][i]
                for k in range(j):
                    e = e - low[i][k] * low[j][k]
                low[i][j] = e * inv
        y = []
        for i in range(n):
            e = b[i]
            for k in range(i):
                e = e - low[i][k] * y[k]
            y.append(e / low[i][i])
        x: list[np.ndarray] = [None] * n  # type: ignore[list-item]
        for i in reversed(range(n)):
            e = y[i]
            for k in range(i + 1, n):
                e = e - low[k][i] * x[k]
            x[i] = e / low[i][i]
    return x


def _rotated(r: list[np.ndarray], w0: np.ndarray, w1: np.ndarray, w2: np.ndarray) -> list[np.ndarray]:
    """The 9 entries of exp([w]x) R (Rodrigues' formula, the series for tiny angles)."""
    theta2 = w0 * w0 + w1 * w1 + w2 * w2
    small = theta2 < 1e-16
    theta = np.sqrt(np.where(small, 1.0, theta2))
    s = np.where(small, 1.0 - theta2 / 6.0, np.sin(theta) / theta)
    c = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(theta)) / (theta * theta))
    # E = I + s K + c K^2 with K = [w]x; K^2 = w w^T - |w|^2 I.
    e00 = 1.0 + c * (w0 * w0 - theta2)
    e11 = 1.0 + c * (w1 * w1 - theta2)
    e22 = 1.0 + c * (w2 * w2 - theta2)
    e01, e10 = c * w0 * w1 - s * w2, c * w0 * w1 + s * w2
    e02, e20 = c * w0 * w2 + s * w1, c * w0 * w2 - s * w1
    e12, e21 = c * w1 * w2 - s * w0, c * w1 * w2 + s * w0
    e = ((e00, e01, e02), (e10, e11, e12), (e20, e21, e22))
    out = []
    for i in range(3):
        for j in range(3):
            out.append(e[i][0] * r[j] + e[i][1] * r[3 + j] + e[i][2] * r[6 + j])
    return out


def refine(
    rotation: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray, side: float, fx: float, fy: float
) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on the pixel reprojection error of the square, all rows at once.

    Args: rotations (M, 3, 3) and translations (M, 3) (mm) to start from; normalised coordinates
    x, y (M, 4) of V1..V4; the side (mm); the focal lengths (px). The error is measured on ideal
    (undistorted) pixels, fx (X/Z - x_i) and fy (Y/Z - y_i), as cv2.solvePnPRefineLM does on the
    undistorted corners. Rotation updates are applied on the left, R <- exp([w]x) R (w in the
    camera frame); Marquardt's damping, proportional to diag(J^T J) (rotation and translation
    differ in units). Returns the refined (R, t). A row stops when its error is at the rounding
    floor, when the decrease a step predicts (or brings) is a negligible share of its error (the
    minimum, to rounding), when damping can no longer lower its error, or after LM_MAX_ITER updates.
    """
    rotation, t = rotation.copy(), t.copy()
    q = marker_vertices(side)
    qx, qy = q[:, 0], q[:, 1]
    st = _State([np.ascontiguousarray(rotation[:, i, j]) for i in range(3) for j in range(3)],
                [np.ascontiguousarray(t[:, k]) for k in range(3)],
                np.ascontiguousarray(x.T), np.ascontiguousarray(y.T))  # fmt: skip
    st.evaluate(qx, qy, fx, fy)
    rows = np.arange(x.shape[0])
    keep = np.isfinite(st.cost) & (st.cost > COST_FLOOR_PX2)
    st, rows = st.take(keep), rows[keep]
    lam = np.full(rows.size, LM_LAMBDA0)

    def write_back(done: np.ndarray) -> None:
        idx = rows[done]
        for k in range(9):
            rotation[idx, k // 3, k % 3] = st.r[k][done]
        for k in range(3):
            t[idx, k] = st.t[k][done]

    for _ in range(LM_MAX_ITER):
        if rows.size == 0:
            break
        a, g = _normal_equations(st, fx, fy)
        diag = [np.maximum(a[i][i], 1e-300) for i in range(6)]
        damped = [[a[i][j] + lam * diag[i] if i == j else a[i][j] for j in range(6)] for i in range(6)]
        step = _solve6(damped, [-v for v in g])
        # The decrease of the squared error the linear model predicts for this step (>= 0):
        # -(2 g.d + d' J'J d), and (J'J + lam D) d = -g gives d' J'J d = -g.d - lam d' D d.
        predicted = sum(-g[i] * step[i] + lam * diag[i] * step[i] * step[i] for i in range(6))
        trial = _State(
            _rotated(st.r, step[0], step[1], step[2]), [st.t[k] + step[3 + k] for k in range(3)], st.x, st.y
        )
        trial.evaluate(qx, qy, fx, fy)
        old_cost = st.cost
        better = np.isfinite(trial.cost) & (trial.cost <= old_cost)
        for name in ("r", "t", "w", "p", "res"):
            current, new = getattr(st, name), getattr(trial, name)
            setattr(st, name, [np.where(better, n, v) for v, n in zip(current, new, strict=True)])
        st.cost = np.where(better, trial.cost, old_cost)
        lam = np.where(better, lam / LM_LAMBDA_DOWN, lam * LM_LAMBDA_UP)
        with np.errstate(invalid="ignore"):
            settled = ~(predicted > LM_RELATIVE_GAIN * old_cost)  # also NaN
            settled |= better & ~(old_cost - trial.cost > LM_RELATIVE_GAIN * old_cost)
        settled |= st.cost <= COST_FLOOR_PX2
        settled |= ~better & (lam > LM_LAMBDA_MAX)
        if settled.any():
            write_back(settled)
            keep = ~settled
            st, rows, lam = st.take(keep), rows[keep], lam[keep]
    if rows.size:
        write_back(np.ones(rows.size, bool))
    return rotation, t


def solve_ippe_vectorised(
    corners: np.ndarray,
    valid: np.ndarray,
    camera: CameraModel,
    side: float,
    settings=None,
    cov: np.ndarray | None = None,
) -> BatchResult:
    """N poses by IPPE (closed form, both candidates, LM-refined, best by reprojection), vectorised.

    Args: ``corners`` (N, 4, 2) pixels of V1..V4 (distorted, as seen); ``valid`` (N,) rows that
    passed :func:`qrfield.solvers.checks.check_corners_batch`; the camera; the side L (mm);
    IppeSettings (``refine`` "lm" or "none"; "vvs", OpenCV's virtual visual servoing, reaches the
    same minimum and is run as "lm"). Returns a :class:`BatchResult` like the single path's:
    ``converged`` where a candidate lies in front of the camera facing it, ``iterations`` 0,
    ``residual_mm`` the largest distance of a vertex from its line of sight. ``cov``: (N, 4, 2, 2)
    checked corner covariances (px^2) or None; propagated (vectorised) to the std fields.
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
    arrays = {
        f.name: np.concatenate([getattr(p, f.name) for p in parts])
        for f in dataclasses.fields(BatchResult)
        if f.name != "method"
    }
    if cov is not None:
        from qrfield.solvers.uncertainty import batch_uncertainty

        arrays.update(
            batch_uncertainty(
                IPPE,
                corners,
                cov,
                camera,
                side,
                arrays["rotation"],
                arrays["position_mm"],
                arrays["angles_deg"],
                None,
                arrays["converged"],
            )
        )
    return BatchResult(method=IPPE, **arrays)


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
        method=IPPE,
        position_mm=position,
        angles_deg=angles,
        rotation=rotation_out,
        converged=converged,
        iterations=np.zeros(count, int),
        residual_mm=residual,
        reprojection_px=reproj,
        valid=valid.copy(),
    )


def _squared_error(
    rotation: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray, side: float, fx: float, fy: float
) -> np.ndarray:
    """(M,) squared pixel error of poses (R (M, 3, 3), t (M, 3)) on normalised corners x, y (M, 4)."""
    q = marker_vertices(side)
    st = _State(
        [rotation[:, i, j] for i in range(3) for j in range(3)], [t[:, k] for k in range(3)], x.T, y.T
    )
    st.evaluate(q[:, 0], q[:, 1], fx, fy)
    return st.cost


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
        exact_a = _squared_error(rot_a, t_a, x[ok], y[ok], side, camera.fx, camera.fy) <= COST_FLOOR_PX2
        exact_b = ~exact_a & (
            _squared_error(rot_b, t_b, x[ok], y[ok], side, camera.fx, camera.fy) <= COST_FLOOR_PX2
        )
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
