"""When the camera sees the code: the one "in view" rule of the renderer, the simulation, the pose
sampler and the session analysis.

A pose (R, t) of the QR symbol (side L, vertices V1..V4 in the marker frame, docs/conventions.md)
is in view when

1. every vertex is in front of the camera: z > :data:`MIN_DEPTH_MM`;
2. the printed face is turned towards the camera, dot(R[:, 2], t) > 0 (marker +Z points into the
   card, so its printed side faces the optical centre), and is seen no more obliquely than
   ``max_view_angle_deg`` (the angle between the card's normal and the line of sight to its
   centre; 90 = only a card facing away is excluded);
3. every vertex lies within the lens' field of view (:func:`view_radius`): OpenCV's distortion
   polynomial folds back far off the axis, so a vertex beyond it is out of view wherever the
   model projects it;
4. every vertex projects inside the image, pixel edges included: -0.5 <= u <= W - 0.5 and
   -0.5 <= v <= H - 0.5 (OpenCV pixels, the centre of the top-left pixel is (0, 0)), or
   ``margin_px`` further inside when a caller wants room around the code.

:func:`view_of` evaluates it for any batch of poses; :func:`view_problem` says in words why one
pose is out of view.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import VERTEX_NAMES, marker_vertices, project_points, transform_points
from qrfield.lens import undistort_points

#: Vertices must be this far in front of the camera (mm).
MIN_DEPTH_MM = 1e-6


@functools.lru_cache(maxsize=16)
def view_radius(camera: CameraModel) -> float:
    """The largest normalised radius tan(off-axis angle) that the image shows; inf without distortion.

    OpenCV's 5-coefficient lens model folds back far outside the field of view: a point 67 degrees
    off the axis of a lens with k1 = -0.28 projects inside a 60-degree-wide image. A point beyond
    this radius is out of view wherever the model projects it. Taken from the exact undistortion
    of the image's border (pixel edges), with a 0.1 % margin.
    """
    if not camera.has_distortion:
        return math.inf
    w, h = camera.width, camera.height
    u, v = np.linspace(-0.5, w - 0.5, w + 1), np.linspace(-0.5, h - 0.5, h + 1)
    border = np.concatenate(
        [
            np.column_stack([u, np.full_like(u, -0.5)]),
            np.column_stack([u, np.full_like(u, h - 0.5)]),
            np.column_stack([np.full_like(v, -0.5), v]),
            np.column_stack([np.full_like(v, w - 0.5), v]),
        ]
    ).reshape(-1, 1, 2)
    ideal = undistort_points(border, camera.K, camera.dist)
    return 1.001 * float(np.hypot(ideal[..., 0], ideal[..., 1]).max())


@dataclass(frozen=True)
class View:
    """What the camera sees of a batch of poses (leading shape S, e.g. () for one pose).

    Attributes:
        in_front, in_field, in_image: (*S, 4) bool per vertex V1..V4 (rules 1, 3 and 4).
        facing: (*S,) bool, rule 2.
        corners_px: (*S, 4, 2) pixels of V1..V4 (distortion included); NaN where a vertex is not
            in front of the camera.
        vertices_mm: (*S, 4, 3) V1..V4 in the camera frame, mm.
    """

    in_front: np.ndarray
    in_field: np.ndarray
    in_image: np.ndarray
    facing: np.ndarray
    corners_px: np.ndarray
    vertices_mm: np.ndarray

    @property
    def in_view(self) -> np.ndarray:
        """(*S,) bool: every rule holds."""
        return self.facing & np.all(self.in_front & self.in_field & self.in_image, axis=-1)


def view_of(
    camera: CameraModel,
    side_mm: float,
    rotation: np.ndarray,
    position_mm: np.ndarray,
    max_view_angle_deg: float = 90.0,
    margin_px: float = 0.0,
) -> View:
    """The rule above for poses R (..., 3, 3) and t (..., 3) (mm, camera frame), broadcast together.

    ``max_view_angle_deg`` in (0, 90]; ``margin_px`` >= 0 keeps the vertices that far inside the
    image's edges.
    """
    if not 0 < max_view_angle_deg <= 90:
        raise ValueError(f"max_view_angle_deg must be in (0, 90], got {max_view_angle_deg!r}")
    if not (math.isfinite(margin_px) and margin_px >= 0):
        raise ValueError(f"margin_px must be a number of pixels >= 0, got {margin_px!r}")
    r = np.asarray(rotation, dtype=float)
    t = np.asarray(position_mm, dtype=float)
    if r.shape[-2:] != (3, 3) or t.shape[-1:] != (3,):
        raise ValueError(
            f"rotation (..., 3, 3) and position_mm (..., 3) mm expected, got {r.shape}, {t.shape}"
        )
    vertices = transform_points(r, t, marker_vertices(side_mm))  # (*S, 4, 3)
    in_front = vertices[..., 2] > MIN_DEPTH_MM
    normal = r[..., :, 2]  # marker +Z in the camera frame
    dot = np.sum(normal * t, axis=-1)
    cos_limit = math.cos(math.radians(max_view_angle_deg)) if max_view_angle_deg < 90 else 0.0
    facing = (dot > 0.0) & (dot > np.linalg.norm(t, axis=-1) * cos_limit)
    safe = np.where(in_front[..., None], vertices, np.array([0.0, 0.0, 1.0]))
    corners = project_points(safe, camera)
    corners = np.where(in_front[..., None], corners, np.nan)
    u, v = corners[..., 0], corners[..., 1]
    lo = -0.5 + margin_px
    with np.errstate(invalid="ignore"):
        in_image = (
            (u >= lo)
            & (u <= camera.width - 0.5 - margin_px)
            & (v >= lo)
            & (v <= camera.height - 0.5 - margin_px)
        )
    in_field = np.hypot(safe[..., 0] / safe[..., 2], safe[..., 1] / safe[..., 2]) <= view_radius(camera)
    return View(in_front, in_field & in_front, in_image, facing, corners, vertices)


def view_problem(
    camera: CameraModel,
    side_mm: float,
    rotation: np.ndarray,
    position_mm: np.ndarray,
    allow_partial: bool = False,
) -> str:
    """Why one pose (R (3, 3), t (3,) mm) is out of view, in words; "" when it is in view.

    ``allow_partial``: only rules 1 and 2 (a card partly outside the picture is still drawable).
    """
    view = view_of(camera, side_mm, np.asarray(rotation, float)[None], np.asarray(position_mm, float)[None])
    if not view.in_front[0].all():
        return "the card is (partly) behind the camera: every vertex needs z > 0 mm"
    if not view.facing[0]:
        return "the card faces away from the camera (its printed side is turned away)"
    if allow_partial:
        return ""
    reasons = []
    outside = [
        f"{VERTEX_NAMES[i]} at ({u:.1f}, {v:.1f})"
        for i, (u, v) in enumerate(view.corners_px[0])
        if not view.in_image[0, i]
    ]
    if outside:
        reasons.append(f"{', '.join(outside)} outside the {camera.width}x{camera.height} image")
    beyond = [
        f"{VERTEX_NAMES[i]} {math.degrees(math.atan(math.hypot(x / z, y / z))):.1f} deg off the optical axis"
        for i, (x, y, z) in enumerate(view.vertices_mm[0])
        if not view.in_field[0, i]
    ]
    if beyond:
        reasons.append(f"{', '.join(beyond)}, beyond the lens' field of view")
    return f"the code is out of view: {'; '.join(reasons)}" if reasons else ""
