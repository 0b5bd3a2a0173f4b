"""The numerical model on N corner sets at once, vectorised in numpy (see :mod:`.numerical`).

Row by row the same arithmetic as the single path (the shared :mod:`.kernel`), so depths and
iteration counts are bit-identical; angles and reprojection errors agree to float rounding.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import angles_from_rotation, marker_vertices, project_points
from qrfield.methods import NUMERICAL
from qrfield.solvers import kernel
from qrfield.solvers.numerical import (
    CONVERGED,
    DIVERGED,
    INVALID,
    N_MAX,
    RISE_RTOL,
    SINGULAR,
    STALL_MM,
    STALLED,
    Z_FLOOR_MM,
    NumericalSettings,
    checked_settings,
)
from qrfield.solvers.rays import normalised_batch
from qrfield.solvers.result import BatchResult
from qrfield.solvers.uncertainty import batch_uncertainty


def _initial_batch(
    x: list[np.ndarray], y: list[np.ndarray], lengths: list[float], side: float, s: NumericalSettings
) -> list[np.ndarray]:
    z0 = side / kernel.mean_side(x, y, np.sqrt)
    z0 = np.minimum(np.maximum(z0, s.z_min_mm), s.z_max_mm)
    z = [z0.copy() for _ in range(4)]
    if s.initial_guess != "parallelogram":
        return z
    z_rel, det = kernel.parallelogram_depths(x, y, np.sqrt)
    ok = det != 0.0
    safe = np.where(ok, det, 1.0)
    z_rel = [v / safe for v in z_rel]
    for v in z_rel:
        ok &= (v > 0.0) & np.isfinite(v)
    if not ok.any():
        return z
    idx = np.flatnonzero(ok)
    sub = [v[idx] for v in z_rel]
    scale = kernel.scale_to_side(sub, [v[idx] for v in x], [v[idx] for v in y], lengths, np.sqrt)
    zs = [scale * v for v in sub]
    good = np.ones(idx.size, bool)
    for v in zs:
        good &= (v > 0.0) & np.isfinite(v)
    for k in range(4):
        z[k][idx[good]] = zs[k][good]
    return z


def _where(mask: np.ndarray, a: list[np.ndarray], b: list[np.ndarray]) -> list[np.ndarray]:
    """Item by item, a where ``mask`` else b (rows of the lists of arrays of the kernel)."""
    return [np.where(mask, x, y) for x, y in zip(a, b, strict=True)]


#: Rows solved per pass: small enough that numpy's temporaries stay in the CPU cache.
BATCH_CHUNK = 16384


def solve_numerical_batch(
    corners: np.ndarray,
    valid: np.ndarray,
    camera: CameraModel,
    side: float,
    settings: NumericalSettings | None,
    cov: np.ndarray | None = None,
) -> BatchResult:
    """N poses by the numerical model at once; rows identical to :func:`solve_numerical` (no mirror).

    ``cov``: (N, 4, 2, 2) checked corner covariances (px^2) or None; propagated to the std fields.
    """
    s = checked_settings(settings)
    if corners.shape[0] <= BATCH_CHUNK:
        return _solve_chunk(corners, valid, camera, side, s, cov)
    parts = [
        _solve_chunk(
            corners[i : i + BATCH_CHUNK],
            valid[i : i + BATCH_CHUNK],
            camera,
            side,
            s,
            None if cov is None else cov[i : i + BATCH_CHUNK],
        )
        for i in range(0, corners.shape[0], BATCH_CHUNK)
    ]
    return BatchResult(
        method=NUMERICAL,
        **{
            name: np.concatenate([getattr(p, name) for p in parts])
            for name in (
                "position_mm",
                "angles_deg",
                "rotation",
                "converged",
                "iterations",
                "residual_mm",
                "reprojection_px",
                "valid",
                "corners_std_px",
                "position_std_mm",
                "angles_std_deg",
            )
        },
    )


def _solve_chunk(
    corners: np.ndarray,
    valid: np.ndarray,
    camera: CameraModel,
    side: float,
    s: NumericalSettings,
    cov: np.ndarray | None,
) -> BatchResult:
    count = corners.shape[0]
    lengths = kernel.lengths_for(side)
    xn, yn = normalised_batch(np.where(valid[:, None, None], corners, 0.0), camera)
    x_all = [xn[:, k].copy() for k in range(4)]
    y_all = [yn[:, k].copy() for k in range(4)]
    z_out = np.full((count, 4), np.nan)
    n_out = np.zeros(count, dtype=int)
    status = np.full(count, INVALID, dtype=int)
    worst_out = np.full(count, np.nan)

    idx = np.flatnonzero(valid)
    x = [v[idx] for v in x_all]
    y = [v[idx] for v in y_all]
    z = _initial_batch(x, y, lengths, side, s)
    tf, tol = s.tf, s.tolerance_mm
    early = s.stop == "seed"

    def finish(mask: np.ndarray, code: int, n: int, worst: np.ndarray) -> None:
        if not mask.any():
            return
        rows = idx[mask]
        z_out[rows] = np.stack([v[mask] for v in z], axis=1)
        n_out[rows] = n
        status[rows] = code
        worst_out[rows] = worst[mask]

    with np.errstate(all="ignore"):
        system = kernel.gn_system(z, x, y, lengths, np.sqrt)
        # The settled rule's last accepted point per row (see iterate_single): z, the system, the
        # misfit, max |diff|, the update; and the step's length (a share of the update).
        kept_z, kept_system, kept_misfit, kept_worst, dz = None, None, None, None, None
        has_kept = np.zeros(idx.size, bool)
        scale = np.full(idx.size, float(tf))
        for n in range(s.n_max + 1):
            if idx.size == 0:
                break
            diff = system[0]
            worst = np.abs(diff[0])
            for k in range(1, 6):
                worst = np.maximum(worst, np.abs(diff[k]))
            done = np.zeros(idx.size, bool)
            if early:
                conv = worst < tol
                finish(conv, CONVERGED, n, worst)
                done |= conv
            misfit = kernel.misfit(diff)
            if early or kept_misfit is None:
                rejected = np.zeros(idx.size, bool)
            else:
                rejected = has_kept & ~(misfit <= kept_misfit * (1.0 + RISE_RTOL))
            if rejected.any():
                # The step raised the misfit: back to the last accepted point, half as far.
                z = _where(rejected, kept_z, z)
                system = tuple(_where(rejected, a, b) for a, b in zip(kept_system, system, strict=True))
                misfit = np.where(rejected, kept_misfit, misfit)
                worst = np.where(rejected, kept_worst, worst)
                scale = np.where(rejected, 0.5 * scale, scale)
            diff, diag, off, grad = system
            bad = ~done & ~rejected & ~np.isfinite(worst)
            finish(bad, DIVERGED, n, worst)
            done |= bad
            if n == s.n_max:
                conv = ~done & (worst < tol) if not early else np.zeros(idx.size, bool)
                finish(conv, CONVERGED, n, worst)
                finish(~done & ~conv, N_MAX, n, worst)
                break
            new_dz, singular = kernel.solve4(diag, off, grad, np.maximum)
            accepted = ~done & ~rejected
            sing = accepted & singular
            finish(sing, SINGULAR, n, worst)
            done |= sing
            dz = new_dz if dz is None else _where(accepted, new_dz, dz)
            if not early:
                if kept_z is None:
                    kept_z, kept_system = z, system
                    kept_misfit, kept_worst = misfit, worst
                else:
                    kept_z = _where(accepted, z, kept_z)
                    kept_system = tuple(
                        _where(accepted, a, b) for a, b in zip(system, kept_system, strict=True)
                    )
                    kept_misfit = np.where(accepted, misfit, kept_misfit)
                    kept_worst = np.where(accepted, worst, kept_worst)
                has_kept |= accepted
                scale = np.where(accepted, np.minimum(tf, 2.0 * scale), scale)
            step = [scale * v for v in dz]
            biggest = np.maximum(
                np.maximum(np.abs(step[0]), np.abs(step[1])), np.maximum(np.abs(step[2]), np.abs(step[3]))
            )
            stall = ~done & (biggest < STALL_MM)
            finish(stall & (worst < tol), CONVERGED, n, worst)
            finish(stall & ~(worst < tol), STALLED, n, worst)
            done |= stall
            keep = ~done
            if not keep.all():
                idx = idx[keep]
                x = [v[keep] for v in x]
                y = [v[keep] for v in y]
                z = [v[keep] for v in z]
                step = [v[keep] for v in step]
                dz = [v[keep] for v in dz]
                scale = scale[keep]
                has_kept = has_kept[keep]
                if kept_z is not None:
                    kept_z = [v[keep] for v in kept_z]
                    kept_system = tuple([v[keep] for v in part] for part in kept_system)
                    kept_misfit, kept_worst = kept_misfit[keep], kept_worst[keep]
            z = [np.maximum(z[k] - step[k], Z_FLOOR_MM) for k in range(4)]
            system = kernel.gn_system(z, x, y, lengths, np.sqrt)

    result = _batch_result(z_out, n_out, status, worst_out, x_all, y_all, corners, valid, camera, side)
    if cov is None:
        return result
    stds = batch_uncertainty(
        NUMERICAL,
        corners,
        cov,
        camera,
        side,
        result.rotation,
        result.position_mm,
        result.angles_deg,
        z_out,
        result.converged,
    )
    return replace(result, **stds)


def _batch_result(
    z_out: np.ndarray,
    n_out: np.ndarray,
    status: np.ndarray,
    worst: np.ndarray,
    x_all: list[np.ndarray],
    y_all: list[np.ndarray],
    corners: np.ndarray,
    valid: np.ndarray,
    camera: CameraModel,
    side: float,
) -> BatchResult:
    count = z_out.shape[0]
    has_pose = np.isin(status, (CONVERGED, N_MAX, STALLED)) & np.all(np.isfinite(z_out), axis=1)
    rotation = np.full((count, 3, 3), np.nan)
    position = np.full((count, 3), np.nan)
    angles = np.full((count, 3), np.nan)
    reproj = np.full(count, np.nan)
    idx = np.flatnonzero(has_pose)
    if idx.size:
        z = [z_out[idx, k] for k in range(4)]
        rows, centre = kernel.pose_from_vertices(
            z, [v[idx] for v in x_all], [v[idx] for v in y_all], np.sqrt, np.maximum
        )
        rot = np.empty((idx.size, 3, 3))
        for i in range(3):
            for j in range(3):
                rot[:, i, j] = rows[i][j]
        pos = np.stack(centre, axis=1)
        rotation[idx] = rot
        position[idx] = pos
        angles[idx] = angles_from_rotation(rot)
        q = marker_vertices(side)
        model = (
            pos[:, None, :]
            + rot[:, None, :, 0] * q[None, :, 0, None]
            + rot[:, None, :, 1] * q[None, :, 1, None]
        )
        with np.errstate(all="ignore"):
            projected = project_points(model, camera)
            err = np.sqrt(np.sum((projected - corners[idx]) ** 2, axis=(1, 2)) / 4.0)
        err[np.any(model[..., 2] <= 0.0, axis=1)] = np.inf
        reproj[idx] = err
    worst = np.where(has_pose | (status != INVALID), worst, np.nan)
    return BatchResult(
        method=NUMERICAL,
        position_mm=position,
        angles_deg=angles,
        rotation=rotation,
        converged=status == CONVERGED,
        iterations=n_out,
        residual_mm=worst,
        reprojection_px=reproj,
        valid=valid.copy(),
    )
