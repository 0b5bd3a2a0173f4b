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

The mirror test: the reprojection chi-square r^T Sigma_n^-1 r of the answer and of its mirror
candidate; ``ambiguous`` when the mirror's exceeds the answer's by less than FLIP_DELTA_CHI2 (a
likelihood ratio mirror / answer above exp(-FLIP_DELTA_CHI2 / 2)). There the error is not Gaussian
(the two branches of the planar ambiguity are both plausible) and the std does not describe it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import marker_vertices
from qrfield.solvers.result import PoseResult, SolverError

#: The mirror candidate counts as fitting the corners within their uncertainty when its
#: reprojection chi-square exceeds the answer's by less than this, i.e. when the mirror is at least
#: exp(-2) = 14 % as likely as the answer (measured recall and precision: docs/uncertainty.md).
FLIP_DELTA_CHI2 = 4.0
#: Without a corner covariance the test falls back on the ratio of the two candidates' RMS
#: reprojection errors (``PoseResult.ambiguity``): at or above this the mirror counts as fitting.
AMBIGUITY_FALLBACK = 0.5
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


def check_corners_cov(cov: object, batch: int | None = None) -> np.ndarray:
    """A corner covariance as float (4, 2, 2) px^2, or (N, 4, 2, 2) when ``batch`` = N (a single
    (4, 2, 2) is then shared by every row); SolverError saying what is wrong (shape, NaN/inf, not
    symmetric, not positive semi-definite)."""
    try:
        c = np.array(cov, dtype=float)
    except (TypeError, ValueError):
        raise SolverError("corners_cov must be a numeric (4, 2, 2) array of px^2 (V1..V4)") from None
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
    return np.sqrt(np.maximum(cov[..., 0, 0] + cov[..., 1, 1], 0.0))


# ---------------------------------------------------------------------- corners -> normalised


def distortion_jacobian(x: np.ndarray, y: np.ndarray, camera: CameraModel) -> np.ndarray:
    """(..., 2, 2) derivative of OpenCV's 5-term distortion (distorted over ideal normalised
    coordinates) at ideal normalised points (x, y) (...)."""
    k1, k2, p1, p2, k3 = (float(v) for v in camera.dist)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    g = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))  # 2 d radial / d r2
    cross = x * y * g + 2.0 * p1 * x + 2.0 * p2 * y
    out = np.empty((*np.shape(x), 2, 2))
    out[..., 0, 0] = radial + x * x * g + 2.0 * p1 * y + 6.0 * p2 * x
    out[..., 0, 1] = cross
    out[..., 1, 0] = cross
    out[..., 1, 1] = radial + y * y * g + 6.0 * p1 * y + 2.0 * p2 * x
    return out


def normalised_cov(cov_px: np.ndarray, x: np.ndarray, y: np.ndarray, camera: CameraModel) -> np.ndarray:
    """(..., 4, 2, 2) covariance of the undistorted normalised coordinates (x, y) (..., 4) of the
    corners, from their pixel covariance (..., 4, 2, 2) as seen (distorted)."""
    scale = np.array([1.0 / camera.fx, 1.0 / camera.fy])
    cov = cov_px * (scale[:, None] * scale[None, :])  # distorted normalised coordinates
    if not camera.has_distortion:
        return cov
    inv = np.linalg.inv(distortion_jacobian(x, y, camera))
    return inv @ cov @ np.swapaxes(inv, -1, -2)


def _inverse_2x2(m: np.ndarray) -> np.ndarray:
    """(..., 2, 2) inverses in closed form."""
    a, b, c, d = m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1]
    det = a * d - b * c
    out = np.empty_like(m)
    out[..., 0, 0], out[..., 0, 1] = d / det, -b / det
    out[..., 1, 0], out[..., 1, 1] = -c / det, a / det
    return out


def information(cov_n: np.ndarray) -> np.ndarray:
    """(..., 4, 2, 2) inverses of the corners' normalised covariance blocks; a block without
    variance gets a floor of 1e-12 of the largest, so that exact corners stay usable."""
    floor = 1e-12 * np.maximum(np.max(cov_n[..., 0, 0] + cov_n[..., 1, 1], axis=-1), 1e-300)
    return _inverse_2x2(cov_n + floor[..., None, None, None] * _EYE3[:2, :2])


# ---------------------------------------------------------------------- Jacobians of the solvers


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) matrices [v]x with [v]x w = v x w."""
    zero = np.zeros(v.shape[:-1])
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([zero, -vz, vy, vz, zero, -vx, -vy, vx, zero], axis=-1).reshape(*v.shape[:-1], 3, 3)


def rigid_jacobian(rotation: np.ndarray, position: np.ndarray, side: float) -> np.ndarray:
    """(..., 8, 6) derivative of the rigid square's normalised projection (x1, y1, ..., x4, y4) at
    pose (R (..., 3, 3), t (..., 3) mm) with respect to p = (omega rad, t mm)."""
    arm = np.matmul(rotation[..., None, :, :], marker_vertices(side)[:, :, None])[..., 0]  # R q_i
    p = arm + position[..., None, :]
    inv_z = 1.0 / p[..., 2]
    u, v = p[..., 0] * inv_z, p[..., 1] * inv_z
    # d(u, v)/dP = [[1, 0, -u], [0, 1, -v]] / Z; dP/d omega = -[R q]x, dP/dt = I.
    dproj = np.zeros((*p.shape[:-1], 2, 3))
    dproj[..., 0, 0] = dproj[..., 1, 1] = 1.0
    dproj[..., 0, 2], dproj[..., 1, 2] = -u, -v
    dproj *= inv_z[..., None, None]
    jac = np.concatenate([-dproj @ _skew(arm), dproj], axis=-1)  # (..., 4, 2, 6)
    return jac.reshape(*p.shape[:-2], 8, 6)


def ippe_jacobian(rotation: np.ndarray, position: np.ndarray, side: float, camera: CameraModel) -> np.ndarray:
    """(..., 6, 8) derivative of the least-squares pose (IPPE refined by LM or VVS, unweighted
    pixels) p = (omega, t) with respect to the normalised corners: (J^T W J)^-1 J^T W."""
    jac = rigid_jacobian(rotation, position, side)
    w = np.tile([camera.fx**2, camera.fy**2], 4)
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
    rays = np.stack([x, y, np.ones_like(x)], axis=-1)  # (..., 4, 3)
    verts = z[..., None] * rays
    d = _INCIDENCE @ verts  # (..., 6, 3): V_i - V_j of each pair
    e = d / np.sqrt(np.sum(d * d, axis=-1, keepdims=True))
    jz = _INCIDENCE * (e @ np.swapaxes(rays, -1, -2))  # d diff_k / d z_i, (..., 6, 4)
    jn = (_INCIDENCE[:, :, None] * e[..., :, None, :2]) * z[..., None, :, None]  # (..., 6, 4, 2)
    jzt = np.swapaxes(jz, -1, -2)
    dz = -np.linalg.solve(jzt @ jz, jzt @ jn.reshape(*jn.shape[:-2], 8))  # (..., 4, 8)
    # dV_i / dn = m_i dz_i / dn + z_i (unit steps in x_i and y_i).
    dv = rays[..., :, :, None] * dz[..., :, None, :] + _UNIT_STEPS * z[..., :, None, None]  # (..., 4, 3, 8)
    arm = verts - verts.mean(axis=-2, keepdims=True)
    outer = np.swapaxes(arm, -1, -2) @ arm
    h = np.trace(outer, axis1=-2, axis2=-1)[..., None, None] * _EYE3 - outer
    torque = np.sum(_skew(arm) @ dv, axis=-3)  # sum_i p_i x dV_i, (..., 3, 8)
    return np.concatenate([np.linalg.solve(h, torque), dv.mean(axis=-3)], axis=-2)


def euler_jacobian(angles_deg: np.ndarray) -> np.ndarray:
    """(..., 3, 3) derivative of (alpha, beta, gamma) in degrees with respect to omega (radians):
    the inverse of E = [e_x, Rx(alpha) e_y, Rx(alpha) Ry(beta) e_z]; NaN at gimbal lock."""
    if np.ndim(angles_deg) == 1:  # one pose: Python floats, no numpy call overhead
        alpha, beta = math.radians(float(angles_deg[0])), math.radians(float(angles_deg[1]))
        ca, sa, cb, sb = math.cos(alpha), math.sin(alpha), math.cos(beta), math.sin(beta)
        inv_cb = 1.0 / cb if abs(cb) > 1e-9 else math.nan
        rows = [[1.0, sa * sb * inv_cb, -ca * sb * inv_cb], [0.0, ca, sa], [0.0, -sa * inv_cb, ca * inv_cb]]
        return math.degrees(1.0) * np.array(rows)
    a = np.radians(angles_deg)
    ca, sa = np.cos(a[..., 0]), np.sin(a[..., 0])
    cb, sb = np.cos(a[..., 1]), np.sin(a[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_cb = np.where(np.abs(cb) > 1e-9, 1.0 / cb, np.nan)
    zero, one = np.zeros_like(ca), np.ones_like(ca)
    rows = [one, sa * sb * inv_cb, -ca * sb * inv_cb, zero, ca, sa, zero, -sa * inv_cb, ca * inv_cb]
    return math.degrees(1.0) * np.stack(rows, axis=-1).reshape(*ca.shape, 3, 3)


def pose_covariance(jac: np.ndarray, cov_n: np.ndarray, angles_deg: np.ndarray) -> np.ndarray:
    """(..., 6, 6) covariance of (x, y, z mm, alpha, beta, gamma deg) from the Jacobian (..., 6, 8)
    of p = (omega, t) over the normalised corners and their covariance (..., 4, 2, 2)."""
    full = np.concatenate([jac[..., 3:, :], euler_jacobian(angles_deg) @ jac[..., :3, :]], axis=-2)
    sigma = np.zeros((*cov_n.shape[:-3], 4, 2, 4, 2))
    for i in range(4):  # block diagonal: corners independent
        sigma[..., i, :, i, :] = cov_n[..., i, :, :]
    sigma = sigma.reshape(*cov_n.shape[:-3], 8, 8)
    return full @ sigma @ np.swapaxes(full, -1, -2)


def pose_std(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position std (..., 3) mm, angle std (..., 3) deg) from a pose covariance (..., 6, 6)."""
    diag = np.sqrt(np.maximum(np.diagonal(cov, axis1=-2, axis2=-1), 0.0))
    return diag[..., :3], diag[..., 3:]


# ---------------------------------------------------------------------- the mirror test


def reprojection_chi2(
    rotations: np.ndarray, positions: np.ndarray, side: float, n_obs: np.ndarray, info: np.ndarray
) -> np.ndarray:
    """(k,) chi-square sum_i r_i^T W_i r_i of rigid squares at poses (k, 3, 3), (k, 3) against the
    normalised corners n_obs (4, 2) with information blocks W (4, 2, 2); inf when a vertex is
    behind the camera."""
    p = np.matmul(rotations[:, None, :, :], marker_vertices(side)[:, :, None])[..., 0] + positions[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = n_obs - p[..., :2] / p[..., 2:3]  # (k, 4, 2)
    chi2 = np.sum(r[..., None, :] @ info @ r[..., :, None], axis=(1, 2, 3))
    return np.where(np.all(p[..., 2] > 0.0, axis=-1), chi2, np.inf)


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


def with_uncertainty(
    result: PoseResult,
    corners: np.ndarray,
    flat: list[float],
    camera: CameraModel,
    side: float,
    cov: np.ndarray | None,
) -> PoseResult:
    """``result`` with its uncertainty fields and the mirror test filled (see :class:`PoseResult`).

    ``cov`` is the checked (4, 2, 2) corner covariance in px^2, or None when unknown (then the std
    fields stay NaN and the mirror test falls back on the ratio ``ambiguity``). A result that did
    not converge gets only ``corners_std_px``.
    """
    from qrfield.solvers.rays import normalised_single

    fields: dict[str, object] = {}
    if cov is not None:
        fields["corners_std_px"] = corners_std_px(cov)
    if not (result.converged and np.isfinite(result.rotation).all()):
        return replace(result, **fields) if fields else result
    if cov is None:
        alt = result.alternative
        if alt is not None and result.ambiguity is not None:
            better = alt.reprojection_px < result.reprojection_px
            return replace(result, ambiguous=bool(better or result.ambiguity >= AMBIGUITY_FALLBACK))
        return result
    x_list, y_list = normalised_single(corners, flat, camera)
    x, y = np.array(x_list), np.array(y_list)
    cov_n = normalised_cov(cov, x, y, camera)
    if result.method == "numerical":
        jac = numerical_jacobian(result.vertices_mm[:, 2], x, y)
    else:
        jac = ippe_jacobian(result.rotation, result.position_mm, side, camera)
    pose_cov = pose_covariance(jac, cov_n, result.angles_deg)
    fields["pose_cov"] = pose_cov
    fields["position_std_mm"], fields["angles_std_deg"] = pose_std(pose_cov)
    rotations, positions = [result.rotation], [result.position_mm]
    mirror = _mirror_start(result, x_list, y_list)
    if mirror is not None:
        rotations.append(mirror[0])
        positions.append(mirror[1])
    n_obs = np.stack([x, y], axis=-1)
    chi2 = reprojection_chi2(np.array(rotations), np.array(positions), side, n_obs, information(cov_n))
    fields["chi2"] = float(chi2[0])
    if mirror is not None:
        fields.update(mirror_chi2=float(chi2[1]), ambiguous=is_ambiguous(chi2[0], chi2[1]))
    return replace(result, **fields)


def _mirror_start(result: PoseResult, x: list[float], y: list[float]) -> tuple[np.ndarray, np.ndarray] | None:
    """(R, t) of the mirror candidate: the method's alternative, or for the numerical model without
    one the reflected plane its mirror search starts from; None when no mirror is in view."""
    if result.alternative is not None and np.isfinite(result.alternative.rotation).all():
        return result.alternative.rotation, result.alternative.position_mm
    if result.method != "numerical":
        return None  # IPPE's second candidate was behind the camera or facing away: no mirror
    from qrfield.solvers.numerical import reflected_pose

    return reflected_pose(result, x, y)


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
    rotation (N, 3, 3), position (N, 3), angles (N, 3) and, for "numerical", depths (N, 4)."""
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
    if method == "numerical":
        jac = numerical_jacobian(depths[idx], x, y)
    else:
        jac = ippe_jacobian(rotation[idx], position[idx], side, camera)
    pos_std, ang_std = pose_std(pose_covariance(jac, normalised_cov(cov[idx], x, y, camera), angles[idx]))
    out["position_std_mm"][idx] = pos_std
    out["angles_std_deg"][idx] = ang_std
    return out
