"""Check a corner set against the fixed patterns of a QR symbol: finders, separators, timing, quiet zone.

Given corners V1..V4 (pixels) and the symbol's modules per side n, a homography maps module
coordinates (V1 = (0, 0), V2 = (n, 0), V3 = (n, n), V4 = (0, n)) to pixels; the centres of the
modules whose colour every QR code fixes are sampled and classified dark or light. The share that
match is the *pattern score* in [0, 1]: about 0.5 for a corner set that is not on a code (or off
by a module or more), near 1 for a good one. It also tells the code's polarity (dark on light, or
inverted) and, when a backend does not report the version, which n fits best.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from qrfield.detect.bilinear import sample_bilinear
from qrfield.detect.lens import Lens, module_points_px
from qrfield.homography import square_to_quad

#: Smallest contrast (grey levels between the dark and light pattern modules) a code may have.
MIN_CONTRAST = 12.0
#: Module counts per side of QR versions 1..40.
ALL_MODULES = tuple(17 + 4 * v for v in range(1, 41))


@dataclass(frozen=True)
class PatternCheck:
    """Result of :func:`check_patterns`.

    Attributes:
        score: share of fixed modules with the expected colour, 0..1 (0 when not measurable).
        modules: modules per side used.
        inverted: True for a light code on a dark background.
        dark, light: median grey levels of the expected dark and light modules (as seen, not inverted).
        reason: why the score is 0, else "".
    """

    score: float
    modules: int
    inverted: bool
    dark: float
    light: float
    reason: str = ""


@functools.lru_cache(maxsize=64)
def fixed_modules(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Module centres (k, 2) in module units (x, y), their expected colour (k,) bool (True = dark),
    and whether each lies in the quiet zone (k,) bool."""
    cells: list[tuple[int, int, bool]] = []

    def finder(r0: int, c0: int) -> None:
        for r in range(7):
            for c in range(7):
                ring = max(abs(r - 3), abs(c - 3))
                cells.append((c0 + c, r0 + r, ring != 2))

    finder(0, 0)
    finder(0, n - 7)
    finder(n - 7, 0)
    for i in range(8):  # separators (light L-shapes inside the symbol)
        cells += [(i, 7, False), (7, i, False), (n - 1 - i, 7, False), (n - 8, i, False)]
        cells += [(i, n - 8, False), (7, n - 1 - i, False)]
    for i in range(8, n - 8):  # timing patterns
        cells += [(i, 6, i % 2 == 0), (6, i, i % 2 == 0)]
    for i in range(-1, n + 1):  # the first ring of the quiet zone
        cells += [(i, -1, False), (i, n, False), (-1, i, False), (n, i, False)]
    cells = list(dict.fromkeys(cells))  # separators overlap at the corners
    xy = np.array([(c + 0.5, r + 0.5) for c, r, _ in cells], dtype=np.float64)
    dark = np.array([d for _, _, d in cells], dtype=bool)
    quiet = (xy < 0).any(axis=1) | (xy > n).any(axis=1)
    for array in (xy, dark, quiet):
        array.setflags(write=False)
    return xy, dark, quiet


def module_homography(corners_px: np.ndarray, n: int) -> np.ndarray:
    """(3, 3) homography from module coordinates (0..n) to pixels for corners V1..V4 (4, 2)
    (qrfield.homography.square_to_quad; NaN entries for three corners in a line)."""
    c = np.asarray(corners_px, dtype=np.float64)
    return square_to_quad(c[:, 0], c[:, 1], float(n))


def to_pixels(h: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Apply homography ``h`` to (k, 2) points."""
    p = xy @ h[:, :2].T + h[:, 2]
    return p[:, :2] / p[:, 2:3]


def small_median(values: np.ndarray) -> float:
    """Median of a small 1-D array (np.median's overhead dominates at this size)."""
    ordered = np.sort(values)
    n = len(ordered)
    return float(0.5 * (ordered[(n - 1) // 2] + ordered[n // 2]))


def check_patterns(
    grey: np.ndarray,
    corners_px: np.ndarray,
    n: int,
    lens: Lens | None = None,
    offset: tuple[int, int] = (0, 0),
) -> PatternCheck:
    """Score corners V1..V4 (pixels) of a symbol of ``n`` modules per side against its fixed patterns.

    With a distorting ``lens`` the module centres are found through it (``offset``: where ``grey``'s
    top-left pixel lies in the camera's image, for a crop); else by the corners' homography.
    """
    xy, dark, quiet = fixed_modules(n)
    values = sample_bilinear(grey, module_points_px(lens, corners_px, n, xy, offset))
    outside = np.isnan(values)
    if outside[~quiet].any():
        return PatternCheck(0.0, n, False, np.nan, np.nan, "the code is cut by the image border")
    if outside.any():  # a tightly cropped image: judge by the quiet zone that is there
        values, dark = values[~outside], dark[~outside]
    d = small_median(values[dark])
    light = small_median(values[~dark])
    inverted = d > light
    if abs(light - d) < MIN_CONTRAST:
        return PatternCheck(
            0.0, n, inverted, d, light, f"too little contrast ({abs(light - d):.0f} grey levels)"
        )
    threshold = 0.5 * (d + light)
    seen_dark = (values > threshold) if inverted else (values < threshold)
    score = float(np.mean(seen_dark == dark))
    return PatternCheck(score, n, inverted, d, light)


def best_module_count(grey: np.ndarray, corners_px: np.ndarray, min_module_px: float = 1.0) -> PatternCheck:
    """The version (modules per side) whose fixed patterns fit the corners best."""
    side = float(np.mean(np.linalg.norm(np.roll(corners_px, -1, axis=0) - corners_px, axis=1)))
    best: PatternCheck | None = None
    for n in ALL_MODULES:
        if side / n < min_module_px:
            break
        check = check_patterns(grey, corners_px, n)
        if best is None or check.score > best.score:
            best = check
    if best is None:
        return PatternCheck(
            0.0, ALL_MODULES[0], False, np.nan, np.nan, f"the code is too small ({side:.1f} px wide)"
        )
    return best
