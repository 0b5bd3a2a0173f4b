"""Pose geometry with the fixed conventions of docs/conventions.md.

Frames:
  - camera frame (OpenCV): origin at the optical centre, +X right, +Y down, +Z forward.
  - marker frame: origin at the centre of the QR symbol (quiet zone excluded), +X from V1 to V2,
    +Y from V1 to V4, +Z = X x Y (into the card). Vertices V1..V4 (top-left, top-right,
    bottom-right, bottom-left) are (-L/2,-L/2,0), (L/2,-L/2,0), (L/2,L/2,0), (-L/2,L/2,0).
  - OpenCV's SOLVEPNP_IPPE_SQUARE frame: same origin and X, +Y up, +Z towards the camera, i.e.
    q_ippe = diag(1, -1, -1) q_marker; its object points 0..3 are V1..V4.
Pose: p_camera = R @ q_marker + t, t = position of the QR centre in mm.
Angles in degrees: R = Rx(alpha) @ Ry(beta) @ Rz(gamma); beta in [-90, 90], alpha and gamma in
(-180, 180]; at beta = +-90 (gimbal lock) gamma is fixed to 0.
All functions accept a leading batch shape (...) and keep it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from qrfield.camera import CameraModel
from qrfield.lens import distort_normalised

#: The names of a pose's six values, in order (docs/conventions.md): the position x, y, z of the QR
#: centre in the camera frame (mm), then the angles alpha, beta, gamma of R = Rx Ry Rz (degrees).
POSITION_NAMES = ("x", "y", "z")
ANGLE_NAMES = ("alpha", "beta", "gamma")
POSE_NAMES = (*POSITION_NAMES, *ANGLE_NAMES)
#: The names of the QR symbol's vertices, in the order every (4, ...) array of corners holds them:
#: top-left, top-right, bottom-right, bottom-left as printed (docs/conventions.md).
VERTEX_NAMES = ("V1", "V2", "V3", "V4")
#: Below this distance of |R[0,2]| from 1 the extraction treats beta as +-90 (gimbal lock).
GIMBAL_EPS = 1e-9
#: Maps marker-frame coordinates to OpenCV IPPE_SQUARE coordinates and back (its own inverse).
IPPE_FLIP = np.diag([1.0, -1.0, -1.0])


def _as_angles(angles_deg: np.ndarray | list[float] | tuple[float, ...]) -> np.ndarray:
    a = np.asarray(angles_deg, dtype=float)
    if a.shape[-1:] != (3,):
        raise ValueError(f"angles must have shape (..., 3) (alpha, beta, gamma in degrees), got {a.shape}")
    return a


def _as_rotation(rotation: np.ndarray) -> np.ndarray:
    r = np.asarray(rotation, dtype=float)
    if r.shape[-2:] != (3, 3):
        raise ValueError(f"rotation must have shape (..., 3, 3), got {r.shape}")
    return r


def rotation_matrix(angles_deg: np.ndarray | list[float] | tuple[float, ...]) -> np.ndarray:
    """R = Rx(alpha) @ Ry(beta) @ Rz(gamma) from angles (..., 3) in degrees; returns (..., 3, 3)."""
    a = np.radians(_as_angles(angles_deg))
    ca, sa = np.cos(a[..., 0]), np.sin(a[..., 0])
    cb, sb = np.cos(a[..., 1]), np.sin(a[..., 1])
    cg, sg = np.cos(a[..., 2]), np.sin(a[..., 2])
    r = np.empty((*a.shape[:-1], 3, 3))
    # Multiplied out by hand so that batches of a million poses cost one pass of numpy.
    r[..., 0, 0] = cb * cg
    r[..., 0, 1] = -cb * sg
    r[..., 0, 2] = sb
    r[..., 1, 0] = ca * sg + sa * sb * cg
    r[..., 1, 1] = ca * cg - sa * sb * sg
    r[..., 1, 2] = -sa * cb
    r[..., 2, 0] = sa * sg - ca * sb * cg
    r[..., 2, 1] = sa * cg + ca * sb * sg
    r[..., 2, 2] = ca * cb
    return r


def wrap_degrees(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles in degrees to (-180, 180]."""
    wrapped = -((180.0 - np.asarray(angle, dtype=float)) % 360.0) + 180.0
    return wrapped


def angle_difference(a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
    """a - b in degrees, wrapped to (-180, 180]."""
    return wrap_degrees(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))


def angles_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """(alpha, beta, gamma) in degrees from R (..., 3, 3), the "inverted rotation matrix".

    beta = asin(R[0,2]), alpha = atan2(-R[1,2], R[2,2]), gamma = atan2(-R[0,1], R[0,0]);
    at beta = +-90 gamma is fixed to 0 and alpha = atan2(+-R[1,0], R[1,1]).
    """
    r = _as_rotation(rotation)
    s = np.clip(r[..., 0, 2], -1.0, 1.0)
    beta = np.arcsin(s)
    locked = np.abs(s) > 1.0 - GIMBAL_EPS
    alpha = np.where(
        locked,
        np.arctan2(np.sign(s) * r[..., 1, 0], r[..., 1, 1]),
        np.arctan2(-r[..., 1, 2], r[..., 2, 2]),
    )
    gamma = np.where(locked, 0.0, np.arctan2(-r[..., 0, 1], r[..., 0, 0]))
    out = np.stack([alpha, beta, gamma], axis=-1)
    out = np.degrees(out)
    out[..., 0] = wrap_degrees(out[..., 0])
    out[..., 2] = wrap_degrees(out[..., 2])
    return out


def rotation_vector(rotation: np.ndarray) -> np.ndarray:
    """(3,) rotation vector (axis times angle, radians) of one rotation matrix R (3, 3): the
    logarithm, R = exp([w]x), by OpenCV's Rodrigues (angle in [0, pi])."""
    import cv2

    r = _as_rotation(rotation)
    if r.shape != (3, 3):
        raise ValueError(f"rotation_vector takes one (3, 3) rotation, got {r.shape}")
    return cv2.Rodrigues(np.ascontiguousarray(r))[0].reshape(3)


def rotation_from_vector(vector: np.ndarray) -> np.ndarray:
    """(3, 3) rotation exp([w]x) of a rotation vector w (3,) in radians (OpenCV's Rodrigues)."""
    import cv2

    w = np.asarray(vector, dtype=float).reshape(-1)
    if w.shape != (3,) or not np.all(np.isfinite(w)):
        raise ValueError(f"a rotation vector needs 3 finite values (radians), got {vector!r}")
    return cv2.Rodrigues(w.reshape(3, 1))[0]


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle of the rotation between R_a and R_b (3, 3 each), degrees in [0, 180]: how far one
    turns from the other, whatever the axis."""
    ra, rb = _as_rotation(a), _as_rotation(b)
    if ra.shape != (3, 3) or rb.shape != (3, 3):
        raise ValueError(f"rotation_angle_deg takes two (3, 3) rotations, got {ra.shape} and {rb.shape}")
    cosine = (float(np.sum(ra * rb)) - 1.0) / 2.0  # trace(R_a^T R_b) = sum of the elementwise product
    return float(np.degrees(np.arccos(min(1.0, max(-1.0, cosine)))))


def marker_vertices(side_mm: float) -> np.ndarray:
    """(4, 3) vertices V1..V4 of a QR symbol of side L in the marker frame, mm."""
    if not np.isfinite(side_mm) or side_mm <= 0:
        raise ValueError(f"QR side must be a positive length in mm, got {side_mm!r}")
    h = side_mm / 2.0
    return np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])


def shortest_module_px(corners_px: np.ndarray, modules: int) -> float:
    """The module's size (px) along the shortest side of the quadrilateral ``corners_px`` (4, 2) px,
    V1..V4 in order, of a code of ``modules`` per side: what a code seen at a steep angle resolves."""
    corners = np.asarray(corners_px, dtype=np.float64)
    if corners.shape != (4, 2):
        raise ValueError(f"corners_px must be (4, 2) (V1..V4), got {corners.shape}")
    # In floats (every cold refinement asks twice): the same sqrt of the summed squares as
    # np.linalg.norm, NaN when any side is (as numpy's min).
    (x1, y1), (x2, y2), (x3, y3), (x4, y4) = corners.tolist()
    sides = [
        math.sqrt(dx * dx + dy * dy)
        for dx, dy in ((x2 - x1, y2 - y1), (x3 - x2, y3 - y2), (x4 - x3, y4 - y3), (x1 - x4, y1 - y4))
    ]
    shortest = math.nan if any(side != side for side in sides) else min(sides)
    return shortest / max(int(modules), 1)


def transform_points(rotation: np.ndarray, translation: np.ndarray, points: np.ndarray) -> np.ndarray:
    """p = R @ q + t for points (..., N, 3) with R (..., 3, 3), t (..., 3)."""
    r = _as_rotation(rotation)
    t = np.asarray(translation, dtype=float)
    q = np.asarray(points, dtype=float)
    if t.shape[-1:] != (3,) or q.shape[-1:] != (3,):
        raise ValueError(f"translation (..., 3) and points (..., N, 3) expected, got {t.shape} and {q.shape}")
    return np.einsum("...ij,...nj->...ni", r, q) + t[..., None, :]


def project_points(points_mm: np.ndarray, camera: CameraModel) -> np.ndarray:
    """Pixels (..., 2) of camera-frame points (..., 3) in mm, with the camera's distortion.

    Implements OpenCV's 5-coefficient model (the same numbers as cv2.projectPoints) in numpy so
    that batches project in one pass. Points must be in front of the camera (Z > 0).
    """
    p = np.asarray(points_mm, dtype=float)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points must have shape (..., 3) in mm, got {p.shape}")
    x = p[..., 0] / p[..., 2]
    y = p[..., 1] / p[..., 2]
    if camera.has_distortion:
        x, y = distort_normalised(camera.dist, x, y)
    return np.stack([camera.fx * x + camera.cx, camera.fy * y + camera.cy], axis=-1)


@dataclass(frozen=True)
class Pose:
    """Position (mm, QR centre in the camera frame) and angles (alpha, beta, gamma, degrees)."""

    position_mm: np.ndarray
    angles_deg: np.ndarray

    def __post_init__(self) -> None:
        pos = np.asarray(self.position_mm, dtype=float).reshape(-1)
        ang = np.asarray(self.angles_deg, dtype=float).reshape(-1)
        if pos.shape != (3,) or ang.shape != (3,):
            raise ValueError(
                f"a pose needs 3 position values (mm) and 3 angles (deg), got {pos.size} and {ang.size}"
            )
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(ang))):
            raise ValueError("a pose must be finite")
        object.__setattr__(self, "position_mm", pos)
        object.__setattr__(self, "angles_deg", ang)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) rotation, marker to camera."""
        return rotation_matrix(self.angles_deg)

    @classmethod
    def from_rotation(cls, rotation: np.ndarray, position_mm: np.ndarray) -> Pose:
        return cls(np.asarray(position_mm, dtype=float), angles_from_rotation(rotation))

    @classmethod
    def parse(cls, text: str, where: str = "pose") -> Pose:
        """Parse ``X,Y,Z,ALPHA,BETA,GAMMA`` (mm and degrees; commas, semicolons or spaces), each
        inside its limit (:data:`qrfield.limits.POSITION_MM`, :data:`qrfield.limits.ANGLE_DEG`);
        ValueError naming ``where`` and the value otherwise."""
        from qrfield.arguments import parse_numbers
        from qrfield.limits import ANGLE_DEG, POSITION_MM

        names = ("X", "Y", "Z", "ALPHA", "BETA", "GAMMA")
        values = parse_numbers(text, where, names=names)
        for name, value in zip(names, values, strict=True):
            (POSITION_MM if name in "XYZ" else ANGLE_DEG).check(value, f"{where}: {name}")
        return cls(values[:3], values[3:])

    def vertices_mm(self, side_mm: float) -> np.ndarray:
        """(4, 3) vertices V1..V4 in the camera frame, mm."""
        return transform_points(self.rotation, self.position_mm, marker_vertices(side_mm))

    def corners_px(self, camera: CameraModel, side_mm: float) -> np.ndarray:
        """(4, 2) pixels of V1..V4 through the camera model (distortion included)."""
        return project_points(self.vertices_mm(side_mm), camera)


def ippe_object_points(side_mm: float) -> np.ndarray:
    """(4, 3) object points in OpenCV's IPPE_SQUARE order and frame (they are V1..V4)."""
    return marker_vertices(side_mm) @ IPPE_FLIP


def rotation_from_ippe(rotation_ippe: np.ndarray) -> np.ndarray:
    """Marker-frame rotation from the rotation OpenCV returns for IPPE_SQUARE object points."""
    return _as_rotation(rotation_ippe) @ IPPE_FLIP


def rotation_to_ippe(rotation: np.ndarray) -> np.ndarray:
    """The rotation OpenCV would use for IPPE_SQUARE object points, from a marker-frame rotation."""
    return _as_rotation(rotation) @ IPPE_FLIP
