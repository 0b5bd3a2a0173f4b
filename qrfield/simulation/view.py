"""Which simulated poses the camera sees: :mod:`qrfield.visibility`'s rule for a grid of poses.

Out-of-view poses are not failures of a solver: the study leaves them out of its counts.
"""

from __future__ import annotations

import numpy as np

from qrfield.camera import CameraModel
from qrfield.visibility import view_of


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
    view = view_of(camera, side_mm, r[None, :, :, :], t[:, None, :], max_view_angle_deg)
    return view.in_view, view.corners_px
