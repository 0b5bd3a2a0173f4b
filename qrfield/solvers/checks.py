"""Input checks shared by the solvers: corner sets, side length, camera.

A usable corner set is four finite pixels V1..V4 forming a convex quadrilateral that runs
clockwise on screen (image coordinates, y down), i.e. every turn e_(k-1) x e_k between successive
edges is positive. That is what any square in front of a pinhole camera projects to in the
order of docs/conventions.md (top-left, top-right, bottom-right, bottom-left; verified against rendered
views in the tests). Anything else is reported by name: NaN/inf, wrong shape, coincident or
collinear corners, a self-intersecting ("bow-tie") or concave quadrilateral, counter-clockwise order.
"""

from __future__ import annotations

import math

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import VERTEX_NAMES
from qrfield.solvers.result import SolverError

#: A turn whose |sin| is below this is treated as collinear corners (0.0057 degrees).
COLLINEAR_SIN = 1e-4

_NAMES = VERTEX_NAMES


def check_side(side_mm: float) -> float:
    """The QR side L as a float, or SolverError if it is not a positive finite length (mm)."""
    try:
        side = float(side_mm)
    except (TypeError, ValueError):
        raise SolverError(f"QR side must be a positive length in mm, got {side_mm!r}") from None
    if not math.isfinite(side) or side <= 0.0:
        raise SolverError(f"QR side must be a positive finite length in mm, got {side_mm!r}")
    return side


def check_camera(camera: object) -> CameraModel:
    """The camera model, or SolverError if it is not a :class:`CameraModel` (which has fx, fy > 0)."""
    if not isinstance(camera, CameraModel):
        raise SolverError(
            f"camera must be a qrfield.camera.CameraModel with a focal length, got {type(camera).__name__}"
        )
    return camera


def _turns(c: list[float]) -> tuple[list[float], list[float]]:
    """Turn cross products at V1..V4 and the edge lengths e_k = V(k+1) - V(k), from flat floats."""
    ex = [c[2] - c[0], c[4] - c[2], c[6] - c[4], c[0] - c[6]]
    ey = [c[3] - c[1], c[5] - c[3], c[7] - c[5], c[1] - c[7]]
    # Turn at vertex k is between incoming edge k-1 and outgoing edge k.
    cross = [ex[k - 1] * ey[k] - ey[k - 1] * ex[k] for k in range(4)]
    length = [math.hypot(ex[k], ey[k]) for k in range(4)]
    return cross, length


def _orient(a: tuple[float, float], b: tuple[float, float], p: tuple[float, float]) -> float:
    return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])


def _segments_cross(a, b, c, d) -> bool:  # type: ignore[no-untyped-def]
    return _orient(a, b, c) * _orient(a, b, d) < 0.0 and _orient(c, d, a) * _orient(c, d, b) < 0.0


def quad_problem(flat: list[float]) -> str:
    """ "" when the 8 floats (u1, v1, ..., u4, v4) are a usable corner set, else what is wrong."""
    cross, length = _turns(flat)
    if all(cross[k] > COLLINEAR_SIN * length[k - 1] * length[k] for k in range(4)):
        return ""
    pts = [(flat[2 * i], flat[2 * i + 1]) for i in range(4)]
    for i in range(4):
        for j in range(i + 1, 4):
            if math.hypot(pts[i][0] - pts[j][0], pts[i][1] - pts[j][1]) <= 1e-9 * (
                1.0 + abs(pts[i][0]) + abs(pts[i][1])
            ):
                return f"corners {_NAMES[i]} and {_NAMES[j]} coincide"
    for k in range(4):
        if abs(cross[k]) <= COLLINEAR_SIN * length[k - 1] * length[k]:
            return (
                f"corners {_NAMES[k - 1]}, {_NAMES[k]}, {_NAMES[(k + 1) % 4]} are collinear; "
                "a QR code seen edge-on has no pose"
            )
    if all(x < 0.0 for x in cross):
        return (
            "corners run counter-clockwise on screen; give them clockwise (image y down) as "
            "V1 top-left, V2 top-right, V3 bottom-right, V4 bottom-left of the code"
        )
    if _segments_cross(pts[0], pts[1], pts[2], pts[3]) or _segments_cross(pts[1], pts[2], pts[3], pts[0]):
        return "corners form a self-intersecting quadrilateral (two corners swapped?); expected order V1..V4"
    reflex = (
        [_NAMES[k] for k in range(4) if cross[k] < 0.0]
        if sum(x > 0 for x in cross) >= 2
        else [_NAMES[k] for k in range(4) if cross[k] > 0.0]
    )
    return f"corners form a concave quadrilateral (reflex at {', '.join(reflex)}); no square projects to it"


def check_corners_single(corners_px: object) -> tuple[np.ndarray, list[float]]:
    """Check one corner set; returns the (4, 2) float array and its 8 values as Python floats.

    Raises SolverError naming the problem (shape, NaN/inf, degenerate or wrongly ordered corners).
    """
    try:
        c = np.array(corners_px, dtype=float)
    except (TypeError, ValueError):
        raise SolverError(f"corners must be 4 pixel pairs (u, v) as numbers, got {corners_px!r}") from None
    if c.shape != (4, 2):
        raise SolverError(f"corners must have shape (4, 2): pixels (u, v) of V1..V4, got shape {c.shape}")
    flat = c.ravel().tolist()
    if not all(math.isfinite(v) for v in flat):
        bad = [_NAMES[i // 2] for i, v in enumerate(flat) if not math.isfinite(v)]
        raise SolverError(f"corners contain NaN or inf (at {', '.join(sorted(set(bad)))})")
    problem = quad_problem(flat)
    if problem:
        raise SolverError(problem)
    return c, flat


def check_corners_batch(corners_px: object) -> tuple[np.ndarray, np.ndarray]:
    """Check N corner sets at once; returns ((N, 4, 2) floats, (N,) bool usable).

    Raises SolverError only for a wrong overall shape; unusable rows (NaN/inf, collinear,
    concave, self-intersecting, counter-clockwise) are marked False so that a study of millions
    of poses carries on. :func:`quad_problem` says what is wrong with one row.
    """
    try:
        c = np.asarray(corners_px, dtype=float)
    except (TypeError, ValueError):
        raise SolverError("corners must be a numeric array of shape (N, 4, 2)") from None
    if c.ndim != 3 or c.shape[1:] != (4, 2):
        raise SolverError(f"batch corners must have shape (N, 4, 2): N sets of V1..V4 pixels, got {c.shape}")
    finite = np.all(np.isfinite(c), axis=(1, 2))
    e = np.roll(c, -1, axis=1) - c  # e_k = V(k+1) - V(k)
    e_prev = np.roll(e, 1, axis=1)
    with np.errstate(invalid="ignore"):
        cross = e_prev[..., 0] * e[..., 1] - e_prev[..., 1] * e[..., 0]
        length = np.hypot(e[..., 0], e[..., 1])
        ok = np.all(cross > COLLINEAR_SIN * np.roll(length, 1, axis=1) * length, axis=1)
    return c, finite & ok
