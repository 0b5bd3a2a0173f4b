"""Closed-form square pose by OpenCV's IPPE_SQUARE, both candidates kept, refined, ranked.

cv2.solvePnPGeneric with SOLVEPNP_IPPE_SQUARE returns the two poses of the planar ambiguity
(Collins and Bartoli 2014) for the object points of :func:`qrfield.geometry.ippe_object_points`
(V1..V4 in OpenCV's frame: +Y up, +Z towards the camera); both are refined (LM or VVS) and
converted to the marker frame of docs/conventions.md with :func:`qrfield.geometry.rotation_from_ippe`. The
one with the smaller reprojection error is the answer, the other its ``alternative``, and
``ambiguity`` = best error / second error (near 1: the image cannot tell the two apart; the same
definition as the numerical model's, see :class:`PoseResult`). When
refining the second candidate slides it towards the answer (it ends nearer the answer than its own
closed form: no local minimum of its own), the alternative is IPPE's unrefined closed-form mirror,
so that the two are always the two branches of the ambiguity.
Corners are undistorted first (exactly, by iteration) when the camera has distortion, so the
solver works on ideal pinhole pixels; reprojection errors are measured on the corners as given.

A candidate behind the camera or facing away from it is no pose of a visible card and is dropped.
OpenCV 5.0's IPPE returns wrong poses whenever a candidate's rotation in its frame is a turn of
exactly 180 degrees (its rotation-vector conversion divides by sin(pi)). Because OpenCV's frame is
ours turned 180 degrees about X, that is the case for the poses people set up on purpose: a card
square-on (both candidates flipped, 70 px error; refined, 33 m behind the camera), tilted about one
axis only (beta alone: 3.3 px error, 8 degrees off, and LM refinement stays there) or turned in
its plane only. So the numerical model's closed-form parallelogram pose (exact for exact corners)
is a third start: refined and kept whenever it reprojects better than IPPE's best refined
candidate, which costs one pure-Python closed form per solve and one extra refinement only then.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import ippe_object_points, rotation_from_ippe, rotation_to_ippe
from qrfield.lens import has_distortion
from qrfield.methods import IPPE
from qrfield.settings import setting, validated
from qrfield.solvers.floats import angles_single, reprojection_single
from qrfield.solvers.rays import normalised_single
from qrfield.solvers.result import BatchResult, PoseResult, SolverError
from qrfield.solvers.uncertainty import ambiguity_ratio, batch_uncertainty

REFINERS = ("lm", "vvs", "none")
#: A lone IPPE candidate this close (card normals, degrees) to the closed-form start's pose is
#: taken as the same branch of the ambiguity.
SAME_BRANCH_DEG = 2.0


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


@functools.cache
def _closed_form_settings():
    """The closed-form start: the parallelogram guess and one update, no mirror search."""
    from qrfield.solvers.numerical import NumericalSettings

    return NumericalSettings(n_max=1, mirror=False, initial_guess="parallelogram")


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


def _ideal_pixels(
    corners: np.ndarray, camera: CameraModel, xy: tuple[list[float], list[float]]
) -> np.ndarray:
    """(4, 1, 2) ideal (undistorted) pixels of the corners from their normalised coordinates."""
    if not has_distortion(camera):
        return np.ascontiguousarray(corners.reshape(4, 1, 2))
    x, y = xy
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    return np.array([[[fx * x[i] + cx, fy * y[i] + cy]] for i in range(4)])


class _Candidate:
    """One IPPE pose in the marker frame of docs/conventions.md, as Python floats (cheap on 4 points)."""

    __slots__ = ("error", "position", "residual", "rows", "vertices")

    def __init__(
        self,
        rvec: np.ndarray,
        tvec: np.ndarray,
        side: float,
        camera: CameraModel,
        flat: list[float],
        rays: list[tuple[float, float, float]],
    ) -> None:
        import cv2

        # OpenCV's IPPE frame has +Y up and +Z towards the camera: convert to our marker frame.
        self.rows = rotation_from_ippe(cv2.Rodrigues(rvec)[0]).tolist()
        (a, b, _), (d, e, _), (g, h, _) = self.rows
        self.position = tvec.reshape(3).tolist()
        self.error = reprojection_single(self.rows, self.position, side, camera, flat)
        half = side / 2.0
        tx, ty, tz = self.position
        self.vertices = []
        residual = 0.0
        corners = ((-half, -half), (half, -half), (half, half), (-half, half))
        for (qx, qy), (rx, ry, rz) in zip(corners, rays, strict=True):
            vx = a * qx + b * qy + tx
            vy = d * qx + e * qy + ty
            vz = g * qx + h * qy + tz
            self.vertices.append([vx, vy, vz])
            # Distance of the vertex from the line of sight through its (undistorted) corner.
            along = vx * rx + vy * ry + vz * rz
            ox, oy, oz = vx - along * rx, vy - along * ry, vz - along * rz
            residual = max(residual, math.sqrt(ox * ox + oy * oy + oz * oz))
        self.residual = residual

    def visible(self) -> bool:
        """In front of the camera with its printed face turned towards it."""
        facing = sum(self.rows[k][2] * self.position[k] for k in range(3)) > 0.0
        return facing and all(v[2] > 0.0 for v in self.vertices) and math.isfinite(self.error)

    def result(
        self, corners: np.ndarray, alternative: PoseResult | None = None, ambiguity: float | None = None
    ) -> PoseResult:
        return PoseResult(
            method=IPPE,
            position_mm=np.array(self.position),
            angles_deg=np.array(angles_single(self.rows)),
            rotation=np.array(self.rows),
            vertices_mm=np.array(self.vertices),
            converged=True,
            iterations=0,
            residual_mm=self.residual,
            reprojection_px=self.error,
            reason="",
            corners_px=corners,
            alternative=alternative,
            ambiguity=ambiguity,
        )


def _unit_rays(x: list[float], y: list[float]) -> list[tuple[float, float, float]]:
    """Unit vectors along the lines of sight of normalised image points."""
    out = []
    for xi, yi in zip(x, y, strict=True):
        norm = math.sqrt(xi * xi + yi * yi + 1.0)
        out.append((xi / norm, yi / norm, 1.0 / norm))
    return out


def _normal_angle(a: _Candidate, b: _Candidate) -> float:
    """Angle between the card normals of two candidates, degrees."""
    dot = a.rows[0][2] * b.rows[0][2] + a.rows[1][2] * b.rows[1][2] + a.rows[2][2] * b.rows[2][2]
    return math.degrees(math.acos(min(1.0, max(-1.0, dot))))


def solve_ippe(
    corners: np.ndarray,
    flat: list[float],
    camera: CameraModel,
    side: float,
    settings: IppeSettings | None,
    xy: tuple[list[float], list[float]] | None = None,
) -> PoseResult:
    """One pose by IPPE_SQUARE from checked corners (see :func:`qrfield.solvers.solve`); never
    raises. ``xy``: their normalised coordinates (qrfield.solvers.rays.normalised_single) when known."""
    import cv2  # lazily: the CLI imports this module for its settings

    s = checked_settings(settings)
    obj = _object_points(side)
    xy = xy if xy is not None else normalised_single(corners, flat, camera)
    pts = _ideal_pixels(corners, camera, xy)
    k = camera.K
    try:
        count, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, pts, k, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    except cv2.error as exc:
        return PoseResult.failed(IPPE, corners, f"OpenCV IPPE_SQUARE failed: {exc.err}")
    if count < 1:
        return PoseResult.failed(IPPE, corners, "OpenCV IPPE_SQUARE returned no pose")
    rays = _unit_rays(*xy)
    starts = list(zip(rvecs[:count], tvecs[:count], strict=True))
    candidates = _refined_candidates(starts, obj, pts, k, s, side, camera, flat, rays)
    closed = _closed_form(corners, flat, camera, side, xy)
    best_error = min((c[0].error for c in candidates), default=math.inf)
    if closed is not None and closed.reprojection_px < best_error:
        start = (cv2.Rodrigues(rotation_to_ippe(closed.rotation))[0], closed.position_mm.reshape(3, 1).copy())
        extra = _refined_candidates([start], obj, pts, k, s, side, camera, flat, rays)
        if extra:
            candidates = extra + _other_branch(candidates, extra[0][0])
    if not candidates:
        return PoseResult.failed(
            IPPE, corners, "OpenCV IPPE_SQUARE found no pose in front of the camera facing it"
        )
    candidates.sort(key=lambda c: c[0].error)
    first = candidates[0][0]
    if len(candidates) < 2:
        return first.result(corners)
    # The mirror branch starts at the closed form farthest from the answer (its own refinement may
    # have slid onto the answer's branch, and then it sorts anywhere).
    starts = [(c, _Candidate(c[1], c[2], side, camera, flat, rays)) for c in candidates]
    entry, raw = max(starts, key=lambda pair: _normal_angle(pair[1], first))
    second = entry[0]
    if entry is candidates[0] or _normal_angle(second, first) < _normal_angle(second, raw):
        # Refining the mirror slid it towards the answer (no local minimum of its own near the
        # closed form; LM stops short of the answer, 0.1-2 degrees away on real frames): keep
        # the closed-form mirror, so that the ambiguity compares the two branches.
        second = raw
    ambiguity = ambiguity_ratio(first.error, second.error)
    return first.result(corners, second.result(corners), ambiguity)


def _other_branch(candidates: list, answer: _Candidate) -> list:
    """The IPPE candidates without the one on ``answer``'s side of the ambiguity (the nearer of
    two by card normal; a single one only when within SAME_BRANCH_DEG): ``answer`` replaces it.
    LM stops 0.1-2 degrees short of a minimum on real frames, so "the same pose" is not exact."""
    if len(candidates) >= 2:
        nearest = min(candidates, key=lambda c: _normal_angle(c[0], answer))
        return [c for c in candidates if c is not nearest]
    return [c for c in candidates if _normal_angle(c[0], answer) > SAME_BRANCH_DEG]


def _refined_candidates(starts, obj, pts, k, s: IppeSettings, side, camera, flat, rays) -> list:
    """Refine each (rvec, tvec) start; keep the visible ones as (candidate, raw rvec, raw tvec)."""
    import cv2

    out = []
    for raw_rvec, raw_tvec in starts:
        rvec, tvec = raw_rvec.copy(), raw_tvec.copy()
        try:
            if s.refine == "lm":
                rvec, tvec = cv2.solvePnPRefineLM(obj, pts, k, None, rvec, tvec)
            elif s.refine == "vvs":
                rvec, tvec = cv2.solvePnPRefineVVS(obj, pts, k, None, rvec, tvec)
        except cv2.error:
            pass  # keep the unrefined closed-form candidate
        if np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec)):
            candidate = _Candidate(rvec, tvec, side, camera, flat, rays)
            if candidate.visible():
                out.append((candidate, raw_rvec, raw_tvec))
    return out


def _closed_form(
    corners: np.ndarray,
    flat: list[float],
    camera: CameraModel,
    side: float,
    xy: tuple[list[float], list[float]],
) -> PoseResult | None:
    """The numerical model's closed-form parallelogram pose (one update), or None if unusable."""
    from qrfield.solvers.numerical import solve_numerical

    closed = solve_numerical(corners, flat, camera, side, _closed_form_settings(), xy)
    if not (np.all(np.isfinite(closed.rotation)) and math.isfinite(closed.reprojection_px)):
        return None
    return closed


def solve_ippe_batch(
    corners: np.ndarray,
    valid: np.ndarray,
    camera: CameraModel,
    side: float,
    settings: IppeSettings | None,
    cov: np.ndarray | None = None,
) -> BatchResult:
    """N poses by IPPE (a loop over :func:`solve_ippe`; no vectorised IPPE in OpenCV).

    ``cov``: (N, 4, 2, 2) checked corner covariances (px^2) or None; propagated (vectorised) to
    the std fields after the loop.
    """
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
        r = solve_ippe(corners[i], corners[i].ravel().tolist(), camera, side, settings)
        converged[i] = r.converged
        out["position_mm"][i] = r.position_mm
        out["angles_deg"][i] = r.angles_deg
        out["rotation"][i] = r.rotation
        out["residual_mm"][i] = r.residual_mm
        out["reprojection_px"][i] = r.reprojection_px
    if cov is not None:
        out.update(
            batch_uncertainty(
                IPPE,
                corners,
                cov,
                camera,
                side,
                out["rotation"],
                out["position_mm"],
                out["angles_deg"],
                None,
                converged,
            )
        )
    return BatchResult(
        method=IPPE, converged=converged, iterations=np.zeros(count, int), valid=valid.copy(), **out
    )
