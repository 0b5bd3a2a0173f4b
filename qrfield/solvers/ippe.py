"""Closed-form square pose by OpenCV's IPPE_SQUARE, both candidates kept, refined, ranked.

cv2.solvePnPGeneric with SOLVEPNP_IPPE_SQUARE returns the two poses of the planar ambiguity
(Collins and Bartoli 2014) for the object points of :func:`qrfield.geometry.ippe_object_points`
(V1..V4 in OpenCV's frame: +Y up, +Z towards the camera); both are refined (LM or VVS) and
converted to the marker frame of DESIGN.md with :func:`qrfield.geometry.rotation_from_ippe`. The
one with the smaller reprojection error is the answer, the other its ``alternative``, and
``ambiguity`` = best error / second error (near 1: the image cannot tell the two apart). When
refining the second candidate slides it onto the answer (it is then no local minimum of its own),
the alternative is IPPE's unrefined closed-form mirror, so that the two always differ.
Corners are undistorted first (exactly, by iteration) when the camera has distortion, so the
solver works on ideal pinhole pixels; reprojection errors are measured on the corners as given.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import angles_from_rotation, ippe_object_points, marker_vertices, rotation_from_ippe
from qrfield.settings import setting, validated
from qrfield.solvers.numerical import undistort
from qrfield.solvers.result import BatchResult, PoseResult, SolverError

REFINERS = ("lm", "vvs", "none")
#: Card normals closer than this (degrees) mean the two candidates are one pose.
SAME_NORMAL_DEG = 0.01


@dataclass(frozen=True)
class IppeSettings:
    """Settings of the IPPE solver."""

    refine: str = setting(
        "lm",
        label="refinement",
        choices=REFINERS,
        help="refine both IPPE candidates by reprojection error: lm (cv2.solvePnPRefineLM), "
        "vvs (cv2.solvePnPRefineVVS) or none",
    )


@functools.lru_cache(maxsize=16)
def checked_settings(settings: IppeSettings | None) -> IppeSettings:
    if settings is None:
        return IppeSettings()
    if not isinstance(settings, IppeSettings):
        raise SolverError(f"method 'ippe' takes IppeSettings, got {type(settings).__name__}")
    return validated(settings)


@functools.lru_cache(maxsize=16)
def _object_points(side: float) -> np.ndarray:
    return np.ascontiguousarray(ippe_object_points(side).reshape(4, 1, 3))


def _ideal_pixels(corners: np.ndarray, camera: CameraModel) -> np.ndarray:
    pts = np.ascontiguousarray(corners.reshape(4, 1, 2))
    if camera.has_distortion:
        pts = undistort(pts, camera, pixels=True)
    return pts


def _candidate(
    rvec: np.ndarray, tvec: np.ndarray, side: float, camera: CameraModel, corners: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Marker-frame rotation, position, vertices, RMS reprojection (px) and line-of-sight residual (mm)."""
    import cv2

    rot_cv, _ = cv2.Rodrigues(rvec)
    rotation = rotation_from_ippe(rot_cv)
    position = tvec.reshape(3).astype(float)
    vertices = marker_vertices(side) @ rotation.T + position
    projected, _ = cv2.projectPoints(_object_points(side), rvec, tvec, camera.K, camera.dist)
    err = float(np.sqrt(np.mean(np.sum((projected.reshape(4, 2) - corners) ** 2, axis=1))))
    if np.any(vertices[:, 2] <= 0):
        err = math.inf
    # Distance of each vertex from the line of sight through its (undistorted) corner.
    rays = undistort(corners.reshape(4, 1, 2), camera).reshape(4, 2)
    rays = np.hstack([rays, np.ones((4, 1))])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    along = np.sum(vertices * rays, axis=1, keepdims=True)
    residual = float(np.max(np.linalg.norm(vertices - along * rays, axis=1)))
    return rotation, position, vertices, err, residual


def _same_normal(rot_a: np.ndarray, rot_b: np.ndarray) -> bool:
    """True when two rotations put the card normal within SAME_NORMAL_DEG of each other."""
    return float(rot_a[:, 2] @ rot_b[:, 2]) > math.cos(math.radians(SAME_NORMAL_DEG))


def _result(cand: tuple, corners: np.ndarray) -> PoseResult:  # type: ignore[type-arg]
    rotation, position, vertices, err, residual = cand
    return PoseResult(
        method="ippe",
        position_mm=position,
        angles_deg=angles_from_rotation(rotation),
        rotation=rotation,
        vertices_mm=vertices,
        converged=True,
        iterations=0,
        residual_mm=residual,
        reprojection_px=err,
        reason="",
        corners_px=corners,
    )


def solve_ippe(
    corners: np.ndarray, camera: CameraModel, side: float, settings: IppeSettings | None
) -> PoseResult:
    """One pose by IPPE_SQUARE from checked corners (see :func:`qrfield.solvers.solve`); never raises."""
    import cv2  # lazily: the CLI imports this module for its settings

    s = checked_settings(settings)
    obj = _object_points(side)
    pts = _ideal_pixels(corners, camera)
    k = camera.K
    try:
        count, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, pts, k, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    except cv2.error as exc:
        return PoseResult.failed("ippe", corners, f"OpenCV IPPE_SQUARE failed: {exc.err}")
    if count < 1:
        return PoseResult.failed("ippe", corners, "OpenCV IPPE_SQUARE returned no pose")
    candidates = []
    for raw_rvec, raw_tvec in zip(rvecs[:count], tvecs[:count], strict=True):
        rvec, tvec = raw_rvec.copy(), raw_tvec.copy()
        try:
            if s.refine == "lm":
                rvec, tvec = cv2.solvePnPRefineLM(obj, pts, k, None, rvec, tvec)
            elif s.refine == "vvs":
                rvec, tvec = cv2.solvePnPRefineVVS(obj, pts, k, None, rvec, tvec)
        except cv2.error:
            pass  # keep the unrefined closed-form candidate
        if np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec)):
            candidates.append((_candidate(rvec, tvec, side, camera, corners), raw_rvec, raw_tvec))
    if not candidates:
        return PoseResult.failed("ippe", corners, "OpenCV IPPE_SQUARE returned no finite pose")
    candidates.sort(key=lambda c: c[0][3])
    first = candidates[0][0]
    best = _result(first, corners)
    if len(candidates) < 2:
        return best
    second = candidates[1][0]
    if _same_normal(first[0], second[0]):
        # Refining the mirror slid it onto the answer (it is no local minimum of its own): keep
        # IPPE's closed-form mirror, so that the ambiguity compares two different poses.
        second = _candidate(candidates[1][1], candidates[1][2], side, camera, corners)
    alternative = _result(second, corners)
    ambiguity = first[3] / second[3] if second[3] > 0.0 else 1.0
    return replace(best, alternative=alternative, ambiguity=ambiguity)


def solve_ippe_batch(
    corners: np.ndarray, valid: np.ndarray, camera: CameraModel, side: float, settings: IppeSettings | None
) -> BatchResult:
    """N poses by IPPE (a loop over :func:`solve_ippe`; no vectorised IPPE in OpenCV)."""
    count = corners.shape[0]
    out = {
        "position_mm": np.full((count, 3), np.nan),
        "angles_deg": np.full((count, 3), np.nan),
        "rotation": np.full((count, 3, 3), np.nan),
        "residual_mm": np.full(count, np.nan),
        "reprojection_px": np.full(count, np.nan),
    }
    converged = np.zeros(count, bool)
    for i in np.flatnonzero(valid):
        r = solve_ippe(corners[i], camera, side, settings)
        converged[i] = r.converged
        out["position_mm"][i] = r.position_mm
        out["angles_deg"][i] = r.angles_deg
        out["rotation"][i] = r.rotation
        out["residual_mm"][i] = r.residual_mm
        out["reprojection_px"][i] = r.reprojection_px
    return BatchResult(
        method="ippe", converged=converged, iterations=np.zeros(count, int), valid=valid.copy(), **out
    )
