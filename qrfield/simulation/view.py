"""Which simulated poses the camera sees: the vectorised twin of :func:`qrfield.render.check_view`.

A pose (R, t) of the QR symbol (side L, vertices V1..V4 in the marker frame, docs/conventions.md) is in view
when every vertex is in front of the camera (z > 1e-6 mm), the card faces the camera
(dot(R[:, 2], t) > 0: its printed side, marker -Z, is turned towards the optical centre) and is
seen no more obliquely than ``max_view_angle_deg`` (the angle between the card's normal and the
line of sight to its centre; 90 = only facing away is excluded), and every vertex projects inside
the image (OpenCV pixels: -0.5 <= u <= W - 0.5, -0.5 <= v <= H - 0.5) from within the lens' field of
view (:func:`qrfield.render.view_radius`). Out-of-view poses are not
failures of a solver: the study leaves them out of its counts.
"""

from __future__ import annotations

import math

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import marker_vertices, project_points
from qrfield.render import view_radius

#: Vertices must be this far in front of the camera (mm), as in qrfield.render.check_view.
MIN_DEPTH_MM = 1e-6


def poses_in_view(
    camera: CameraModel,
    side_mm: float,
    rotation: np.ndarray,
    position_mm: np.ndarray,
    max_view_angle_deg: float = 90.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Visibility and exact vertex pixels of every combination of A rotations and G positions.

    Args:
        camera: the camera model (distortion included in the projection).
        side_mm: QR side L in mm.
        rotation: (A, 3, 3) marker-to-camera rotations.
        position_mm: (G, 3) QR centres in the camera frame, mm.
        max_view_angle_deg: largest angle between the card's normal and the line of sight, degrees.

    Returns:
        in_view: (G, A) bool.
        corners_px: (G, A, 4, 2) pixels of V1..V4; NaN where a vertex is not in front of the camera.
    """
    r = np.asarray(rotation, dtype=float)
    t = np.asarray(position_mm, dtype=float)
    if r.ndim != 3 or r.shape[1:] != (3, 3):
        raise ValueError(f"rotation must have shape (A, 3, 3), got {r.shape}")
    if t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(f"position_mm must have shape (G, 3) in mm, got {t.shape}")
    if not 0 < max_view_angle_deg <= 90:
        raise ValueError(f"max_view_angle_deg must be in (0, 90], got {max_view_angle_deg!r}")
    q = marker_vertices(side_mm)
    rotated = np.einsum("aij,kj->aki", r, q)  # (A, 4, 3)
    vertices = rotated[None, :, :, :] + t[:, None, None, :]  # (G, A, 4, 3)
    in_front = np.all(vertices[..., 2] > MIN_DEPTH_MM, axis=-1)
    normal = r[:, :, 2]  # (A, 3): marker +Z in the camera frame
    facing = t @ normal.T  # (G, A): dot(R[:, 2], t)
    distance = np.linalg.norm(t, axis=1)[:, None]
    cos_limit = math.cos(math.radians(max_view_angle_deg)) if max_view_angle_deg < 90 else 0.0
    faces = (facing > 0.0) & (facing > distance * cos_limit)
    safe = np.where(in_front[..., None, None], vertices, np.array([0.0, 0.0, 1.0]))
    corners = project_points(safe, camera)
    corners[~in_front] = np.nan
    u, v = corners[..., 0], corners[..., 1]
    inside = np.all(
        (u >= -0.5) & (u <= camera.width - 0.5) & (v >= -0.5) & (v <= camera.height - 0.5), axis=-1
    )
    # The lens model folds back far off the axis: a vertex beyond the field of view is out of view
    # even where it projects inside the image (see qrfield.render.view_radius).
    radius = np.hypot(safe[..., 0] / safe[..., 2], safe[..., 1] / safe[..., 2])
    inside &= np.all(radius <= view_radius(camera), axis=-1)
    return in_front & faces & inside, corners
