"""Rigid transforms for hand-eye work: 4x4 matrices, unit quaternions, rotation vectors.

A transform ``T_a_b`` is a (4, 4) row-major homogeneous matrix in mm that maps coordinates in frame
b into frame a: ``p_a = T_a_b @ [p_b, 1]``, so ``T_a_c = T_a_b @ T_b_c``. A code's pose (marker to
camera, docs/conventions.md) is ``T_camera_marker``. Quaternions are (qw, qx, qy, qz), unit norm,
Hamilton convention (the rotation of a vector v is q v q*), as robot controllers give the tool's
orientation. Rotation vectors are axis * angle in radians (the exponential map). Every function
takes a leading batch shape (...) and keeps it.
"""

from __future__ import annotations

import numpy as np

from qrfield.geometry import angles_from_rotation, rotation_matrix

#: A quaternion whose norm differs from 1 by more than this is refused (a typo, not rounding):
#: controllers print 4-6 decimals, so a unit quaternion's norm is within 1e-4 of 1.
QUATERNION_NORM_TOLERANCE = 1e-3


def _array(value: np.ndarray, tail: tuple[int, ...], what: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape[a.ndim - len(tail) :] != tail:
        raise ValueError(f"{what} must have shape (..., {', '.join(map(str, tail))}), got {a.shape}")
    return a


def make_transform(rotation: np.ndarray, translation_mm: np.ndarray) -> np.ndarray:
    """(..., 4, 4) from R (..., 3, 3) and t (..., 3) in mm."""
    r = _array(rotation, (3, 3), "rotation")
    t = _array(translation_mm, (3,), "translation")
    shape = np.broadcast_shapes(r.shape[:-2], t.shape[:-1])
    out = np.zeros((*shape, 4, 4))
    out[..., :3, :3] = r
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def check_transform(transform: np.ndarray, what: str = "transform", tolerance: float = 1e-6) -> np.ndarray:
    """``transform`` as a float (..., 4, 4) rigid transform; ValueError naming ``what`` if its shape,
    its last row or its rotation part (orthonormal, determinant +1, within ``tolerance``) is wrong."""
    t = _array(transform, (4, 4), what)
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{what} must be finite")
    if np.abs(t[..., 3, :] - [0.0, 0.0, 0.0, 1.0]).max() > tolerance:
        raise ValueError(f"{what}: the last row must be 0 0 0 1, got {np.round(t[..., 3, :], 6).tolist()}")
    r = t[..., :3, :3]
    gram = np.einsum("...ji,...jk->...ik", r, r)
    if np.abs(gram - np.eye(3)).max() > tolerance or np.any(np.linalg.det(r) < 0):
        raise ValueError(f"{what}: the upper-left 3x3 is not a rotation (orthonormal, determinant +1)")
    return t


def invert(transform: np.ndarray) -> np.ndarray:
    """The inverse of a rigid transform (..., 4, 4): [R^T, -R^T t]."""
    t = _array(transform, (4, 4), "transform")
    rt = np.swapaxes(t[..., :3, :3], -1, -2)
    return make_transform(rt, -np.einsum("...ij,...j->...i", rt, t[..., :3, 3]))


def rotation_from_quaternion(quaternion: np.ndarray, where: str = "quaternion") -> np.ndarray:
    """R (..., 3, 3) of unit quaternions (..., 4) (qw, qx, qy, qz); ValueError naming ``where`` for a
    quaternion whose norm is not 1 within QUATERNION_NORM_TOLERANCE (it is normalised otherwise)."""
    q = _array(quaternion, (4,), where)
    norm = np.linalg.norm(q, axis=-1)
    if not np.all(np.isfinite(q)) or np.any(np.abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE):
        shown = np.round(np.atleast_1d(norm), 6).tolist()
        raise ValueError(
            f"{where}: (qw, qx, qy, qz) must be a unit quaternion (norm 1 within "
            f"{QUATERNION_NORM_TOLERANCE:g}), its norm is {shown[0] if len(shown) == 1 else shown}"
        )
    w, x, y, z = np.moveaxis(q / norm[..., None], -1, 0)
    r = np.empty((*q.shape[:-1], 3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - z * w)
    r[..., 0, 2] = 2 * (x * z + y * w)
    r[..., 1, 0] = 2 * (x * y + z * w)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - x * w)
    r[..., 2, 0] = 2 * (x * z - y * w)
    r[..., 2, 1] = 2 * (y * z + x * w)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def quaternion_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) (qw, qx, qy, qz), qw >= 0, of rotations (..., 3, 3).

    From the largest of the four squared components (Shepperd's method), so it is exact at every
    angle, 180 degrees included.
    """
    r = _array(rotation, (3, 3), "rotation")
    trace = r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2]
    # 4 q_k^2 - 1 for k = w, x, y, z.
    squares = np.stack(
        [trace, 2 * r[..., 0, 0] - trace, 2 * r[..., 1, 1] - trace, 2 * r[..., 2, 2] - trace], axis=-1
    )
    k = np.argmax(squares, axis=-1)
    big = np.sqrt(np.maximum(np.take_along_axis(squares, k[..., None], -1)[..., 0] + 1.0, 0.0)) / 2.0
    s = 1.0 / (4.0 * big)
    wx, wy, wz = r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]
    xy, xz, yz = r[..., 0, 1] + r[..., 1, 0], r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1]
    candidates = np.stack(
        [
            np.stack([big, wx * s, wy * s, wz * s], -1),
            np.stack([wx * s, big, xy * s, xz * s], -1),
            np.stack([wy * s, xy * s, big, yz * s], -1),
            np.stack([wz * s, xz * s, yz * s, big], -1),
        ],
        axis=-2,
    )
    q = np.take_along_axis(candidates, k[..., None, None], -2)[..., 0, :]
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def rotation_exp(vector_rad: np.ndarray) -> np.ndarray:
    """R (..., 3, 3) of rotation vectors (..., 3) (axis * angle, radians): Rodrigues' formula."""
    v = _array(vector_rad, (3,), "rotation vector")
    angle = np.linalg.norm(v, axis=-1)
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    # sin(a)/a and (1 - cos a)/a^2, with their series below 1e-8 rad.
    a = np.where(small, 1.0 - angle**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    k = skew(v)
    return np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def rotation_log(rotation: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) (axis * angle, radians, angle in [0, pi]) of rotations (..., 3, 3),
    through the quaternion, so exact near 0 and near 180 degrees."""
    q = quaternion_from_rotation(rotation)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(s, q[..., 0])
    scale = np.where(s < 1e-12, 2.0, angle / np.where(s < 1e-12, 1.0, s))
    return v * scale[..., None]


def rotation_angle_deg(rotation: np.ndarray) -> np.ndarray:
    """The angle (...,) in degrees of rotations (..., 3, 3), in [0, 180]."""
    return np.degrees(np.linalg.norm(rotation_log(rotation), axis=-1))


def skew(vector: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrices [v]x of vectors (..., 3): [v]x w = v x w."""
    v = _array(vector, (3,), "vector")
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def transform_from_pose(position_mm: np.ndarray, angles_deg: np.ndarray) -> np.ndarray:
    """T_camera_marker (..., 4, 4) of a pose: position (..., 3) mm and alpha, beta, gamma (..., 3)
    in degrees, R = Rx(alpha) Ry(beta) Rz(gamma) (docs/conventions.md)."""
    return make_transform(rotation_matrix(angles_deg), position_mm)


def pose_from_transform(transform: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position (..., 3) mm, angles (..., 3) deg) of T (..., 4, 4): the inverse of transform_from_pose."""
    t = _array(transform, (4, 4), "transform")
    return t[..., :3, 3].copy(), angles_from_rotation(t[..., :3, :3])


def transform_from_quaternion(
    position_mm: np.ndarray, quaternion: np.ndarray, where: str = "tool pose"
) -> np.ndarray:
    """T (..., 4, 4) of a position (..., 3) mm and a unit quaternion (..., 4) (qw, qx, qy, qz)."""
    return make_transform(rotation_from_quaternion(quaternion, where), _array(position_mm, (3,), where))


def perturbed(transform: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """T with a small change ``delta`` (..., 6) = (dt mm, dtheta rad) in the frame T maps into:
    R' = exp(dtheta) R, t' = t + dt (the parametrisation of every covariance in qrfield.handeye)."""
    t = _array(transform, (4, 4), "transform")
    d = _array(delta, (6,), "delta")
    return make_transform(rotation_exp(d[..., 3:]) @ t[..., :3, :3], t[..., :3, 3] + d[..., :3])


def difference(estimate: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(..., 6) = (dt mm, dtheta rad) with ``estimate = perturbed(reference, delta)``: the error of
    ``estimate`` in the parametrisation of :func:`perturbed`."""
    e = _array(estimate, (4, 4), "estimate")
    r = _array(reference, (4, 4), "reference")
    rot = e[..., :3, :3] @ np.swapaxes(r[..., :3, :3], -1, -2)
    return np.concatenate([e[..., :3, 3] - r[..., :3, 3], rotation_log(rot)], axis=-1)
