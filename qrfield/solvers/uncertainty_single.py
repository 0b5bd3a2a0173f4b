"""The uncertainty of one corner set's poses, in Python floats and a few fused numpy calls.

The same first-order propagation and mirror test as the array functions of
:mod:`qrfield.solvers.uncertainty` (which the batch path uses, and whose docstring gives the
method), written for the single solve that every video frame makes: there the array functions
spend most of their time in the overhead of about 80 numpy calls on 8 x 6 matrices. Here the
per-vertex terms are Python floats, the matrices are built once from them, and the small linear
systems go to qrfield.linalg.small_solve (cv2's LU: a quarter of np.linalg.solve's overhead here).
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
from qrfield.solvers.uncertainty import _BLOCK_DIAGONAL, distortion_terms


def block_diagonal(blocks: list[float]) -> np.ndarray:
    """(8, 8) block-diagonal matrix of the four 2x2 blocks given as 16 floats (corner, row, column)."""
    out = np.zeros(64)
    out[_BLOCK_DIAGONAL] = blocks
    return out.reshape(8, 8)


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
) -> tuple[list[float], list[list[float]], float]:
    """The rigid square at pose (rows of R, t mm): its normalised projection (8 floats x1, y1, ...),
    that projection's Jacobian (8 rows of 6: d/d(omega rad, t mm)) and its nearest vertex depth
    (mm; <= 0 makes the other two meaningless). :func:`qrfield.solvers.uncertainty.rigid_projection`
    of one pose."""
    h = side / 2.0
    (r00, r01, _), (r10, r11, _), (r20, r21, _) = rows
    tx, ty, tz = t
    proj: list[float] = []
    jac: list[list[float]] = []
    nearest = math.inf
    for qx, qy in ((-h, -h), (h, -h), (h, h), (-h, h)):
        ax, ay, az = r00 * qx + r01 * qy, r10 * qx + r11 * qy, r20 * qx + r21 * qy
        pz = az + tz
        nearest = min(nearest, pz)
        inv_z = 1.0 / pz if pz != 0.0 else math.inf
        u, v = (ax + tx) * inv_z, (ay + ty) * inv_z
        proj += [u, v]
        jac.append([-u * ay * inv_z, (az + u * ax) * inv_z, -ay * inv_z, inv_z, 0.0, -u * inv_z])
        jac.append([(-v * ay - az) * inv_z, v * ax * inv_z, ax * inv_z, 0.0, inv_z, -v * inv_z])
    return proj, jac, nearest


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
    vx = [z[i] * x[i] for i in range(4)]
    vy = [z[i] * y[i] for i in range(4)]
    a = [[0.0] * 4 for _ in range(4)]  # Jz^T Jz
    b = [[0.0] * 8 for _ in range(4)]  # Jz^T Jn
    for i, j in PAIRS:
        dx, dy, dz = vx[i] - vx[j], vy[i] - vy[j], z[i] - z[j]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        ex, ey, ez = dx / norm, dy / norm, dz / norm
        ji = ex * x[i] + ey * y[i] + ez
        jj = -(ex * x[j] + ey * y[j] + ez)
        a[i][i] += ji * ji
        a[j][j] += jj * jj
        a[i][j] += ji * jj
        a[j][i] += ji * jj
        # Jn's row k: (ex z_i, ey z_i) at corner i, (-ex z_j, -ey z_j) at corner j.
        nix, niy, njx, njy = ex * z[i], ey * z[i], -ex * z[j], -ey * z[j]
        for row, jv in ((b[i], ji), (b[j], jj)):
            row[2 * i] += jv * nix
            row[2 * i + 1] += jv * niy
            row[2 * j] += jv * njx
            row[2 * j + 1] += jv * njy
    w = small_solve(np.array(a), np.array(b))  # (4, 8)
    mx, my, mz = sum(vx) * 0.25, sum(vy) * 0.25, sum(z) * 0.25
    arms = [(vx[i] - mx, vy[i] - my, z[i] - mz) for i in range(4)]
    # K: rows (p_i x m_i, m_i); S: the unit-step terms of sum_i p_i x dV_i (rows 0-2) and sum_i dV_i (3-5).
    k_rows = []
    s_rows = [[0.0] * 8 for _ in range(6)]
    for i, (px, py, pz) in enumerate(arms):
        xi, yi, zi = x[i], y[i], z[i]
        k_rows.append([py - pz * yi, pz * xi - px, px * yi - py * xi, xi, yi, 1.0])
        u, v = 2 * i, 2 * i + 1
        s_rows[1][u], s_rows[2][u] = zi * pz, -zi * py  # z_i p_i x e_x
        s_rows[0][v], s_rows[2][v] = -zi * pz, zi * px  # z_i p_i x e_y
        s_rows[3][u], s_rows[4][v] = zi, zi
    q = np.array(s_rows) - np.array(k_rows).T @ w  # (6, 8): sum_i p_i x dV_i, then sum_i dV_i
    sxx = sum(p[0] * p[0] for p in arms)
    syy = sum(p[1] * p[1] for p in arms)
    szz = sum(p[2] * p[2] for p in arms)
    sxy = sum(p[0] * p[1] for p in arms)
    sxz = sum(p[0] * p[2] for p in arms)
    syz = sum(p[1] * p[2] for p in arms)
    h = np.array([[syy + szz, -sxy, -sxz], [-sxy, sxx + szz, -syz], [-sxz, -syz, sxx + syy]])
    out = np.empty((6, 8))
    out[:3] = small_solve(h, q[:3])
    out[3:] = 0.25 * q[3:]
    return out


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


def branch_chi2_single(
    projection: tuple[list[float], list[list[float]], float], n_obs: np.ndarray, info: np.ndarray
) -> float:
    """Chi-square of one branch at its own chi-square optimum (one Gauss-Newton step, predicted):
    :func:`qrfield.solvers.uncertainty.branch_chi2` of one pose; inf when a vertex is behind the camera."""
    proj, jac_rows, nearest = projection
    if not nearest > 0.0:
        return math.inf
    r = n_obs - np.array(proj)
    jac = np.array(jac_rows)
    jtw = jac.T @ info
    g = jtw @ r
    step = small_solve(jtw @ jac, g)
    chi2 = float(r @ info @ r) - float(g @ step)
    return max(chi2, 0.0)
