"""The ``steep`` backend: small codes seen steeply, compressed along one direction, that the other
backends miss.

A code tilted 40-55 degrees about both axes is a thin parallelogram: its modules are 1.2-1.5 px
across the compression and several px along it. Through a blur of about a px the finder patterns'
one-module rings are gone across the compression, so the contour locators (qrfield.detect.finders,
qrfield.detect.small) do not see the nested squares; along the other direction they are sharp.
Here, in the busy regions of the image (:func:`qrfield.detect.small.busy_blobs`) that no other
backend explained (this backend runs last):

1. *Compressed blobs*: each connected busy blob's second moments give its widths along their two
   principal directions (a square's second moment is isotropic, so for a code seen through an
   affine map they are its side and its side compressed); blobs whose widths (less the mask's
   reach) differ by less than MIN_ANISOTROPY (the small backend's), that do not fill their
   moments' rectangle, or whose compressed width cannot hold 21 modules of MIN_MODULE_PX are
   rejected before any resampling (the cost on frames with no code).
2. *Un-compressed canvas*: the blob's surroundings, sharpened (unsharp mask against a blur of one
   px, SHARPEN times), are resampled by one affine map (cubic) that stretches the compressed
   direction back (:func:`canvas_scale` canvas px per image px across the compression, less
   along it) and turns the code's outline (the blob's least-area rectangle) upright: the code is
   then a roughly square, upright symbol with canvas modules of about CANVAS_MODULE_PX.
3. *Finder patterns*: first the contour locator (qrfield.detect.finders) on the canvas, where
   its finders show as nested squares; then by correlation: the canvas is correlated
   (normalised) with a finder pattern and its light separator (9 x 9 modules) at module sizes
   MODULE_STEP apart (:func:`module_sizes`: those the blob's module counts allow, widened by
   PERSPECTIVE, since the canvas undoes one affine map and a code in perspective keeps finders
   of different sizes); the strongest peaks over all sizes (at most MAX_PEAKS a size,
   MAX_FINDERS in all, at least MIN_CORRELATION) whose triples make a code's finder triangle
   (LEG_RANGE, RIGHT_ANGLE_DEG, sizes and legs within FINDER_RATIO; the TRIOS strongest) are
   handed as squares to the contour locator's triple search, which picks the finders and n by
   the fixed patterns (>= 0.8 in the canvas) and decodes the rectified symbol; the first triple
   that locates a code gives it. The larger templates are correlated at half resolution
   (COARSE_TEMPLATE_PX), their peaks placed at full resolution. A code not
   decoded must score MIN_IMAGE_SCORE in the image too, before the costly reading is tried.

Through a distorting lens (``locate_steep(grey, lens)``) the blob's widths and the canvas are
taken in ideal pixels (qrfield.detect.lens), where the code's plane maps by a homography.
Corners come back to the image by the inverse affine map (and the lens). A code located but not
read is read by qrfield.detect.reading after its fixed patterns are fitted in the image
(:meth:`qrfield.detect.detector.Detector.accept`), which also checks the patterns again: nothing
from here is reported without those checks.
"""

from __future__ import annotations

import functools
import itertools

import cv2
import numpy as np

from qrfield.detect.lens import Lens, undistort_pixels
from qrfield.detect.patterns import ALL_MODULES, check_patterns

#: Least ratio of a blob's principal widths for this backend (rounder blobs are the small
#: backend's); most blobs tried per image, the largest first.
MIN_ANISOTROPY = 1.15
MAX_BLOBS = 4
#: Least and most share (px) of the compressed width per module: a code compressed along its
#: diagonal has modules of 1.2 px along its sides and 0.6 px of its compressed width per module.
MIN_MODULE_PX = 0.6
MAX_MODULE_PX = 3.0
#: Most modules per side searched for (version 10).
MAX_MODULES = 57
#: Longest principal width (px) of a blob tried.
MAX_WIDTH_PX = 600.0
#: How far the busy mask reaches beyond a code's outline (px, each side: the 5 x 5 average at half
#: resolution and the closing), taken off each principal width.
MASK_REACH_PX = 4.0
#: Least area (half-resolution px) of a blob: the smallest code's widths with the mask's reach.
MIN_AREA = int((21 * MIN_MODULE_PX + 2 * MASK_REACH_PX) ** 2 * MIN_ANISOTROPY / 4)
#: Least and most share of its principal widths' rectangle (including the reach) a blob fills.
MIN_FILL = 0.6
MAX_FILL = 1.3
#: Canvas px per image px across the compression: enough for canvas modules of CANVAS_MODULE_PX
#: at the most modules the blob can hold, within CANVAS_SCALE .. MAX_CANVAS_SCALE (the canvas's
#: cost goes with its area); the unsharp-mask strength (against a 1 px blur).
CANVAS_SCALE = 1.8
CANVAS_MODULE_PX = 3.5
MAX_CANVAS_SCALE = 6.0
SHARPEN = 6.0
#: Module sizes tried differ by this share at least (the triple search allows 20 %).
MODULE_STEP = 0.15
#: Finder candidates per module count: the strongest correlation peaks, at least this correlation.
MAX_PEAKS = 5
MIN_CORRELATION = 0.35
#: A triple of peaks is tried only when it makes a code's finder triangle: legs of this range of
#: times (n - 7) modules, at 90 degrees within this.
LEG_RANGE = (0.5, 1.7)
RIGHT_ANGLE_DEG = 40.0
#: Least pattern score in the image (no lens) of a located code not decoded in the canvas: below
#: it the reading (qrfield.detect.reading, the costly part) is not tried. Located codes of the
#: steep set that were read scored 0.78-0.85; the hard set's located codes that no one reads
#: 0.67-0.93.
MIN_IMAGE_SCORE = 0.76
#: The canvas undoes one affine compression; perspective remains, so a code's near finder can be
#: up to twice its far one: finders are searched for at module sizes from PERSPECTIVE[0] times the
#: smallest the blob's module counts allow to PERSPECTIVE[1] times the largest, and three finder
#: candidates (their sizes, and the two legs of their triangle) may differ by up to FINDER_RATIO.
PERSPECTIVE = (0.7, 1.4)
FINDER_RATIO = 2.0
#: Most finder candidates kept per canvas (the strongest over all sizes), and most triples of them
#: tried (the strongest by summed correlation). TRIOS was 6 before issue-26p2: over the canvases of
#: steep seeds 2026, 2027, 2031 (300 views each) and the hard set (seed 2024, 400 views) every
#: code a triple located came from the strongest one (199 canvases); 2 keeps a margin.
MAX_FINDERS = 8
TRIOS = 2
#: Finder templates of more than this side (px: modules above 4 canvas px) are correlated at half
#: resolution (the template halved, at least 2 px a module), each peak then placed by the full
#: template within COARSE_REFINE_PX of it; peaks are taken at half resolution down to
#: MIN_CORRELATION less COARSE_MARGIN, kept at full resolution from MIN_CORRELATION (issue-26p2).
COARSE_TEMPLATE_PX = 36
COARSE_REFINE_PX = 3
COARSE_MARGIN = 0.05
COARSE_PEAKS = 2 * MAX_PEAKS


def compressed_blobs(grey: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float, float, np.ndarray]]:
    """Busy blobs of ``grey`` shaped like a compressed code, the largest first (at most MAX_BLOBS):
    (centre (2,) px, long direction (2,) unit, long width px, compressed width px, blob pixel
    centres (k, 2) px in the image), widths from the second moments less the mask's reach."""
    from qrfield.detect.small import busy_blobs

    count, labels, stats = busy_blobs(grey)
    out = []
    for k in range(1, count):
        x, y, w, h, area = (int(v) for v in stats[k])
        if area < MIN_AREA or max(w, h) * 2 > 1.5 * MAX_WIDTH_PX:
            continue
        blob = (labels[y : y + h, x : x + w] == k).astype(np.uint8)
        m = cv2.moments(blob, binaryImage=True)
        if m["m00"] <= 0:
            continue
        cov = np.array([[m["mu20"], m["mu11"]], [m["mu11"], m["mu02"]]]) / m["m00"] * 4.0  # full px^2
        values, vectors = np.linalg.eigh(cov)
        if values[0] <= 0:
            continue
        long_w = 2.0 * np.sqrt(3.0 * values[1]) - 2.0 * MASK_REACH_PX
        short_w = 2.0 * np.sqrt(3.0 * values[0]) - 2.0 * MASK_REACH_PX
        if short_w < 21 * MIN_MODULE_PX or long_w > MAX_WIDTH_PX or long_w < MIN_ANISOTROPY * short_w:
            continue
        fill = 4.0 * area / ((long_w + 2 * MASK_REACH_PX) * (short_w + 2 * MASK_REACH_PX))
        if not MIN_FILL <= fill <= MAX_FILL:
            continue
        centre = 2.0 * np.array([x + m["m10"] / m["m00"], y + m["m01"] / m["m00"]]) + 0.5
        ys, xs = np.nonzero(blob)
        points = 2.0 * np.column_stack([xs + x, ys + y]).astype(np.float64) + 0.5
        out.append((area, (centre, vectors[:, 1], float(long_w), float(short_w), points)))
    out.sort(key=lambda item: -item[0])
    return [blob for _, blob in out[:MAX_BLOBS]]


def module_counts(short_w: float) -> list[int]:
    """Module counts per side a code of compressed width ``short_w`` px may have."""
    return [n for n in ALL_MODULES if n <= MAX_MODULES and MIN_MODULE_PX <= short_w / n <= MAX_MODULE_PX]


def canvas_scale(short_w: float) -> float:
    """Canvas px per image px across the compression for a blob of compressed width ``short_w``."""
    counts = module_counts(short_w)
    most = counts[-1] if counts else 21
    return float(np.clip(CANVAS_MODULE_PX * most / short_w, CANVAS_SCALE, MAX_CANVAS_SCALE))


def canvas_map(
    centre: np.ndarray, long_dir: np.ndarray, long_w: float, short_w: float, points: np.ndarray
) -> tuple[np.ndarray, int, float]:
    """The (2, 3) affine map image px -> canvas px that stretches the compressed direction back
    (``scale`` = :func:`canvas_scale` across it, scale * short_w / long_w along it) and turns the
    blob's least-area rectangle upright, the code's centre at the canvas's; the canvas side (px);
    the scale."""
    scale = canvas_scale(short_w)
    e1 = long_dir / np.linalg.norm(long_dir)
    e2 = np.array([-e1[1], e1[0]])
    stretch = np.diag([scale * short_w / long_w, scale]) @ np.vstack([e1, e2])
    local = (points - centre) @ stretch.T
    (_, _), (_, _), angle = cv2.minAreaRect(local.astype(np.float32))
    t = np.deg2rad(angle)
    turn = np.array([[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]])  # undoes the rectangle's angle
    linear = turn @ stretch
    side = int(np.ceil(1.5 * scale * short_w + 24))
    offset = np.full(2, (side - 1) / 2.0) - linear @ centre
    return np.hstack([linear, offset[:, None]]), side, scale


@functools.lru_cache(maxsize=64)
def _finder_template(size: int) -> np.ndarray:
    """A dark-on-light finder pattern with its light separator, 9 x 9 modules in ``size`` x
    ``size`` canvas px, upright (float32, 0 dark .. 255 light; 4 x 4 samples per px)."""
    sub = (np.arange(4 * size) + 0.5) / 4.0 * (9.0 / size)  # module coordinates 0..9
    ring = np.maximum(np.abs(sub[:, None] - 4.5), np.abs(sub[None, :] - 4.5))
    dark = ((ring < 3.5) & (ring >= 2.5)) | (ring < 1.5)
    light = (~dark).astype(np.float32)
    return 255.0 * light.reshape(size, 4, size, 4).mean(axis=(1, 3))


def _finder_triangle(points: list[np.ndarray], shortest_px: float, longest_px: float) -> bool:
    """True when three finder centres (canvas px) make the right-angled triangle of a code whose
    finder centres are ``shortest_px`` to ``longest_px`` apart along its sides: at one of them
    two legs within LEG_RANGE of that span, at most FINDER_RATIO apart, at an angle of
    90 +- RIGHT_ANGLE_DEG (the canvas undoes the compression; perspective remains)."""
    lo, hi = LEG_RANGE
    for a in range(3):
        u, v = points[(a + 1) % 3] - points[a], points[(a + 2) % 3] - points[a]
        lu, lv = float(np.hypot(*u)), float(np.hypot(*v))
        if not (lo * shortest_px <= min(lu, lv) and max(lu, lv) <= hi * longest_px):
            continue
        if max(lu, lv) > FINDER_RATIO * min(lu, lv):
            continue
        if abs(float(u @ v)) <= np.sin(np.deg2rad(RIGHT_ANGLE_DEG)) * lu * lv:
            return True
    return False


def _peaks(
    response: np.ndarray, radius: int, least: float = MIN_CORRELATION, most: int = MAX_PEAKS
) -> list[tuple[int, int]]:
    """(x, y) of the strongest local maxima of ``response``, at most ``most``, at least
    ``least``, each ``radius`` px from the stronger ones."""
    r = response.copy()
    out: list[tuple[int, int]] = []
    for _ in range(most):
        _, value, _, (x, y) = cv2.minMaxLoc(r)
        if value < least:
            break
        out.append((x, y))
        r[max(y - radius, 0) : y + radius + 1, max(x - radius, 0) : x + radius + 1] = -1.0
    return out


def _ideal_blob(
    lens: Lens, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float, float, np.ndarray] | None:
    """A blob's (centre, long direction, long width, compressed width, points) as
    :func:`compressed_blobs` gives them, in ideal pixels of ``lens`` (qrfield.detect.lens: where
    the plane of the code maps by a homography): its pixel centres ``points`` (k, 2) undistorted,
    the widths from their second moments less the mask's reach; None when degenerate."""
    ideal = undistort_pixels(lens.camera, points)
    centre = ideal.mean(axis=0)
    values, vectors = np.linalg.eigh(np.cov((ideal - centre).T))
    if values[0] <= 0:
        return None
    long_w = 2.0 * np.sqrt(3.0 * values[1]) - 2.0 * MASK_REACH_PX
    short_w = 2.0 * np.sqrt(3.0 * values[0]) - 2.0 * MASK_REACH_PX
    if short_w <= 0:
        return None
    return centre, vectors[:, 1], float(long_w), float(short_w), ideal


def locate_steep(
    grey: np.ndarray, lens: Lens | None = None
) -> list[tuple[np.ndarray, int, str | None, np.ndarray | None]]:
    """Codes in the compressed busy blobs of ``grey`` (H, W) uint8: (corners V1..V4 px, modules,
    text or None, decoded module matrix or None), as qrfield.detect.finders.locate_by_finders gives
    them; pixel centres as OpenCV's (the top-left pixel's centre at (0, 0)).

    ``lens``: the camera's lens (qrfield.detect.lens.Lens, for images of this size), None for a
    pinhole. Through a distorting lens the canvas is made from ideal pixels (each canvas pixel
    mapped back by the affine map, then through the lens): a code near the edge of a wide lens
    is curved in the image (a 100 mm code at 240 mm: a corner 5 px off a straight-sided
    quadrilateral, steep seed 2027 view 137), in ideal pixels it is the plane's homography."""
    from qrfield.detect.finders import _candidates_from_finders, decode_rectified

    found: list[tuple[np.ndarray, int, str | None, np.ndarray | None]] = []
    blobs = compressed_blobs(grey)
    if not blobs:
        return found
    distorted = lens is not None and lens.distorted and lens.fits(grey.shape)
    g = grey.astype(np.float32)
    for blob in blobs:
        if distorted:
            ideal_blob = _ideal_blob(lens, blob[4])
            if ideal_blob is None:
                continue
            blob = ideal_blob
        centre, long_dir, long_w, short_w, points = blob
        affine, side, scale = canvas_map(centre, long_dir, long_w, short_w, points)
        inverse = cv2.invertAffineTransform(affine)
        if distorted:
            # canvas px -> ideal px (the inverse affine map) -> image px (the lens)
            ys, xs = np.mgrid[0:side, 0:side].astype(np.float64)
            grid = np.column_stack([xs.ravel(), ys.ravel()]) @ inverse[:, :2].T + inverse[:, 2]
            source = lens.distort(grid).reshape(side, side, 2)
        else:
            box = np.array([[0, 0], [side, 0], [side, side], [0, side]], dtype=np.float64)
            source = box @ inverse[:, :2].T + inverse[:, 2]
        # the image region the canvas covers, sharpened there only
        reach = source.reshape(-1, 2)
        x0, y0 = np.maximum(np.floor(reach.min(axis=0)).astype(int) - 4, 0)
        x1, y1 = np.minimum(np.ceil(reach.max(axis=0)).astype(int) + 5, (grey.shape[1], grey.shape[0]))
        if x1 - x0 < 8 or y1 - y0 < 8:
            continue
        crop = g[y0:y1, x0:x1]
        sharp = cv2.addWeighted(crop, 1.0 + SHARPEN, cv2.GaussianBlur(crop, (0, 0), 1.0), -SHARPEN, 0.0)
        if distorted:
            maps = (source - np.array([x0, y0], dtype=np.float64)).astype(np.float32)
            canvas = cv2.remap(sharp, maps, None, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        else:
            shifted = affine.copy()
            shifted[:, 2] += affine[:, :2] @ np.array([x0, y0], dtype=np.float64)
            canvas = cv2.warpAffine(
                sharp, shifted, (side, side), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE
            )
        canvas = np.clip(canvas, 0, 255).astype(np.uint8)
        best = _locate_in_canvas(canvas, short_w, scale, decode_rectified, _candidates_from_finders)
        if best is None:
            continue
        corners_c, n, text, matrix = best
        corners = corners_c @ inverse[:, :2].T + inverse[:, 2]
        if distorted:
            corners = lens.distort(corners)
        if (
            text is None
            and check_patterns(grey, corners, n, lens if distorted else None).score < MIN_IMAGE_SCORE
        ):
            continue  # not read, and its patterns hold too poorly in the image to be read there
        if not any(np.abs(corners - other[0]).max() < 2.0 for other in found):
            found.append((corners, n, text, matrix))
    return found


def module_sizes(short_w: float, scale: float) -> list[float]:
    """Canvas module sizes (px) at which finder patterns are searched for in a canvas made at
    ``scale`` from a blob of compressed width ``short_w`` px: from the largest module the blob's
    module counts allow (times PERSPECTIVE[1]) down to the smallest (times PERSPECTIVE[0]),
    each MODULE_STEP below the last; the canvas undoes one affine compression, so a code seen
    in perspective keeps finders of different sizes (its near finder up to twice its far one)."""
    counts = module_counts(short_w)
    if not counts:
        return []
    largest = PERSPECTIVE[1] * scale * short_w / counts[0]
    smallest = max(PERSPECTIVE[0] * scale * short_w / counts[-1], 1.0)
    sizes = []
    module = largest
    while module >= smallest:
        sizes.append(module)
        module /= 1.0 + MODULE_STEP
    return sizes


def _coarse_peaks(
    image: np.ndarray, half: np.ndarray, template: np.ndarray, module: float
) -> list[tuple[float, int, int]]:
    """(correlation, x, y) of the strongest peaks (:func:`_peaks`) of a finder ``template``
    (size x size px) over the float32 canvas ``image``, found in ``half`` (the canvas at half
    resolution, cv2.INTER_AREA) with the template halved, each then placed at full resolution:
    the best of the full template's correlations within COARSE_REFINE_PX of the half-resolution
    peak's place; (x, y) the template's top-left canvas px, as cv2.matchTemplate's response."""
    size = template.shape[0]
    small = _finder_template(round(size / 2.0))
    response = cv2.matchTemplate(half, small, cv2.TM_CCOEFF_NORMED)
    r, out = COARSE_REFINE_PX, []
    limit_x, limit_y = image.shape[1] - size, image.shape[0] - size
    coarse = _peaks(response, max(int(3.5 * module / 2.0), 1), MIN_CORRELATION - COARSE_MARGIN, COARSE_PEAKS)
    for hx, hy in coarse:
        # the half template's centre (half px) -> canvas px -> the full template's top-left
        cx = 2.0 * (hx + (small.shape[0] - 1) / 2.0) + 0.5
        cy = 2.0 * (hy + (small.shape[0] - 1) / 2.0) + 0.5
        x0 = int(np.clip(round(cx - (size - 1) / 2.0) - r, 0, limit_x))
        y0 = int(np.clip(round(cy - (size - 1) / 2.0) - r, 0, limit_y))
        x1, y1 = min(x0 + 2 * r, limit_x), min(y0 + 2 * r, limit_y)
        local = cv2.matchTemplate(image[y0 : y1 + size, x0 : x1 + size], template, cv2.TM_CCOEFF_NORMED)
        _, value, _, (x, y) = cv2.minMaxLoc(local)
        if value >= MIN_CORRELATION:
            out.append((float(value), x0 + x, y0 + y))
    # as _peaks: the strongest first, each 3.5 modules from the stronger ones, at most MAX_PEAKS
    out.sort(key=lambda peak: -peak[0])
    kept: list[tuple[float, int, int]] = []
    radius = max(int(3.5 * module), 2)
    for peak in out:
        if all(max(abs(peak[1] - k[1]), abs(peak[2] - k[2])) > radius for k in kept):
            kept.append(peak)
    return kept[:MAX_PEAKS]


def _finder_peaks(image: np.ndarray, sizes: list[float]) -> list[tuple[float, np.ndarray, int]]:
    """Finder-pattern candidates in a float32 canvas: (correlation, centre (2,) canvas px, template
    side px) of the strongest peaks of each module size in ``sizes`` (:func:`_peaks`), the
    strongest first, a weaker peak dropped where a stronger one (of any size) lies within half a
    finder of it (one finder answers several sizes), at most MAX_FINDERS. Templates of more than
    COARSE_TEMPLATE_PX are correlated at half resolution and their peaks placed at full
    resolution (:func:`_coarse_peaks`, issue-26p2: this search's CPU time 0.75x on the hard set's
    frames that reach the backend)."""
    found = []
    half = None
    for module in sizes:
        template = _finder_template(max(round(9 * module), 9))
        size = template.shape[0]
        if size + 2 > image.shape[0]:
            continue
        if size > COARSE_TEMPLATE_PX:
            if half is None:
                half = cv2.resize(
                    image, (image.shape[1] // 2, image.shape[0] // 2), interpolation=cv2.INTER_AREA
                )
            peaks = _coarse_peaks(image, half, template, module)
        else:
            response = cv2.matchTemplate(image, template, cv2.TM_CCOEFF_NORMED)
            peaks = [(float(response[y, x]), x, y) for x, y in _peaks(response, max(int(3.5 * module), 2))]
        for value, x, y in peaks:
            found.append((value, np.array([x + (size - 1) / 2.0, y + (size - 1) / 2.0]), size))
    found.sort(key=lambda peak: -peak[0])
    kept: list[tuple[float, np.ndarray, int]] = []
    for peak in found:
        if all(np.hypot(*(peak[1] - k[1])) > 3.5 / 9.0 * max(peak[2], k[2]) for k in kept):
            kept.append(peak)
    return kept[:MAX_FINDERS]


def _finder_trio(peaks: list[tuple[float, np.ndarray, int]], counts: list[int]) -> bool:
    """True when three finder candidates (:func:`_finder_peaks`) can be a code's three finders:
    their sizes within FINDER_RATIO of each other and a right-angled triangle
    (:func:`_finder_triangle`) whose legs fit between the fewest and the most modules
    ``counts`` allow at their mean module size."""
    sizes = [size for _, _, size in peaks]
    if max(sizes) > FINDER_RATIO * min(sizes):
        return False
    module = float(np.mean(sizes)) / 9.0
    return _finder_triangle(
        [centre for _, centre, _ in peaks], (counts[0] - 7) * module, (counts[-1] - 7) * module
    )


def _locate_in_canvas(
    canvas: np.ndarray, short_w: float, scale: float, decode_rectified, candidates_from_finders
) -> tuple[np.ndarray, int, str | None, np.ndarray | None] | None:
    """The code (corners V1..V4 canvas px, n, text or None, matrix or None) found in an upright
    (side, side) uint8 ``canvas`` made at ``scale`` from a blob of compressed width ``short_w``
    px, or None: (1) the contour locator on the canvas (qrfield.detect.finders.locate_by_finders:
    where the canvas shows the finders' nested squares, their outlines hold the perspective better
    than squares of the templates' sizes), the first one it decoded, else the first it located;
    only when it locates nothing, (2) the TRIOS strongest finder triples by correlation (summed
    correlation), tried in turn up to the first that locates a code, read in the canvas or not
    (issue-26p2: before, every triple was tried until one decoded; on the steep and hard sets
    measured that changed no detection, docs/detection.md); ``decode_rectified`` and
    ``candidates_from_finders`` are qrfield.detect.finders' (imported once by the caller)."""
    from qrfield.detect.finders import locate_by_finders

    counts = module_counts(short_w)
    if not counts:
        return None
    located = None
    for corners, m, text, matrix in locate_by_finders(canvas):
        if text is not None:
            return corners, m, text, matrix
        located = located or (corners, m, None, None)
    if located is not None:
        return located  # the contour locator's (issue-26p2: no trio was ever taken after it)
    peaks = _finder_peaks(canvas.astype(np.float32), module_sizes(short_w, scale))
    trios = [trio for trio in itertools.combinations(peaks, 3) if _finder_trio(list(trio), counts)]
    trios.sort(key=lambda trio: -sum(strength for strength, _, _ in trio))
    for trio in trios[:TRIOS]:
        squares = [
            centre + 3.5 / 9.0 * size * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
            for _, centre, size in trio
        ]
        for corners, m in candidates_from_finders(canvas, squares)[:1]:
            text, matrix, corners = decode_rectified(canvas, corners, m)
            # the first trio that locates a code gives it, read or not (issue-26p2)
            return corners, m, text, (matrix if text is not None else None)
    return None
