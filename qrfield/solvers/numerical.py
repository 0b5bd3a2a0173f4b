"""The thesis' numerical positioning model (Teoh 2022), as docs/conventions.md reconstructs it.

What is the seed's (named in its abstract, symbol list and chapter 1): the four vertices as
positioning points; the pinhole model and similar triangles (vertex i lies on its line of sight,
V_i = z_i (x_i, y_i, 1)); the two known parameters f and L; "guessing parameters and updating
rules"; actual lengths L_i, calculated lengths L_i,calculated and their differences diff_i; the
tuning factor tf; the tolerance; the iteration count n and n_max = 30; the working-distance bounds
Z_w,min and Z_w,max; the orientation extracted "using the rotation matrix".

What is our reconstruction (the seed gives no equations):
  - unknowns: the four depths z_1..z_4 (mm) along the lines of sight of the undistorted corners;
  - residuals: diff = calculated minus actual length of the four sides (L) and two diagonals (L sqrt 2);
  - update: a Gauss-Newton step on the six residuals, scaled by tf (tf = 1 is the full step);
    with the settled rule (ours) the step is damped: a step that raises the misfit (the sum of
    squared diffs) is taken back and halved. Why: seen nearly square-on, the lengths change only
    to second order with the tilt, the Gauss-Newton matrix is nearly singular along it and the
    full step overshoots; undamped, it then cycles for ever (measured: 10 of 60 frames of the
    moving sequence of ``qrfield benchmark detect``, 5 of 312 hard-set views, NOCONV with every
    length within 0.005 mm), damped it creeps along that flat valley;
  - stop rule "seed" (our reading of the seed): converged as soon as max |diff_i| < tolerance;
    not converged when n reaches n_max, when the step falls below STALL_MM (a least-squares optimum
    whose residual stays above the tolerance, e.g. with noisy corners) or when the normal equations
    are singular;
  - stop rule "settled" (ours): iterate until the step falls below STALL_MM (the least-squares
    optimum of the six lengths), then converged if max |diff_i| < tolerance there; reaching n_max
    still in the flat valley above, converged if max |diff_i| < tolerance (the thesis' own test).
    With noisy corners no depths fit all six lengths exactly, so the seed rule needs a tolerance loose enough
    to stop early (and stopping early leaves the tilt inaccurate: lengths change only to second
    order with tilt); the settled rule reaches the optimum and judges it;
  - initial guess "seed": equal depths z = f L / (mean side in pixels), in normalised units so that
    fx != fy is handled, clamped to [Z_w,min, Z_w,max]; the bounds are used only for this clamp;
  - initial guess "parallelogram" (ours, not the seed's): a square's vertices satisfy
    V1 + V3 = V2 + V4, so z1 m1 - z2 m2 + z3 m3 - z4 m4 = 0 gives the depths up to scale in closed
    form; the scale is fitted to the six actual lengths. Exact for exact corners; with noise it
    starts on the right side of the planar (mirror) ambiguity. Falls back to "seed" if degenerate;
  - orientation: the least-squares rotation of the marker's points onto the solved vertices
    (X along V1->V2, Y along V1->V4, orthonormalised), position = mean of the solved vertices;
  - mirror: the plane of the solution reflected about the line of sight to its centre gives a
    second starting point; iterating from it (until its step is below MIRROR_STALL_MM) finds the
    other candidate of the planar ambiguity, reported as ``alternative`` when some depth differs
    from the answer's by more than MIRROR_DISTINCT_MM (single path only; setting ``mirror``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from qrfield.camera import CameraModel
from qrfield.methods import NUMERICAL
from qrfield.settings import setting, validated
from qrfield.solvers import kernel
from qrfield.solvers.floats import angles_single, reprojection_single
from qrfield.solvers.rays import normalised_single
from qrfield.solvers.result import PoseResult, SolverError
from qrfield.solvers.uncertainty import ambiguity_ratio

#: A Gauss-Newton step whose largest depth change is below this (mm, 0.1 micrometre) means the
#: iteration has settled at its least-squares optimum.
STALL_MM = 1e-4
#: The mirror search stops earlier: its candidate is a diagnostic, wanted to 10 micrometres in depth.
MIRROR_STALL_MM = 1e-2
#: A mirror candidate whose depths all lie within this of the answer's is the answer again (mm).
MIRROR_DISTINCT_MM = 0.1
#: The settled rule takes a step back when it raises the misfit by more than this share (float
#: rounding near the optimum is not a rise).
RISE_RTOL = 1e-12
#: Depths are kept at least this positive (mm) so that the vertices stay in front of the camera.
Z_FLOOR_MM = 1e-3
GUESSES = ("seed", "parallelogram")
STOP_RULES = ("seed", "settled")

# Status codes of one solve (the batch path keeps them per row).
CONVERGED, N_MAX, STALLED, SINGULAR, DIVERGED, INVALID = range(6)


@dataclass(frozen=True)
class NumericalSettings:
    """Settings of the numerical model; each help text names the seed's symbol where it has one.

    The defaults are for measuring real images: our parallelogram guess and settled stop rule with
    a 1 mm tolerance. :data:`SEED_SETTINGS` is the thesis' model as docs/conventions.md reads it (seed guess,
    seed stop rule, 0.01 mm) for reproducing its simulation.
    """

    tf: float = setting(
        1.0,
        label="tuning factor tf",
        minimum=0.05,
        maximum=2.0,
        help="scale of each Gauss-Newton depth update (seed: tf; 1 = full step, below 1 damps it)",
    )
    tolerance_mm: float = setting(
        1.0,
        label="tolerance",
        unit="mm",
        minimum=1e-9,
        maximum=100.0,
        decimals=6,
        help="converged when every side and diagonal is within this of its true length (seed: "
        "tolerance); with stop rule 'seed' use a small value such as 0.01 mm",
    )
    n_max: int = setting(
        30,
        label="n_max",
        unit="iterations",
        minimum=1,
        maximum=10000,
        help="most updates before giving up (seed: n_max = 30)",
    )
    z_min_mm: float = setting(
        100.0,
        label="Z_w,min",
        unit="mm",
        minimum=1.0,
        maximum=100000.0,
        help="nearest working distance; the seed guess is clamped to it",
    )
    z_max_mm: float = setting(
        2000.0,
        label="Z_w,max",
        unit="mm",
        minimum=1.0,
        maximum=100000.0,
        help="farthest working distance; the seed guess is clamped to it",
    )
    initial_guess: str = setting(
        "parallelogram",
        label="initial guess",
        choices=GUESSES,
        help="seed: equal depths from the apparent size (the thesis); parallelogram: closed-form "
        "depths from V1+V3 = V2+V4 (ours)",
    )
    stop: str = setting(
        "settled",
        label="stop rule",
        choices=STOP_RULES,
        help="seed: stop as soon as max |diff| < tolerance (the thesis); settled: iterate to the "
        "least-squares optimum, then test max |diff| < tolerance (ours; robust to corner noise)",
    )
    mirror: bool = setting(
        True,
        label="search the mirror solution",
        help="also iterate from the reflected plane and report the other candidate (single solves only)",
    )


#: The thesis' model as docs/conventions.md reads it: seed guess, seed stop rule, a tight tolerance.
SEED_SETTINGS = NumericalSettings(tolerance_mm=0.01, initial_guess="seed", stop="seed")


@functools.lru_cache(maxsize=64)
def checked_settings(settings: NumericalSettings | None) -> NumericalSettings:
    """Validated settings (cached: settings are frozen); SolverError when they are inconsistent."""
    if settings is None:
        settings = NumericalSettings()
    if not isinstance(settings, NumericalSettings):
        raise SolverError(f"method 'numerical' takes NumericalSettings, got {type(settings).__name__}")
    settings = validated(settings)
    if settings.z_min_mm >= settings.z_max_mm:
        raise SolverError(
            f"setting z_min_mm ({settings.z_min_mm} mm) must be below z_max_mm ({settings.z_max_mm} mm)"
        )
    return settings


def _reason(status: int, worst: float, n: int, settings: NumericalSettings) -> str:
    if status == CONVERGED:
        return ""
    if status == N_MAX:
        return (
            f"not converged within n_max = {settings.n_max} iterations (max |diff| {worst:.3g} mm, "
            f"tolerance {settings.tolerance_mm:g} mm)"
        )
    if status == STALLED:
        return (
            f"settled after {n} iterations at max |diff| {worst:.3g} mm, above the tolerance "
            f"{settings.tolerance_mm:g} mm (no depths fit all six lengths: corner noise, a wrong "
            "side length or camera model, or the mirror side of the ambiguity)"
        )
    if status == SINGULAR:
        return f"the update equations became singular after {n} iterations"
    if status == DIVERGED:
        return f"the iteration diverged (non-finite lengths) after {n} iterations"
    return "invalid corners"


# ---------------------------------------------------------------------- single path (Python floats)


def _initial_single(
    x: list[float], y: list[float], lengths: list[float], side: float, s: NumericalSettings
) -> list[float]:
    if s.initial_guess == "parallelogram":
        z_rel, det = kernel.parallelogram_depths(x, y, math.sqrt)
        if det != 0.0:
            z_rel = [v / det for v in z_rel]
            if all(v > 0.0 and math.isfinite(v) for v in z_rel):
                scale = kernel.scale_to_side(z_rel, x, y, lengths, math.sqrt)
                z = [scale * v for v in z_rel]
                if all(v > 0.0 and math.isfinite(v) for v in z):
                    return z
    z0 = side / kernel.mean_side(x, y, math.sqrt)
    z0 = min(max(z0, s.z_min_mm), s.z_max_mm)
    return [z0, z0, z0, z0]


def _larger(a: float, b: float) -> float:
    """max(a, b) for two floats (what the builtin returns, NaN included), without its generic call."""
    return b if b > a else a


def iterate_single(
    z: list[float],
    x: list[float],
    y: list[float],
    lengths: list[float],
    s: NumericalSettings,
    stall_mm: float = STALL_MM,
) -> tuple[list[float], int, int, float]:
    """The damped Gauss-Newton iteration on one corner set; returns (z, n, status, max |diff|).

    Stop rule "seed": the full step times tf every time (the thesis' reading). Stop rule
    "settled": a step that raises the misfit (the sum of squared diffs) is taken back and tried
    at half the length (see :data:`RISE_RTOL`); the length grows back by 2 up to tf after each
    step that lowers it; reaching n_max with every diff within the tolerance counts as converged.
    Each evaluation of the lengths (a step tried) counts as one iteration.
    """
    tf, tol, n_max = s.tf, s.tolerance_mm, s.n_max
    early = s.stop == "seed"
    sqrt = math.sqrt
    system = kernel.gn_system(z, x, y, lengths, sqrt)
    kept: tuple | None = None  # the settled rule's last accepted point: (z, system, misfit, worst, dz)
    scale = tf
    for n in range(n_max + 1):
        diff, diag, off, grad = system
        worst = max(abs(diff[0]), abs(diff[1]), abs(diff[2]), abs(diff[3]), abs(diff[4]), abs(diff[5]))
        if early and worst < tol:
            return z, n, CONVERGED, worst
        misfit = kernel.misfit(diff)
        rejected = kept is not None and not misfit <= kept[2] * (1.0 + RISE_RTOL)
        if rejected:
            # The step raised the misfit (or left the valid region): back, and half as far.
            z, system, misfit, worst, dz = kept  # type: ignore[misc]
            scale = 0.5 * scale
        elif not math.isfinite(worst):
            return z, n, DIVERGED, worst
        if n == n_max:
            return z, n, CONVERGED if not early and worst < tol else N_MAX, worst
        if not rejected:
            dz, singular = kernel.solve4(diag, off, grad, _larger)
            if singular:
                return z, n, SINGULAR, worst
            if not early:
                kept = (z, system, misfit, worst, dz)
                scale = min(tf, 2.0 * scale)
        s0, s1, s2, s3 = scale * dz[0], scale * dz[1], scale * dz[2], scale * dz[3]
        if max(abs(s0), abs(s1), abs(s2), abs(s3)) < stall_mm:
            return z, n, CONVERGED if worst < tol else STALLED, worst
        # max(z - step, Z_FLOOR_MM) unrolled (what max returns: the floor only when it is larger).
        z0, z1, z2, z3 = z[0] - s0, z[1] - s1, z[2] - s2, z[3] - s3
        z = [
            Z_FLOOR_MM if z0 < Z_FLOOR_MM else z0,
            Z_FLOOR_MM if z1 < Z_FLOOR_MM else z1,
            Z_FLOOR_MM if z2 < Z_FLOOR_MM else z2,
            Z_FLOOR_MM if z3 < Z_FLOOR_MM else z3,
        ]
        system = kernel.gn_system(z, x, y, lengths, sqrt)
    raise AssertionError("unreachable")  # pragma: no cover


def _result_single(
    z: list[float],
    n: int,
    status: int,
    worst: float,
    x: list[float],
    y: list[float],
    side: float,
    camera: CameraModel,
    corners: np.ndarray,
    flat: list[float],
    s: NumericalSettings,
    alternative: PoseResult | None = None,
    ambiguity: float | None = None,
    pose: tuple[list[list[float]], list[float], float] | None = None,
) -> PoseResult:
    """The PoseResult of solved depths (or a failed one when they are unusable).

    ``pose`` = (rows of R, centre, reprojection px) when already computed by :func:`_pose_single`.
    """
    if not _usable(status, z):
        return PoseResult.failed(NUMERICAL, corners, _reason(status, worst, n, s), iterations=n)
    rows, centre, reprojection = pose or _pose_single(z, x, y, side, camera, flat)
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rows
    z0, z1, z2, z3 = z
    # One array for the four pose fields (views of it): a numpy call instead of four.
    values = np.array(
        [
            *centre,
            *angles_single(rows),
            r00, r01, r02, r10, r11, r12, r20, r21, r22,
            z0 * x[0], z0 * y[0], z0, z1 * x[1], z1 * y[1], z1,
            z2 * x[2], z2 * y[2], z2, z3 * x[3], z3 * y[3], z3,
        ]
    )  # fmt: skip
    return PoseResult(
        method=NUMERICAL,
        position_mm=values[0:3],
        angles_deg=values[3:6],
        rotation=values[6:15].reshape(3, 3),
        vertices_mm=values[15:27].reshape(4, 3),
        converged=status == CONVERGED,
        iterations=n,
        residual_mm=worst,
        reprojection_px=reprojection,
        reason=_reason(status, worst, n, s),
        corners_px=corners,
        alternative=alternative,
        ambiguity=ambiguity,
    )


def _pose_single(
    z: list[float], x: list[float], y: list[float], side: float, camera: CameraModel, flat: list[float]
) -> tuple[list[list[float]], list[float], float]:
    rows, centre = kernel.pose_from_vertices(z, x, y, math.sqrt, max)
    return rows, centre, reprojection_single(rows, centre, side, camera, flat)


def _usable(status: int, z: list[float]) -> bool:
    return status not in (SINGULAR, DIVERGED) and all(math.isfinite(v) for v in z)


def _mirror_guess(
    rows: list[list[float]], centre: list[float], x: list[float], y: list[float]
) -> list[float] | None:
    """Depths on the solution's plane reflected about the line of sight to its centre (None if behind)."""
    norm = math.sqrt(centre[0] ** 2 + centre[1] ** 2 + centre[2] ** 2)
    d = [c / norm for c in centre]
    n = [rows[0][2], rows[1][2], rows[2][2]]
    nd = n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
    m = [2.0 * nd * d[k] - n[k] for k in range(3)]
    num = m[0] * centre[0] + m[1] * centre[1] + m[2] * centre[2]
    z = []
    for i in range(4):
        den = m[0] * x[i] + m[1] * y[i] + m[2]
        if den == 0.0 or num / den <= 0.0:
            return None
        z.append(num / den)
    return z


def solve_numerical(
    corners: np.ndarray,
    flat: list[float],
    camera: CameraModel,
    side: float,
    settings: NumericalSettings | None,
    xy: tuple[list[float], list[float]] | None = None,
) -> PoseResult:
    """One pose by the numerical model, from checked corners (see :func:`qrfield.solvers.solve`);
    ``xy``: their normalised coordinates (qrfield.solvers.rays.normalised_single) when known."""
    s = checked_settings(settings)
    x, y = xy if xy is not None else normalised_single(corners, flat, camera)
    lengths = kernel.lengths_for(side)
    z0 = _initial_single(x, y, lengths, side, s)
    z, n, status, worst = iterate_single(z0, x, y, lengths, s)
    if not (s.mirror and _usable(status, z)):
        return _result_single(z, n, status, worst, x, y, side, camera, corners, flat, s)
    pose = _pose_single(z, x, y, side, camera, flat)
    alternative = _mirror_candidate(z, pose, x, y, lengths, side, camera, corners, flat, s)
    ambiguity = None if alternative is None else ambiguity_ratio(pose[2], alternative.reprojection_px)
    return _result_single(
        z, n, status, worst, x, y, side, camera, corners, flat, s, alternative, ambiguity, pose
    )


def _mirror_candidate(
    z: list[float],
    pose: tuple[list[list[float]], list[float], float],
    x: list[float],
    y: list[float],
    lengths: list[float],
    side: float,
    camera: CameraModel,
    corners: np.ndarray,
    flat: list[float],
    s: NumericalSettings,
) -> PoseResult | None:
    """The other candidate of the planar ambiguity, iterated from the mirrored plane, or None."""
    guess = _mirror_guess(pose[0], pose[1], x, y)
    if guess is None:
        return None
    z_alt, n_alt, status_alt, worst_alt = iterate_single(guess, x, y, lengths, s, MIRROR_STALL_MM)
    if (
        not _usable(status_alt, z_alt)
        or max(abs(a - b) for a, b in zip(z_alt, z, strict=True)) <= MIRROR_DISTINCT_MM
    ):
        return None  # the mirror start slid back to the same pose: no second candidate
    return _result_single(z_alt, n_alt, status_alt, worst_alt, x, y, side, camera, corners, flat, s)


def reflected_pose_single(
    rows: list[list[float]], centre: list[float], x: list[float], y: list[float]
) -> tuple[list[list[float]], list[float]] | None:
    """(rows of R, t mm) of the rigid pose on the plane of the pose (``rows`` of R, ``centre`` mm)
    reflected about the line of sight to its centre (the start of the mirror search), or None when
    that plane lies behind the camera.

    The mirror test of :mod:`.uncertainty` starts from it when the search found no distinct mirror.
    """
    guess = _mirror_guess(rows, centre, x, y)
    if guess is None:
        return None
    return kernel.pose_from_vertices(guess, x, y, math.sqrt, max)
