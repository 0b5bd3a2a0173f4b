"""Sub-pixel refinement of the four outer corners V1..V4 of a QR symbol.

Method: each side of the symbol (V1V2 top, V2V3 right, V3V4 bottom, V4V1 left) is a straight line
in the image (no lens distortion) along which the outer edges of the finder patterns and of every
dark boundary module lie. Across each side, short profiles are sampled (bilinear) at about one
pixel spacing (at most 40 per side). On each profile, coming in from the quiet zone, the first
crossing of the level halfway between the local quiet zone and the dark level of the finder cores
locates the edge to a fraction of a pixel; the edge is then placed by the area under the
normalised darkness profile in a window around that crossing (for a straight step blurred by any
symmetric kernel, and for pixels that average over their area, that area is exact, where a
threshold crossing is biased by up to 0.1 px). A line offset = c0 + c1 * along is fitted per side
by least squares with two trims: points a third of a module or more inside the median (a light
boundary module lets the profile reach the next dark module), then points beyond 3 RMS.
Corners are the intersections of neighbouring lines; V3, which has no finder pattern, comes from
the right and bottom lines, i.e. the outer edges of the top-right and bottom-left finder patterns
and of the dark boundary modules that continue them.

Backends often misplace V3 (they extrapolate it): the first pass lets V3 move by up to three
modules, a second pass refits from the corrected corners when it moved, and if the first pass
fails the finder-pattern edges alone are fitted first (then the whole sides).

Lens distortion is not modelled: through a distorted lens the sides are curves and the fitted
lines place the corners off (measured on 28 seeded views through tests/solver_cases.DISTORTED, a
wide Pi-like lens with k1 = -0.28: worst corner 0.35 px median, 1.3 px largest, against about
0.04 px for a pinhole camera). For such lenses undistort the image before detection.

Corner quality: the RMS distance in pixels of the accepted edge points to the two lines meeting at
the corner (noise and edge roughness; about 0.01-0.05 px on a rendered view with noise sigma 2,
more on blurred, noisy or distorted images). Smaller is better.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from qrfield.detect.bilinear import sample_bilinear
from qrfield.detect.patterns import module_homography, to_pixels

#: Index of the next and of the previous corner (or side), cyclically.
_NEXT = np.array([1, 2, 3, 0])
_PREVIOUS = np.array([3, 0, 1, 2])
#: Step between samples along a profile, px.
PROFILE_STEP_PX = 0.5
#: Distance beyond the search window, px, at which the quiet-zone level is read.
QUIET_OFFSET_PX = 1.5
#: Most profiles sampled across one side (about one per pixel below that).
MAX_PROFILES_PER_SIDE = 40
#: Samples integrated across each edge (over a window of 2 to 5 px).
AREA_SAMPLES = 9
#: Largest share of the contrast by which the ends of an edge window may differ from dark and light.
CLEAN_STEP = 0.12


@dataclass(frozen=True)
class EdgeLine:
    """A fitted side: ``point`` + t * ``direction`` (unit), with fit statistics (px)."""

    point: np.ndarray
    direction: np.ndarray
    rms_px: float
    inliers: int
    samples: int


@dataclass(frozen=True)
class RefineResult:
    """Outcome of :func:`refine_corners`.

    Attributes:
        ok: True when all four sides were fitted and the corners are plausible.
        corners_px: (4, 2) refined V1..V4 when ok, else the input corners.
        corner_rms_px: (4,) RMS px of the edge points of the two sides meeting at each corner (NaN if not ok).
        reason: why refinement failed, else "".
        lines: the four fitted sides (top, right, bottom, left) when ok.
    """

    ok: bool
    corners_px: np.ndarray
    corner_rms_px: np.ndarray
    reason: str = ""
    lines: tuple[EdgeLine, ...] = ()


@functools.lru_cache(maxsize=64)
def _finder_cores(n: int) -> np.ndarray:
    """Module-centre coordinates (27, 2) of the 3 x 3 dark cores of the three finder patterns."""
    core = [
        (c0 + c + 0.5, r0 + r + 0.5)
        for c0, r0 in ((0, 0), (n - 7, 0), (0, n - 7))
        for r in range(2, 5)
        for c in range(2, 5)
    ]
    out = np.array(core, dtype=np.float64)
    out.setflags(write=False)
    return out


def _dark_level(grey: np.ndarray, corners: np.ndarray, n: int) -> float:
    """Median grey level of the three finder cores (3 x 3 modules each), as seen (NaN if outside)."""
    values = sample_bilinear(grey, to_pixels(module_homography(corners, n), _finder_cores(n)))
    if np.isnan(values).any():
        return np.nan
    return float(np.sort(values)[len(values) // 2])


@functools.lru_cache(maxsize=16)
def _unit_steps(k: int) -> np.ndarray:
    """k evenly spaced values from 0 to 1 (cached: called on every frame)."""
    out = np.linspace(0.0, 1.0, k)
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=16)
def _profile_offsets(search_px: float) -> np.ndarray:
    """Offsets along the outward normal, px, from the quiet zone in to past the search window."""
    out = np.arange(search_px + QUIET_OFFSET_PX, -(search_px + 1.0) - 1e-9, -PROFILE_STEP_PX)
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=16)
def _row_starts(shape: tuple[int, int], length: int) -> np.ndarray:
    """Flat index of the first sample of each profile in a (4, k, length) array."""
    out = np.arange(shape[0] * shape[1]).reshape(shape) * length
    out.setflags(write=False)
    return out


def _as_seen(values: np.ndarray, inverted: bool) -> np.ndarray:
    """Grey levels with dark modules dark: inverted codes are flipped."""
    return 255.0 - values if inverted else values


def _masked_median(x: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Row-wise median of ``x`` (rows, k) over entries where ``mask``; NaN for an empty row."""
    n = mask.sum(axis=1)
    y = np.sort(np.where(mask, x, np.inf), axis=1)
    rows = np.arange(len(x))
    median = 0.5 * (y[rows, np.maximum((n - 1) // 2, 0)] + y[rows, np.maximum(n // 2, 0)])
    return np.where(n > 0, median, np.nan)


def _masked_ols(along: np.ndarray, offset: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row-wise least squares offset = c0 + c1 * along with weights ``w`` (0 or 1)."""
    n = np.maximum(w.sum(axis=1), 1.0)
    a_mean = (w * along).sum(axis=1) / n
    o_mean = (w * offset).sum(axis=1) / n
    da = along - a_mean[:, None]
    wda = w * da
    c1 = (wda * offset).sum(axis=1) / np.maximum((wda * da).sum(axis=1), 1e-12)
    return o_mean - c1 * a_mean, c1


def _fit_sides(
    along: np.ndarray, offset: np.ndarray, valid: np.ndarray, module_px: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Robust lines offset = c0 + c1 * along through the edge points of the four sides at once.

    Edge points are measured along each side's normal at fixed positions along it, so the error is in
    ``offset`` only and ordinary least squares is the right fit. Trimming: first drop points farther
    than a third of a module from the median (edges of the next module in), then points beyond
    3 RMS of that fit (at least 0.15 px). Inputs are (4, k); returns c0, c1, rms px, inliers (4,).
    """
    offset = np.where(valid, offset, 0.0)
    c0, c1 = _masked_ols(along, offset, valid.astype(np.float64))
    residual = offset - (c0[:, None] + c1[:, None] * along)
    deviation = np.abs(residual - _masked_median(residual, valid)[:, None])
    keep = valid & (deviation < np.maximum(0.35 * module_px, 0.5)[:, None])
    w = keep.astype(np.float64)
    c0, c1 = _masked_ols(along, offset, w)
    residual = offset - (c0[:, None] + c1[:, None] * along)
    # Second, finer trim: beyond 3 RMS (at least 0.15 px) of the first fit.
    inliers = w.sum(axis=1)
    rms = np.sqrt((w * residual**2).sum(axis=1) / np.maximum(inliers, 1))
    keep &= np.abs(residual) < np.maximum(3.0 * rms, 0.15)[:, None]
    w = keep.astype(np.float64)
    c0, c1 = _masked_ols(along, offset, w)
    residual = offset - (c0[:, None] + c1[:, None] * along)
    inliers = keep.sum(axis=1)
    rms = np.sqrt((w * residual**2).sum(axis=1) / np.maximum(inliers, 1))
    return c0, c1, rms, inliers


def refine_corners(
    grey: np.ndarray,
    corners_px: np.ndarray,
    modules: int,
    *,
    inverted: bool = False,
    search_px: float = 2.5,
    from_finders: bool = True,
) -> RefineResult:
    """Refine rough corners V1..V4 to sub-pixel accuracy by fitting the symbol's four outer edges.

    Args:
        grey: (H, W) uint8 grey image.
        corners_px: (4, 2) rough corners V1..V4 in pixels (OpenCV convention), e.g. from a backend.
        modules: modules per side of the symbol (21 for version 1).
        inverted: True for a light code on a dark background.
        search_px: how far (px) the true edges may lie from the rough sides near V1, V2, V4.
        from_finders: first fit only the outer edges of the three finder patterns and take V3 from
            the two lines that point at it (backends often misplace V3 by several px, as they
            extrapolate it), then fit the whole sides from there. False when V3 is already good
            (tracking).

    Returns:
        RefineResult; never raises for image content (ok=False and a reason instead).
    """
    corners = np.asarray(corners_px, dtype=np.float64)
    if corners.shape != (4, 2) or not np.all(np.isfinite(corners)):
        raise ValueError(f"corners must be a finite (4, 2) array of pixels V1..V4, got shape {corners.shape}")
    if modules < 21:
        raise ValueError(f"a QR symbol has at least 21 modules per side, got {modules}")
    if from_finders:
        # Usually one pass over the whole sides finds enough of the edges near V2 and V4 to place
        # V3 even when the backend missed it; only when it does not, fit the finders first.
        direct = _refine(grey, corners, modules, inverted, search_px, finders_only=False, loose_v3=True)
        if direct.ok:
            if np.linalg.norm(direct.corners_px[2] - corners[2]) < 0.6 * search_px:
                return direct
            # V3 moved: part of its sides lay outside the window; once more with all of them.
            again = _refine(
                grey, direct.corners_px, modules, inverted, min(search_px, 1.5), finders_only=False
            )
            return again if again.ok else direct
        first = _refine(grey, corners, modules, inverted, search_px, finders_only=True)
        if not first.ok:
            return first
        second = _refine(grey, first.corners_px, modules, inverted, min(search_px, 1.5), finders_only=False)
        if not second.ok:
            return RefineResult(False, corners.copy(), first.corner_rms_px * np.nan, second.reason)
        return second
    return _refine(grey, corners, modules, inverted, search_px, finders_only=False)


def _refine(
    grey: np.ndarray,
    corners: np.ndarray,
    modules: int,
    inverted: bool,
    search_px: float,
    finders_only: bool,
    loose_v3: bool = False,
) -> RefineResult:
    nan4 = np.full(4, np.nan)

    def fail(reason: str) -> RefineResult:
        return RefineResult(False, corners.copy(), nan4, reason)

    # Per-side geometry in plain floats (four values each: numpy's per-call cost would dominate).
    pts = corners.tolist()
    centre_x = 0.25 * sum(p[0] for p in pts)
    centre_y = 0.25 * sum(p[1] for p in pts)
    side_list, dir_list, normal_list = [], [], []
    for i in range(4):
        (x0, y0), (x1, y1) = pts[i], pts[(i + 1) % 4]
        length = math.hypot(x1 - x0, y1 - y0)
        if length < 8:
            return fail(f"the code is too small to refine ({length:.1f} px side)")
        dx, dy = (x1 - x0) / length, (y1 - y0) / length
        nx, ny = dy, -dx
        if nx * (0.5 * (x0 + x1) - centre_x) + ny * (0.5 * (y0 + y1) - centre_y) < 0:
            nx, ny = -nx, -ny  # outward, whatever the handedness of the corner order
        side_list.append(length)
        dir_list.append((dx, dy))
        normal_list.append((nx, ny))
    dark = _dark_level(grey, corners, modules)
    if not math.isfinite(dark):
        return fail("the finder patterns are outside the image")
    level_dark = 255.0 - dark if inverted else dark
    sides = np.array(side_list)
    directions = np.array(dir_list)
    normals = np.array(normal_list)
    module_px = sides / modules
    # Module size across each side (what a profile crosses): from the two neighbouring sides.
    across_px = np.minimum(module_px[_PREVIOUS], module_px[_NEXT])
    # k profiles across each side (rows: V1V2, V2V3, V3V4, V4V1), about one per pixel, not too close
    # to the corners where the other side's edge blurs in.
    margin = 2.0 + 0.5 * module_px
    if finders_only:
        # Only along the outer edges of the finder patterns (modules 0..7 from V1, V2, V4), where
        # the rough sides are close to the truth; sides V2V3 and V3V4 have one finder each.
        k = int(np.clip(6.0 * module_px.min(), 8, MAX_PROFILES_PER_SIDE // 2)) * 2
        h = _unit_steps(k // 2)[None, :] * (6.5 * module_px - margin)[:, None] + margin[:, None]
        h2 = _unit_steps(k)[None, :] * (6.5 * module_px - margin)[:, None] + margin[:, None]
        along = np.empty((4, k))
        along[0] = np.concatenate([h[0], sides[0] - h[0]])
        along[1] = h2[1]
        along[2] = sides[2] - h2[2]
        along[3] = np.concatenate([h[3], sides[3] - h[3]])
    else:
        k = int(np.clip((sides - 2 * margin).min(), 8, MAX_PROFILES_PER_SIDE))
        along = margin[:, None] + _unit_steps(k)[None, :] * (sides - 2 * margin)[:, None]
    base = corners[:, None, :] + along[:, :, None] * directions[:, None, :]

    # Pass 1: where the profile, coming in from the quiet zone, first crosses the half level.
    # Big modules: backends' corners are off by more, and a wider window stays within one module.
    search_px = max(search_px, 0.4 * float(module_px.min()))
    offsets = _profile_offsets(round(search_px, 3))
    points = base[:, :, None, :] + offsets[None, None, :, None] * normals[:, None, None, :]
    values = _as_seen(sample_bilinear(grey, points), inverted)
    quiet = values[:, :, 0]
    threshold = 0.5 * (quiet + level_dark)
    below = values < threshold[:, :, None]
    first = np.maximum(np.argmax(below, axis=2), 1)
    # (NaN, outside the image, compares False: such profiles are not valid)
    valid = below.any(axis=2) & ~below[:, :, 0] & (quiet - level_dark > 12.0)
    flat_index = _row_starts(first.shape, values.shape[2]) + first
    v_out = values.reshape(-1)[flat_index - 1]
    v_in = values.reshape(-1)[flat_index]
    with np.errstate(invalid="ignore", divide="ignore"):  # flat or outside profiles: dropped below
        crossing = offsets[first - 1] - (v_out - threshold) / (v_out - v_in) * PROFILE_STEP_PX
        crossing = np.where(valid, crossing, 0.0)

        # Pass 2: the crossing of the half level is pixel-locked (biased by up to 0.1 px by the
        # pixels' area sampling); the area under the normalised darkness profile around it is not:
        # for a step at e blurred by any symmetric kernel, the integral of darkness over
        # [c - h, c + h] = e - (c - h).
        half = np.clip(0.45 * across_px, 1.0, 2.5)[:, None]
        t = _unit_steps(AREA_SAMPLES) * 2.0 - 1.0
        window_offsets = crossing[:, :, None] + half[:, :, None] * t[None, None, :]
        window = base[:, :, None, :] + window_offsets[..., None] * normals[:, None, None, :]
        seen = _as_seen(sample_bilinear(grey, window), inverted)
        darkness = (quiet[:, :, None] - seen) / (quiet - level_dark)[:, :, None]
        inner, outer = darkness[:, :, 0], darkness[:, :, -1]
        trapezoid = darkness.sum(axis=2) - 0.5 * (inner + outer)
        edge = crossing - half + (2.0 * half / (AREA_SAMPLES - 1)) * trapezoid
        # Clean steps (fully dark inside and fully light outside the window) take the area
        # estimate. With small modules (2-3 px) blur keeps the window from saturating: there the
        # half-level crossing stands in, if the inside is clearly dark. A profile that grazes the
        # corner of a dark module beside a light boundary module is neither and is dropped.
        clean = (np.abs(edge - crossing) < 0.5) & (inner > 1.0 - CLEAN_STEP) & (np.abs(outer) < CLEAN_STEP)
        if across_px.min() < 3.5:
            fallback = (across_px < 3.5)[:, None] & (inner > 0.6) & (np.abs(outer) < 0.25)
            edge = np.where(clean, edge, crossing)
            valid &= clean | fallback
        else:
            valid &= clean
    found = valid.sum(axis=1)
    if found.min() < max(6, k // 5):
        worst = int(np.argmin(found))
        return fail(f"side V{worst + 1}V{(worst + 1) % 4 + 1}: too few edge points ({found[worst]} of {k})")
    c0, c1, rms, inliers = _fit_sides(along, edge, valid, across_px)
    if inliers.min() < max(6, k // 5):
        worst = int(np.argmin(inliers))
        return fail(f"side V{worst + 1}V{(worst + 1) % 4 + 1}: the edge points do not line up")
    # V_i = intersection of side i-1 (ending at V_i) and side i (starting at V_i), in plain floats.
    line_points, line_dirs = [], []
    for i in range(4):
        (px, py), (dx, dy), (nx, ny) = pts[i], dir_list[i], normal_list[i]
        ux, uy = dx + float(c1[i]) * nx, dy + float(c1[i]) * ny
        norm = math.hypot(ux, uy)
        line_points.append((px + float(c0[i]) * nx, py + float(c0[i]) * ny))
        line_dirs.append((ux / norm, uy / norm))
    refined_list = []
    for i in range(4):
        (ax, ay), (adx, ady) = line_points[i - 1], line_dirs[i - 1]
        (bx, by), (bdx, bdy) = line_points[i], line_dirs[i]
        det = ady * bdx - adx * bdy
        if abs(det) < 1e-3:
            return fail("two sides are parallel")
        t = (bdx * (by - ay) - bdy * (bx - ax)) / det
        refined_list.append((ax + t * adx, ay + t * ady))
    refined = np.array(refined_list)
    lines = tuple(
        EdgeLine(line_points[i], line_dirs[i], float(rms[i]), int(inliers[i]), int(found[i]))
        for i in range(4)
    )
    moved = np.sqrt(((refined - corners) ** 2).sum(axis=1))
    if (finders_only or loose_v3) and moved[2] < search_px + 1.0 + 3.0 * module_px.max():
        moved[2] = 0.0  # V3 may move a lot: that is the point of this pass
    if moved.max() > search_px + 1.0:
        return fail(f"a refined corner moved {moved.max():.1f} px, beyond the search window")
    corner_rms = np.sqrt(0.5 * (rms[_PREVIOUS] ** 2 + rms**2))
    return RefineResult(True, refined, corner_rms, "", lines)
