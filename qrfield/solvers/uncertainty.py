"""Pose uncertainty: the corners' covariance propagated to the pose, and the mirror (flip) test.

Conventions (docs/conventions.md, "Pose uncertainty"): corners V1..V4 in pixels as seen (distorted),
their covariance (4, 2, 2) in px^2 (one 2x2 block per corner, corners independent); the pose is
(x, y, z) in mm and (alpha, beta, gamma) in degrees with R = Rx(alpha) Ry(beta) Rz(gamma).
The array functions accept a leading batch shape (...) and keep it.

Method (first order; measured calibration in docs/uncertainty.md):
  1. The corner covariance goes through the exact undistortion to normalised ideal coordinates
     n = (x_i, y_i), the solvers' own input: Sigma_n = U Sigma U^T with U = D^-1 diag(1/fx, 1/fy),
     D the 2x2 Jacobian of the distortion at the undistorted point.
  2. Each solver is a function p(n) of those 8 numbers, p = (omega, t), omega a small rotation of
     the camera frame (R -> exp([omega]x) R). Its Jacobian A = dp/dn is analytic:
       - "ippe" (refined by LM or VVS) is the least-squares fit of the rigid square's projection to
         the ideal pixels: A = (J^T W J)^-1 J^T W with J (8 x 6) the projection's Jacobian and
         W = diag(fx^2, fy^2, ...) (pixels, unweighted, as OpenCV's refinement);
       - "numerical" solves the four depths z from the six lengths (Gauss-Newton to their
         least-squares optimum; implicit function theorem: dz/dn = -(Jz^T Jz)^-1 Jz^T Jn), then
         fits the rotation to the vertices V_i = z_i (x_i, y_i, 1) (Kabsch: d omega =
         H^-1 sum p_i x dV_i with H = sum |p_i|^2 I - p_i p_i^T, p_i the centred vertices) and
         takes the mean vertex as the position.
  3. The pose covariance is A Sigma_n A^T; the angles follow from omega by the inverse of the
     Euler-rate matrix E = [e_x, Rx e_y, Rx Ry e_z] (singular at beta = +-90: NaN there).

The mirror test: the reprojection chi-square r^T Sigma_n^-1 r of the answer's branch and of its
mirror's (each at its own chi-square optimum, one Gauss-Newton step from the solver's pose);
``ambiguous`` when the mirror's exceeds the answer's by less than FLIP_DELTA_CHI2 (a likelihood
ratio mirror / answer above exp(-FLIP_DELTA_CHI2 / 2)). There the error is not Gaussian
(the two branches of the planar ambiguity are both plausible) and the std does not describe it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import marker_vertices
from qrfield.lens import distortion_jacobian_terms, has_distortion
from qrfield.solvers.rays import normalised_single
from qrfield.solvers.result import PoseResult, SolverError

#: The mirror candidate counts as fitting the corners within their uncertainty when its
#: reprojection chi-square exceeds the answer's by less than this, i.e. when the mirror is at least
#: exp(-4.5) = 1.1 % as likely as the answer. Chosen for recall: on seeded views with known noise
#: it leaves no flip unflagged, where 4 and 6 leave a few, each a pose tens of degrees off with a
#: std of a degree (measured recall and precision: docs/uncertainty.md, ``qrfield benchmark pose``).
FLIP_DELTA_CHI2 = 9.0
#: The degrees of freedom of a branch's reprojection chi-square (``PoseResult.chi2``: 8 corner
#: coordinates, 6 pose parameters).
FIT_DOF = 2.0
#: A fit whose chi-square exceeds this (the 0.99 quantile of chi-square with FIT_DOF degrees of
#: freedom) says its corners are further off the pose's projection than their covariance allows:
#: the camera model, the side or the corners are wrong, and the propagated std, which assumes they
#: are right, is too small (``PoseResult.misfit``; ``qrfield solve`` warns; the live stream scales
#: such a frame's covariance by 1 + (chi2 - FIT_CHI2) / FIT_DOF, :func:`qrfield.stream.continuity.fit_scale`).
#: About 1 % of fits whose corners are as their covariance says lie above it.
FIT_CHI2 = 9.21
#: Without a corner covariance the test falls back on the ratio of the two candidates' RMS
#: reprojection errors (``PoseResult.ambiguity``): at or above this the mirror counts as fitting.
AMBIGUITY_FALLBACK = 0.5
#: The share of a frame's pose variance (x, y, z, alpha, beta, gamma) that the frames of a still
#: card share: the corner fit's error is mostly fixed by the view (the card's pixels, its blur, its
#: lighting), not drawn afresh each frame, so averaging N frames leaves this share of each frame's
#: variance. Measured on rendered still cards with fresh sensor noise per frame (``qrfield benchmark
#: stream``, section 1; docs/uncertainty.md, "Frames of a still card share their error").
FRAME_SHARED_SHARE = (0.67, 0.68, 0.68, 0.57, 0.61, 0.52)
#: Relative asymmetry tolerated in a 2x2 corner covariance block.
SYMMETRY_RTOL = 1e-6

_EYE3 = np.eye(3)
_FOUR = np.arange(4)


def _incidence() -> np.ndarray:
    """(6, 4): +1 at vertex i and -1 at vertex j of each pair (i, j) of qrfield.solvers.kernel.PAIRS."""
    from qrfield.solvers.kernel import PAIRS

    out = np.zeros((6, 4))
    for k, (i, j) in enumerate(PAIRS):
        out[k, i], out[k, j] = 1.0, -1.0
    return out


def _unit_steps() -> np.ndarray:
    """(4, 3, 8): dV_i / d(x_i, y_i) at unit depth (ones at [i, 0, 2i] and [i, 1, 2i + 1])."""
    out = np.zeros((4, 3, 8))
    out[_FOUR, 0, 2 * _FOUR] = 1.0
    out[_FOUR, 1, 2 * _FOUR + 1] = 1.0
    return out


_INCIDENCE = _incidence()
_UNIT_STEPS = _unit_steps()
#: (3, 9): v @ _LEVI_CIVITA is [v]x flattened.
_LEVI_CIVITA = np.array(
    [[0, 0, 0, 0, 0, -1, 0, 1, 0], [0, 0, 1, 0, 0, 0, -1, 0, 0], [0, -1, 0, 1, 0, 0, 0, 0, 0]], dtype=float
)
#: Flat indices of the 4 diagonal 2x2 blocks of an 8 x 8 matrix, in (corner, row, column) order.
_BLOCK_DIAGONAL = np.array(
    [(2 * i + r) * 8 + 2 * i + c for i in range(4) for r in range(2) for c in range(2)]
)


def check_corners_cov(cov: object, batch: int | None = None) -> np.ndarray:
    """A corner covariance as float (4, 2, 2) px^2, or (N, 4, 2, 2) when ``batch`` = N (a single
    (4, 2, 2) is then shared by every row); SolverError saying what is wrong (shape, NaN/inf, not
    symmetric, not positive semi-definite)."""
    try:
        c = np.array(cov, dtype=float)
    except (TypeError, ValueError):
        raise SolverError("corners_cov must be a numeric (4, 2, 2) array of px^2 (V1..V4)") from None
    if batch is None and c.shape == (4, 2, 2) and _usable_single(c.reshape(16).tolist()):
        return c  # the usual case, checked in Python floats; else the checks below say what is wrong
    if batch is not None and c.shape == (4, 2, 2):
        c = np.broadcast_to(c, (batch, 4, 2, 2)).copy()
    want = (4, 2, 2) if batch is None else (batch, 4, 2, 2)
    if c.shape != want:
        raise SolverError(
            f"corners_cov must have shape {want}: a 2x2 covariance in px^2 per corner V1..V4, got {c.shape}"
        )
    a, b, d = c[..., 0, 0], c[..., 0, 1], c[..., 1, 1]
    if not np.isfinite(c).all():
        raise SolverError("corners_cov contains NaN or inf")
    if (np.abs(b - c[..., 1, 0]) > SYMMETRY_RTOL * (a + d + 1e-300)).any():
        raise SolverError("corners_cov is not symmetric (each corner's 2x2 block must equal its transpose)")
    if (a < 0.0).any() or (d < 0.0).any() or (a * d - b * b < -1e-9 * (a + d) ** 2).any():
        raise SolverError(
            "corners_cov is not a covariance: a negative variance or a 2x2 block that is not "
            "positive semi-definite"
        )
    return c


def _usable_single(v: list[float]) -> bool:
    """The checks of :func:`check_corners_cov` on one (4, 2, 2) covariance as 16 floats: all pass."""
    for i in range(0, 16, 4):
        a, b, c, d = v[i : i + 4]
        if not (
            math.isfinite(a + b + c + d)
            and abs(b - c) <= SYMMETRY_RTOL * (a + d + 1e-300)
            and a >= 0.0
            and d >= 0.0
            and a * d - b * b >= -1e-9 * (a + d) ** 2
        ):
            return False
    return True


def isotropic_cov(std_px: float, batch: int | None = None) -> np.ndarray:
    """(4, 2, 2) covariance of independent corners with ``std_px`` on each coordinate, px
    ((N, 4, 2, 2) with ``batch``)."""
    try:
        std = float(std_px)
    except (TypeError, ValueError):
        raise SolverError(f"corner standard deviation must be a number of pixels, got {std_px!r}") from None
    if not math.isfinite(std) or std < 0.0:
        raise SolverError(f"corner standard deviation must be a finite number of pixels >= 0, got {std_px!r}")
    cov = np.zeros((4, 2, 2))
    cov[:, 0, 0] = cov[:, 1, 1] = std * std
    return cov if batch is None else np.broadcast_to(cov, (batch, 4, 2, 2)).copy()


def corners_std_px(cov: np.ndarray) -> np.ndarray:
    """(..., 4) RMS radius of each corner's uncertainty, sqrt(trace of its 2x2 block), px."""
    if cov.shape == (4, 2, 2):  # one corner set (every frame's solve): in floats
        c = cov.reshape(16).tolist()
        return np.array([math.sqrt(max(c[k] + c[k + 3], 0.0)) for k in range(0, 16, 4)])
    return np.sqrt(np.maximum(cov[..., 0, 0] + cov[..., 1, 1], 0.0))


# ---------------------------------------------------------------------- corners -> normalised


def distortion_jacobian(x: np.ndarray, y: np.ndarray, camera: CameraModel) -> np.ndarray:
    """(..., 2, 2) derivative of OpenCV's 5-term distortion (distorted over ideal normalised
    coordinates) at ideal normalised points (x, y) (...)."""
    j00, j01, j11 = distortion_terms(x, y, camera)
    out = np.empty((*np.shape(x), 2, 2))
    out[..., 0, 0] = j00
    out[..., 0, 1] = j01
    out[..., 1, 0] = j01
    out[..., 1, 1] = j11
    return out


def distortion_terms(x: Any, y: Any, camera: CameraModel) -> tuple[Any, Any, Any]:
    """The entries (d00, d01 = d10, d11) of :func:`distortion_jacobian` at (x, y): Python floats or
    arrays (...) alike (the single path passes floats; qrfield.lens.distortion_jacobian_terms)."""
    return distortion_jacobian_terms(camera.dist.tolist(), x, y)


def normalised_cov(cov_px: np.ndarray, x: np.ndarray, y: np.ndarray, camera: CameraModel) -> np.ndarray:
    """(..., 4, 2, 2) covariance of the undistorted normalised coordinates (x, y) (..., 4) of the
    corners, from their pixel covariance (..., 4, 2, 2) as seen (distorted)."""
    scale = np.array([1.0 / camera.fx, 1.0 / camera.fy])
    cov = cov_px * (scale[:, None] * scale[None, :])  # distorted normalised coordinates
    if not camera.has_distortion:
        return cov
    inv = np.linalg.inv(distortion_jacobian(x, y, camera))
    return inv @ cov @ np.swapaxes(inv, -1, -2)


def information_matrix(cov_n: np.ndarray) -> np.ndarray:
    """(8, 8) block-diagonal inverse of one corner set's normalised covariance (4, 2, 2); a floor of
    1e-12 of the largest variance (and 1e-30, about 1e-12 px^2, when all are 0) keeps exact
    corners usable."""
    return block_diagonal(information_blocks(cov_n.reshape(16).tolist()))


def block_diagonal(blocks: list[float]) -> np.ndarray:
    """(8, 8) block-diagonal matrix of the four 2x2 blocks given as 16 floats (corner, row, column);
    (m, 8, 8) for m such sets of 16 floats one after the other."""
    m = len(blocks) // 16
    out = [0.0] * (64 * m)
    for k in range(m):
        for i in range(4):
            at, b = 64 * k + 18 * i, 16 * k + 4 * i  # row 2i, column 2i of matrix k
            out[at], out[at + 1], out[at + 8], out[at + 9] = blocks[b : b + 4]
    return np.array(out).reshape(8, 8) if m == 1 else np.array(out).reshape(m, 8, 8)


def information_blocks(c: list[float]) -> list[float]:
    """The inverses of the four 2x2 blocks of a normalised covariance given as 16 floats (corner,
    row, column), in the same layout, with the floor of :func:`information_matrix`."""
    floor = 1e-12 * max(c[4 * i] + c[4 * i + 3] for i in range(4)) + 1e-30
    out = []
    for i in range(4):
        a, b, cc, d = c[4 * i] + floor, c[4 * i + 1], c[4 * i + 2], c[4 * i + 3] + floor
        det = a * d - b * cc
        out += [d / det, -b / det, -cc / det, a / det]
    return out


# ---------------------------------------------------------------------- Jacobians of the solvers


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) matrices [v]x with [v]x w = v x w (one matmul: [v]x is linear in v)."""
    return (v @ _LEVI_CIVITA).reshape(*v.shape[:-1], 3, 3)


@functools.lru_cache(maxsize=16)
def _vertices(side: float) -> np.ndarray:
    """marker_vertices(side), cached read-only (4, 3) mm."""
    q = marker_vertices(side)
    q.setflags(write=False)
    return q


def rigid_projection(
    rotation: np.ndarray, position: np.ndarray, side: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rigid square at pose (R (..., 3, 3), t (..., 3) mm): its normalised projection (..., 8)
    (x1, y1, ..., x4, y4), that projection's Jacobian (..., 8, 6) with respect to p = (omega rad,
    t mm), and the vertices' depths (..., 4) mm (a depth <= 0 makes the first two meaningless)."""
    arm = rotation[..., None, :, :] @ _vertices(side)[:, :, None]  # R q_i, (..., 4, 3, 1)
    arm = arm[..., 0]
    p = arm + position[..., None, :]
    ax, ay, az = arm[..., 0], arm[..., 1], arm[..., 2]
    inv_z = 1.0 / p[..., 2]
    u, v = p[..., 0] * inv_z, p[..., 1] * inv_z
    # du/domega = (R q) x (1, 0, -u) / Z, dv/domega = (R q) x (0, 1, -v) / Z;
    # d(u, v)/dt = [[1, 0, -u], [0, 1, -v]] / Z.
    jac = np.zeros((*p.shape[:-1], 2, 6))
    jac[..., 0, 0], jac[..., 0, 1], jac[..., 0, 2] = -u * ay, az + u * ax, -ay
    jac[..., 1, 0], jac[..., 1, 1], jac[..., 1, 2] = -v * ay - az, v * ax, ax
    jac[..., 0, 3], jac[..., 1, 4] = 1.0, 1.0
    jac[..., 0, 5], jac[..., 1, 5] = -u, -v
    jac *= inv_z[..., None, None]
    proj = np.stack([u, v], axis=-1)
    return proj.reshape(*p.shape[:-2], 8), jac.reshape(*p.shape[:-2], 8, 6), p[..., 2]


def rigid_jacobian(rotation: np.ndarray, position: np.ndarray, side: float) -> np.ndarray:
    """(..., 8, 6) derivative of the rigid square's normalised projection (x1, y1, ..., x4, y4) at
    pose (R (..., 3, 3), t (..., 3) mm) with respect to p = (omega rad, t mm)."""
    return rigid_projection(rotation, position, side)[1]


def ippe_jacobian(rotation: np.ndarray, position: np.ndarray, side: float, camera: CameraModel) -> np.ndarray:
    """(..., 6, 8) derivative of the least-squares pose (IPPE refined by LM or VVS, unweighted
    pixels) p = (omega, t) with respect to the normalised corners: (J^T W J)^-1 J^T W."""
    return least_squares_jacobian(rigid_jacobian(rotation, position, side), camera)


def least_squares_jacobian(jac: np.ndarray, camera: CameraModel) -> np.ndarray:
    """(J^T W J)^-1 J^T W for the rigid projection's Jacobian J (..., 8, 6), W = diag(fx^2, fy^2, ...)."""
    w = np.array([camera.fx**2, camera.fy**2] * 4)
    jtw = np.swapaxes(jac, -1, -2) * w
    return np.linalg.solve(jtw @ jac, jtw)


def numerical_jacobian(z: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(..., 6, 8) derivative of the numerical model's pose p = (omega, t) with respect to the
    normalised corners (x1, y1, ..., x4, y4), at its least-squares depths z (..., 4) (mm).

    Depths: implicit function theorem on the Gauss-Newton optimum of the six lengths (second
    derivatives of the residuals neglected, as Gauss-Newton does; exact for exact corners). Pose:
    the Kabsch rotation's first-order change (what qrfield.solvers.kernel.pose_from_vertices
    computes for four vertices) and the mean vertex.
    """
    rays = np.ones((*z.shape, 3))  # lines of sight (x, y, 1), (..., 4, 3)
    rays[..., 0], rays[..., 1] = x, y
    verts = z[..., None] * rays
    d = _INCIDENCE @ verts  # (..., 6, 3): V_i - V_j of each pair
    e = d / np.sqrt((d * d).sum(axis=-1))[..., None]
    jz = _INCIDENCE * (e @ np.swapaxes(rays, -1, -2))  # d diff_k / d z_i, (..., 6, 4)
    jn = (_INCIDENCE[:, :, None] * e[..., :, None, :2]) * z[..., None, :, None]  # (..., 6, 4, 2)
    jzt = np.swapaxes(jz, -1, -2)
    dz = np.linalg.solve(jzt @ jz, jzt @ jn.reshape(*jn.shape[:-2], 8))  # minus dz/dn, (..., 4, 8)
    # dV_i / dn = m_i dz_i / dn + z_i (unit steps in x_i and y_i).
    dv = _UNIT_STEPS * z[..., :, None, None] - rays[..., :, :, None] * dz[..., :, None, :]  # (..., 4, 3, 8)
    arm = verts - 0.25 * verts.sum(axis=-2)[..., None, :]
    outer = np.swapaxes(arm, -1, -2) @ arm
    h = (arm * arm).sum(axis=(-2, -1))[..., None, None] * _EYE3 - outer
    out = np.empty((*z.shape[:-1], 6, 8))
    out[..., :3, :] = np.linalg.solve(h, (_skew(arm) @ dv).sum(axis=-3))  # H^-1 sum_i p_i x dV_i
    out[..., 3:, :] = 0.25 * dv.sum(axis=-3)
    return out


def euler_jacobian(angles_deg: np.ndarray) -> np.ndarray:
    """(..., 3, 3) derivative of (alpha, beta, gamma) in degrees with respect to omega (radians):
    the inverse of E = [e_x, Rx(alpha) e_y, Rx(alpha) Ry(beta) e_z]; NaN at gimbal lock."""
    if np.ndim(angles_deg) == 1:  # one pose: Python floats, no numpy call overhead
        return np.array(euler_rows(float(angles_deg[0]), float(angles_deg[1])))
    a = np.radians(angles_deg)
    ca, sa = np.cos(a[..., 0]), np.sin(a[..., 0])
    cb, sb = np.cos(a[..., 1]), np.sin(a[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_cb = np.where(np.abs(cb) > 1e-9, 1.0 / cb, np.nan)
    zero, one = np.zeros_like(ca), np.ones_like(ca)
    rows = [one, sa * sb * inv_cb, -ca * sb * inv_cb, zero, ca, sa, zero, -sa * inv_cb, ca * inv_cb]
    return math.degrees(1.0) * np.stack(rows, axis=-1).reshape(*ca.shape, 3, 3)


def euler_rows(alpha_deg: float, beta_deg: float) -> list[list[float]]:
    """:func:`euler_jacobian` of one pose as rows of Python floats (deg per rad; NaN at gimbal lock)."""
    alpha, beta = math.radians(alpha_deg), math.radians(beta_deg)
    ca, sa, cb, sb = math.cos(alpha), math.sin(alpha), math.cos(beta), math.sin(beta)
    inv_cb = 1.0 / cb if abs(cb) > 1e-9 else math.nan
    deg = math.degrees(1.0)
    rows = [[1.0, sa * sb * inv_cb, -ca * sb * inv_cb], [0.0, ca, sa], [0.0, -sa * inv_cb, ca * inv_cb]]
    return [[deg * v for v in row] for row in rows]


def pose_covariance(jac: np.ndarray, cov_n: np.ndarray, angles_deg: np.ndarray) -> np.ndarray:
    """(..., 6, 6) covariance of (x, y, z mm, alpha, beta, gamma deg) from the Jacobian (..., 6, 8)
    of p = (omega, t) over the normalised corners and their covariance (..., 4, 2, 2), or one
    (4, 2, 2) shared by every row."""
    if np.ndim(angles_deg) == 2 and len(angles_deg) <= 8:  # a few poses: the scalar Euler path
        euler = np.array([euler_jacobian(a) for a in angles_deg])
    else:
        euler = euler_jacobian(angles_deg)
    full = np.concatenate([jac[..., 3:, :], euler @ jac[..., :3, :]], axis=-2)
    sigma = np.zeros((*cov_n.shape[:-3], 64))
    sigma[..., _BLOCK_DIAGONAL] = cov_n.reshape(*cov_n.shape[:-3], 16)  # corners independent
    sigma = sigma.reshape(*cov_n.shape[:-3], 8, 8)
    return full @ sigma @ np.swapaxes(full, -1, -2)


def pose_std(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position std (..., 3) mm, angle std (..., 3) deg) from a pose covariance (..., 6, 6)."""
    diag = np.sqrt(np.maximum(np.diagonal(cov, axis1=-2, axis2=-1), 0.0))
    return diag[..., :3], diag[..., 3:]


# ---------------------------------------------------------------------- the mirror test


def branch_chi2(
    projection: tuple[np.ndarray, np.ndarray, np.ndarray], n_obs: np.ndarray, info: np.ndarray
) -> np.ndarray:
    """(k,) chi-square of each branch of the ambiguity at its own chi-square optimum, from the
    rigid projections of k poses on those branches (:func:`rigid_projection`: (k, 8), (k, 8, 6),
    (k, 4)), the normalised corners n_obs (8,) and their information matrix W (8, 8).

    The optimum is that of the chi-square linearised at the pose given (one Gauss-Newton step,
    predicted): r^T W r - g^T H^-1 g with g = J^T W r, H = J^T W J. The solvers' poses minimise
    other residuals (lengths; unweighted pixels), so under an anisotropic or uneven corner
    covariance their own chi-square overstates the branch's. inf when a vertex is behind the camera.
    """
    proj, jac, depth = projection
    out = np.full(proj.shape[0], np.inf)
    front = np.flatnonzero(depth.min(axis=-1) > 0.0)
    if front.size == 0:
        return out
    r = n_obs - proj[front]  # (k, 8)
    jac = jac[front]
    jtw = np.swapaxes(jac, -1, -2) @ info
    g = jtw @ r[..., None]  # (k, 6, 1)
    step = np.linalg.solve(jtw @ jac, g)
    chi2 = ((r @ info) * r).sum(axis=-1) - (g * step).sum(axis=(-2, -1))
    out[front] = np.maximum(chi2, 0.0)
    return out


def is_misfit(chi2: float) -> bool:
    """A fit's reprojection chi-square (``PoseResult.chi2``) above FIT_CHI2: its corners are further
    off than their covariance allows. False when unknown (NaN: no covariance, no pose)."""
    return bool(math.isfinite(chi2) and chi2 > FIT_CHI2)


def is_ambiguous(chi2_answer: float, chi2_mirror: float) -> bool:
    """The mirror explains the corners within their uncertainty about as well as the answer, or better."""
    return bool(chi2_mirror - chi2_answer < FLIP_DELTA_CHI2)


def ambiguity_ratio(error_answer: float, error_mirror: float) -> float:
    """RMS reprojection error of the better-fitting of the two candidates over that of the worse,
    in [0, 1] (1: the corners cannot tell them apart); 1 when both are 0."""
    low, high = sorted((error_answer, error_mirror))
    if not math.isfinite(low):
        return math.nan
    if high == 0.0:
        return 1.0
    return low / high if math.isfinite(high) else 0.0


# ---------------------------------------------------------------------- one solve's result


def with_uncertainties(
    results: list[PoseResult],
    corners: np.ndarray,
    flat: list[float],
    camera: CameraModel,
    side: float,
    cov: np.ndarray | None,
    xy: tuple[list[float], list[float]] | None = None,
) -> list[PoseResult]:
    """``results`` (one per method, all of the same corners) with their uncertainty fields and the
    mirror test filled (see :class:`PoseResult`): the corners' normalised covariance and its
    inverse once, then per answer its Jacobian, pose covariance and the chi-squares of its branch
    and its mirror's (:mod:`qrfield.solvers.uncertainty_single`).

    ``cov`` is the checked (4, 2, 2) corner covariance in px^2, or None when unknown (then the std
    fields stay NaN and the mirror test falls back on the ratio ``ambiguity``). A result that did
    not converge gets only ``corners_std_px``. ``xy``: the corners' normalised coordinates when known.
    """
    fields: list[dict[str, object]] = [{} for _ in results]
    if cov is not None:
        std = corners_std_px(cov)
        for f in fields:
            f["corners_std_px"] = std
    poses = {}  # index -> (method, rows of R, t, angles, depths) of each converged, finite pose
    for i, r in enumerate(results):
        if r.converged:
            rows = r.rotation.tolist()
            if all(math.isfinite(v) for row in rows for v in row):
                poses[i] = (r.method, rows, r.position_mm.tolist(), r.angles_deg.tolist(), None)
    if cov is None:
        for i in poses:
            r = results[i]
            if r.alternative is not None and r.ambiguity is not None:
                better = r.alternative.reprojection_px < r.reprojection_px
                fields[i]["ambiguous"] = bool(better or r.ambiguity >= AMBIGUITY_FALLBACK)
    elif poses:
        # One corner set: Python floats and a few fused numpy calls (uncertainty_single), the same
        # numbers as the array functions above to float rounding.
        from qrfield.solvers import uncertainty_single as one

        x_list, y_list = xy if xy is not None else normalised_single(corners, flat, camera)
        cov16 = one.normalised_cov_single(cov, x_list, y_list, camera, has_distortion(camera))
        solved = list(poses)
        from qrfield.solvers.registry import uses_depth_model  # here: the registry imports the solvers

        for i in solved:
            if uses_depth_model(results[i].method):  # its covariance goes through the depths
                method, rows, t, angles, _ = poses[i]
                poses[i] = (method, rows, t, angles, results[i].vertices_mm[:, 2].tolist())
        mirrors = [_mirror_start(results[i], poses[i][1], poses[i][2], x_list, y_list) for i in solved]
        computed = one.uncertainty_fields(
            [poses[i] for i in solved], mirrors, x_list, y_list, cov16, camera, side
        )
        for i, f in zip(solved, computed, strict=True):
            fields[i].update(f)
    return [dataclasses.replace(r, **f) if f else r for r, f in zip(results, fields, strict=True)]


def _mirror_start(
    result: PoseResult, rows: list[list[float]], centre: list[float], x: list[float], y: list[float]
) -> tuple[list[list[float]], list[float]] | None:
    """(rows of R, t mm) of the mirror candidate of ``result`` (whose pose is ``rows``, ``centre``):
    the method's alternative, or for the numerical model without one the reflected plane its
    mirror search starts from; None when no mirror is in view."""
    alternative = result.alternative
    if alternative is not None:
        alt_rows = alternative.rotation.tolist()
        if all(math.isfinite(v) for row in alt_rows for v in row):
            return alt_rows, alternative.position_mm.tolist()
    from qrfield.solvers.registry import uses_depth_model  # here: the registry imports the solvers

    if not uses_depth_model(result.method):
        return None  # IPPE's second candidate was behind the camera or facing away: no mirror
    from qrfield.solvers.numerical import reflected_pose_single

    return reflected_pose_single(rows, centre, x, y)


def batch_uncertainty(
    method: str,
    corners: np.ndarray,
    cov: np.ndarray,
    camera: CameraModel,
    side: float,
    rotation: np.ndarray,
    position: np.ndarray,
    angles: np.ndarray,
    depths: np.ndarray | None,
    rows: np.ndarray,
) -> dict[str, np.ndarray]:
    """The std fields of a BatchResult ((N, 4), (N, 3), (N, 3)) for N corner sets (N, 4, 2) with
    covariances (N, 4, 2, 2); pose stds only at ``rows`` (bool (N,), the converged ones), from
    rotation (N, 3, 3), position (N, 3), angles (N, 3) and, for a depth model (the numerical one),
    depths (N, 4), else None (``method`` names the method for messages)."""
    from qrfield.solvers.rays import normalised_batch

    count = corners.shape[0]
    out = {
        "corners_std_px": corners_std_px(cov),
        "position_std_mm": np.full((count, 3), np.nan),
        "angles_std_deg": np.full((count, 3), np.nan),
    }
    idx = np.flatnonzero(rows)
    if idx.size == 0:
        return out
    x, y = normalised_batch(corners[idx], camera)
    if depths is not None:  # a depth model (the numerical one): through its depths
        jac = numerical_jacobian(depths[idx], x, y)
    else:
        jac = ippe_jacobian(rotation[idx], position[idx], side, camera)
    pos_std, ang_std = pose_std(pose_covariance(jac, normalised_cov(cov[idx], x, y, camera), angles[idx]))
    out["position_std_mm"][idx] = pos_std
    out["angles_std_deg"][idx] = ang_std
    return out
