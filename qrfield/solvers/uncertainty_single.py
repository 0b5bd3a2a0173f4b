"""The uncertainty of one corner set's poses, in Python floats and a few fused numpy calls.

The same first-order propagation and mirror test as the array functions of
:mod:`qrfield.solvers.uncertainty` (which the batch path uses, and whose docstring gives the
method), written for the single solve that every video frame makes: there the array functions
spend most of their time in the overhead of about 80 numpy calls on 8 x 6 matrices. Here the
per-vertex terms are Python floats, the matrices are built once from them, and the small linear
systems go to qrfield.linalg.small_solve (cv2's LU: a quarter of np.linalg.solve's overhead here).
The branches of one corner set (each method's answer and its mirror) share their numpy calls:
one array of their projections' Jacobians, one batched chi-square (:func:`branch_chi2_many`).
The numbers agree with the array functions to float rounding (tests/test_solvers_uncertainty_single.py
compares both on seeded poses, pinhole and distorted, both methods).

Conventions (docs/conventions.md): corners V1..V4, normalised ideal coordinates (x_i, y_i) as
Python floats, corner covariance (4, 2, 2) in px^2, poses p = (omega rad, t mm) for the
Jacobians and (x, y, z mm, alpha, beta, gamma deg) for the covariance.
"""

from __future__ import annotations

import math

import numpy as np

from qrfield.camera import CameraModel
from qrfield.linalg import small_solve
from qrfield.solvers.kernel import PAIRS
from qrfield.solvers.uncertainty import block_diagonal, distortion_terms, euler_rows, information_blocks


def normalised_cov_single(
    cov_px: np.ndarray, x: list[float], y: list[float], camera: CameraModel, distorted: bool
) -> list[float]:
    """The 16 entries (corner, row, column) of the normalised corners' covariance
    (:func:`qrfield.solvers.uncertainty.normalised_cov` of one corner set), from (4, 2, 2) px^2."""
    sx, sy = 1.0 / camera.fx, 1.0 / camera.fy
    sxx, sxy, syy = sx * sx, sx * sy, sy * sy
    c = cov_px.reshape(16).tolist()
    out = []
    for i in range(4):
        a, b, cc, d = c[4 * i] * sxx, c[4 * i + 1] * sxy, c[4 * i + 2] * sxy, c[4 * i + 3] * syy
        if distorted:
            j00, j01, j11 = distortion_terms(x[i], y[i], camera)
            det = j00 * j11 - j01 * j01
            # inv = [[j11, -j01], [-j01, j00]] / det; inv S inv^T
            i00, i01, i11 = j11 / det, -j01 / det, j00 / det
            t00, t01 = i00 * a + i01 * cc, i00 * b + i01 * d
            t10, t11 = i01 * a + i11 * cc, i01 * b + i11 * d
            a, b = t00 * i00 + t01 * i01, t00 * i01 + t01 * i11
            cc, d = t10 * i00 + t11 * i01, t10 * i01 + t11 * i11
        out += [a, b, cc, d]
    return out


def rigid_projection_single(
    rows: list[list[float]], t: list[float], side: float
) -> tuple[list[float], list[float], float]:
    """The rigid square at pose (rows of R, t mm): its normalised projection (8 floats x1, y1, ...),
    that projection's Jacobian (48 floats: 8 rows of 6, d/d(omega rad, t mm)) and its nearest
    vertex depth (mm; <= 0 makes the other two meaningless).
    :func:`qrfield.solvers.uncertainty.rigid_projection` of one pose."""
    h = side / 2.0
    (r00, r01, _), (r10, r11, _), (r20, r21, _) = rows
    tx, ty, tz = t
    proj: list[float] = []
    jac: list[float] = []
    nearest = math.inf
    for qx, qy in ((-h, -h), (h, -h), (h, h), (-h, h)):
        ax, ay, az = r00 * qx + r01 * qy, r10 * qx + r11 * qy, r20 * qx + r21 * qy
        pz = az + tz
        nearest = min(nearest, pz)
        inv_z = 1.0 / pz if pz != 0.0 else math.inf
        u, v = (ax + tx) * inv_z, (ay + ty) * inv_z
        proj += [u, v]
        jac += [-u * ay * inv_z, (az + u * ax) * inv_z, -ay * inv_z, inv_z, 0.0, -u * inv_z]
        jac += [(-v * ay - az) * inv_z, v * ax * inv_z, ax * inv_z, 0.0, inv_z, -v * inv_z]
    return proj, jac, nearest


def _inverse3(m: list[float]) -> list[float]:
    """The inverse of a 3 x 3 matrix given as 9 floats (row-major), by its adjugate."""
    a, b, c, d, e, f, g, h, i = m
    co0, co1, co2 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * co0 + b * co1 + c * co2
    return [
        co0 / det,
        (c * h - b * i) / det,
        (b * f - c * e) / det,
        co1 / det,
        (a * i - c * g) / det,
        (c * d - a * f) / det,
        co2 / det,
        (b * g - a * h) / det,
        (a * e - b * d) / det,
    ]


def _numerical_terms(z: list[float], x: list[float], y: list[float]) -> tuple[np.ndarray, list[float]]:
    """(q, H^-1) of :func:`numerical_jacobian_single`: q (6, 8) the sums sum_i p_i x dV_i (rows
    0-2) and sum_i dV_i (rows 3-5) over the normalised corners, H^-1 (9 floats) the inverse of the
    Kabsch matrix, so that d omega = H^-1 q[:3] and dt = q[3:] / 4."""
    vx = [z[i] * x[i] for i in range(4)]
    vy = [z[i] * y[i] for i in range(4)]
    m = [0.0] * 72  # row k: [Jz | Jn] of pair k (6 x 12, row-major), two nonzeros in each part
    for k, (i, j) in enumerate(PAIRS):
        dx, dy, dz = vx[i] - vx[j], vy[i] - vy[j], z[i] - z[j]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        ex, ey, ez = dx / norm, dy / norm, dz / norm
        row = 12 * k
        m[row + i] = ex * x[i] + ey * y[i] + ez
        m[row + j] = -(ex * x[j] + ey * y[j] + ez)
        # Jn's row k: (ex z_i, ey z_i) at corner i, (-ex z_j, -ey z_j) at corner j.
        m[row + 4 + 2 * i], m[row + 5 + 2 * i] = ex * z[i], ey * z[i]
        m[row + 4 + 2 * j], m[row + 5 + 2 * j] = -ex * z[j], -ey * z[j]
    mx, my, mz = sum(vx) * 0.25, sum(vy) * 0.25, sum(z) * 0.25
    arms = [(vx[i] - mx, vy[i] - my, z[i] - mz) for i in range(4)]
    # K^T: columns (p_i x m_i, m_i); S: the unit-step terms of sum_i p_i x dV_i (rows 0-2) and
    # sum_i dV_i (rows 3-5).
    kt = [0.0] * 24  # row-major 6 x 4
    s = [0.0] * 48  # row-major 6 x 8
    for i, (px, py, pz) in enumerate(arms):
        xi, yi, zi = x[i], y[i], z[i]
        kt[i], kt[4 + i], kt[8 + i] = py - pz * yi, pz * xi - px, px * yi - py * xi
        kt[12 + i], kt[16 + i], kt[20 + i] = xi, yi, 1.0
        u, v = 2 * i, 2 * i + 1
        s[8 + u], s[16 + u] = zi * pz, -zi * py  # z_i p_i x e_x
        s[v], s[16 + v] = -zi * pz, zi * px  # z_i p_i x e_y
        s[24 + u], s[32 + v] = zi, zi
    flat = np.array(m + kt + s)
    jm = flat[:72].reshape(6, 12)
    normal = jm[:, :4].T @ jm  # [Jz^T Jz | Jz^T Jn], 4 x 12
    w = small_solve(normal[:, :4], normal[:, 4:])  # (Jz^T Jz)^-1 Jz^T Jn
    q = flat[96:].reshape(6, 8) - flat[72:96].reshape(6, 4) @ w
    sxx = syy = szz = sxy = sxz = syz = 0.0
    for px, py, pz in arms:
        sxx += px * px
        syy += py * py
        szz += pz * pz
        sxy += px * py
        sxz += px * pz
        syz += py * pz
    h_inv = _inverse3([syy + szz, -sxy, -sxz, -sxy, sxx + szz, -syz, -sxz, -syz, sxx + syy])
    return q, h_inv


def _pose_rows(q: np.ndarray, g: list[float], d: float, euler: list[list[float]] | None) -> np.ndarray:
    """(6, 8) Jacobian with rotation rows G q[:3] and position rows d q[3:] (G: 9 floats): of
    p = (omega, t) when ``euler`` is None, else of (x, y, z mm, alpha, beta, gamma deg) with the
    Euler-rate rows E (deg/rad): rows d q[3:], then (E G) q[:3]; one matmul either way."""
    if euler is None:
        top, bottom = g, [d, 0.0, 0.0, 0.0, d, 0.0, 0.0, 0.0, d]
        t = [*top[0:3], 0.0, 0.0, 0.0, *top[3:6], 0.0, 0.0, 0.0, *top[6:9], 0.0, 0.0, 0.0]
        t += [0.0, 0.0, 0.0, *bottom[0:3], 0.0, 0.0, 0.0, *bottom[3:6], 0.0, 0.0, 0.0, *bottom[6:9]]
        return np.array(t).reshape(6, 6) @ q
    t = [0.0, 0.0, 0.0, d, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, d, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, d]
    for e0, e1, e2 in euler:  # rows of E G, then zeros for the position columns
        t += [e0 * g[k] + e1 * g[3 + k] + e2 * g[6 + k] for k in range(3)] + [0.0, 0.0, 0.0]
    return np.array(t).reshape(6, 6) @ q


_EYE9 = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]


def numerical_jacobian_single(z: list[float], x: list[float], y: list[float]) -> np.ndarray:
    """(6, 8) derivative of the numerical model's pose p = (omega, t) over the normalised corners
    at its depths z (4 floats, mm): :func:`qrfield.solvers.uncertainty.numerical_jacobian` of one
    corner set (the same implicit-function and Kabsch terms, with the sparse sums written out).

    With e_k the unit vector of pair k = (i, j) and m_i = (x_i, y_i, 1): d diff_k / d z_i = e_k . m_i,
    d diff_k / d z_j = -e_k . m_j, d diff_k / d (x_i, y_i) = z_i (e_kx, e_ky) (minus at j). Then
    w = (Jz^T Jz)^-1 Jz^T Jn (minus dz/dn, 4 x 8), dV_i/dn = z_i (unit steps at i) - m_i w_i, and
    with the centred vertices p_i: d omega = H^-1 sum_i p_i x dV_i, dt = sum_i dV_i / 4, where
    p_i x dV_i = z_i p_i x (unit step) - w_i (p_i x m_i).
    """
    q, h_inv = _numerical_terms(z, x, y)
    return _pose_rows(q, h_inv, 0.25, None)


def ippe_jacobian_single(jac: np.ndarray, camera: CameraModel) -> np.ndarray:
    """(6, 8) (J^T W J)^-1 J^T W for the rigid projection's Jacobian J (8, 6), W = diag(fx^2, fy^2, ...):
    :func:`qrfield.solvers.uncertainty.least_squares_jacobian` of one pose."""
    jtw = (jac * np.array([camera.fx**2, camera.fy**2] * 4)[:, None]).T
    return small_solve(jtw @ jac, jtw)


def pose_covariance_single(jac: np.ndarray, cov_n: np.ndarray, euler: list[list[float]]) -> np.ndarray:
    """(6, 6) covariance of (x, y, z mm, alpha, beta, gamma deg) from the Jacobian (6, 8) of
    p = (omega, t), the normalised corners' (8, 8) covariance and the Euler-rate rows (3 x 3, deg/rad)."""
    full = np.concatenate([jac[3:], np.array(euler) @ jac[:3]])
    return full @ cov_n @ full.T


def branch_chi2_many(
    projections: list[tuple[list[float], list[float], float]],
    jac: np.ndarray,
    n_obs: np.ndarray,
    info: np.ndarray,
) -> list[float]:
    """Chi-square of each branch at its own chi-square optimum (one Gauss-Newton step, predicted),
    from the branches' rigid projections (:func:`rigid_projection_single`) and their Jacobians
    stacked (k, 8, 6): :func:`qrfield.solvers.uncertainty.branch_chi2` of k poses in one batch;
    inf where a vertex is behind the camera."""
    out = [math.inf] * len(projections)
    front = [k for k, p in enumerate(projections) if p[2] > 0.0]
    if not front:
        return out
    if len(front) < len(projections):
        jac = jac[front]
    r = n_obs - np.array([projections[k][0] for k in front])  # (m, 8)
    jtw = jac.transpose(0, 2, 1) @ info  # (m, 6, 8)
    g = jtw @ r[:, :, None]  # (m, 6, 1)
    normal = jtw @ jac
    step = np.empty_like(g)
    for k in range(len(front)):  # cv2's LU per branch: less overhead than one batched np.linalg.solve
        step[k] = small_solve(normal[k], g[k])
    chi2 = ((r @ info) * r).sum(axis=1) - (g * step).sum(axis=(1, 2))
    for k, value in zip(front, chi2.tolist(), strict=True):
        out[k] = value if value > 0.0 else 0.0
    return out


def uncertainty_fields(
    poses: list[tuple[str, list[list[float]], list[float], list[float], list[float]]],
    mirrors: list[tuple[list[list[float]], list[float]] | None],
    x: list[float],
    y: list[float],
    cov16: list[float],
    camera: CameraModel,
    side: float,
) -> list[dict[str, object]]:
    """The uncertainty fields (pose_cov, position_std_mm, angles_std_deg, chi2 and, with a mirror,
    mirror_chi2 and ambiguous) of k converged poses of one corner set.

    ``poses``: per pose (method, rows of R, t mm, angles deg, depths z mm of "numerical"'s
    vertices); ``mirrors``: per pose its mirror start (rows of R, t mm) or None; x, y the corners'
    normalised coordinates; ``cov16`` their normalised covariance (:func:`normalised_cov_single`).
    """
    from qrfield.solvers.uncertainty import is_ambiguous

    sigma_n, info = block_diagonal(cov16 + information_blocks(cov16))  # Sigma_n and its inverse W
    n_obs = np.array([x[0], y[0], x[1], y[1], x[2], y[2], x[3], y[3]])
    projections = []
    slots = []  # per pose: (index of its branch, index of its mirror's or None)
    for (_, rows, t, _, _), mirror in zip(poses, mirrors, strict=True):
        slots.append((len(projections), None if mirror is None else len(projections) + 1))
        projections.append(rigid_projection_single(rows, t, side))
        if mirror is not None:
            projections.append(rigid_projection_single(mirror[0], mirror[1], side))
    jac_flat: list[float] = []
    for p in projections:
        jac_flat += p[1]
    jac = np.array(jac_flat).reshape(len(projections), 8, 6)
    chi2 = branch_chi2_many(projections, jac, n_obs, info)
    out = []
    for (_, _, _, angles, z), (own, other) in zip(poses, slots, strict=True):
        euler = euler_rows(angles[0], angles[1])
        if z is not None:  # a depth model (the numerical one): through its depths
            full = _pose_rows(*_numerical_terms(z, x, y), 0.25, euler)
        else:
            full = _pose_rows(ippe_jacobian_single(jac[own], camera), _EYE9, 1.0, euler)
        pose_cov = full @ sigma_n @ full.T
        std = np.sqrt(np.maximum(pose_cov.diagonal(), 0.0))
        fields: dict[str, object] = {
            "pose_cov": pose_cov,
            "position_std_mm": std[:3],
            "angles_std_deg": std[3:],
            "chi2": chi2[own],
        }
        if other is not None:
            fields["mirror_chi2"] = chi2[other]
            fields["ambiguous"] = is_ambiguous(chi2[own], chi2[other])
        out.append(fields)
    return out
