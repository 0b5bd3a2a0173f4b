"""A perspective-tolerant locator: finder patterns from contours, a homography, a rectified decode.

zxing-cpp and OpenCV miss codes seen under strong perspective (tilted 40-50 degrees near the edge of
a wide-angle view) although the symbol is sharp. Here the three finder patterns are found as
nested contours (dark ring, light ring, dark core) of a binarised image; their outer quadrilaterals
give 12 points whose module coordinates are known up to the symbol size n, so a homography maps
the symbol; n is the version whose fixed patterns fit best. The symbol is then warped upright and
decoded by zxing-cpp. Used as a last fallback (it costs a few milliseconds).
"""

from __future__ import annotations

import itertools

import cv2
import numpy as np

from qrfield.detect.patterns import ALL_MODULES, check_patterns

#: Most finder-pattern candidates considered per image (the strongest by area).
MAX_FINDERS = 12
#: Pixels per module and quiet-zone modules of the rectified image handed to the decoder.
RECTIFIED_PX = 5
RECTIFIED_QUIET = 4
#: Largest median grey-level step between neighbouring pixels (sampled rows) of a frame that is
#: searched: a scene with a code is mostly smooth (a few levels); noise and fine texture are not.
MAX_ROUGHNESS = 40.0
#: Least spread of grey levels (in the frame averaged over 8 x 8 pixels, which quells noise) for a
#: frame to be searched at all.
MIN_CONTRAST = 40.0


#: Tolerances of the polygon fitted to a finder's outline, as shares of its perimeter, tried in
#: turn until one gives a convex quadrilateral: the first suits a square seen nearly face on; a
#: finder foreshortened to a thin parallelogram (a code tilted 50-70 deg: its short sides are a
#: few px) collapses to 2 or 3 vertices at it, and keeps its 4 at the smaller ones.
QUAD_TOLERANCES = (0.08, 0.05, 0.03, 0.02)


def _quadrilateral(contour: np.ndarray) -> np.ndarray | None:
    """The convex quadrilateral (4, 2) fitted to a contour (cv2.approxPolyDP), or None."""
    perimeter = cv2.arcLength(contour, True)
    for tolerance in QUAD_TOLERANCES:
        approx = cv2.approxPolyDP(contour, tolerance * perimeter, True)
        if len(approx) == 4 and cv2.isContourConvex(approx):
            return approx.reshape(4, 2).astype(np.float64)
        if len(approx) > 4:
            return None  # smaller tolerances only add vertices
    return None


def _finder_quads(binary: np.ndarray) -> list[np.ndarray]:
    """Outer quadrilaterals (4, 2) of nested dark-light-dark contours in a binary image (255 = dark)."""
    contours, hierarchy = cv2.findContours(binary, cv2.RETR_TREE, cv2.CHAIN_APPROX_SIMPLE)
    if hierarchy is None:
        return []
    hierarchy = hierarchy[0]
    quads = []
    for i, contour in enumerate(contours):
        child = hierarchy[i][2]
        if child < 0:
            continue
        grandchild = hierarchy[child][2]
        if grandchild < 0:
            continue
        outer = cv2.contourArea(contour)
        core = cv2.contourArea(contours[grandchild])
        if outer < 30 or core <= 0 or not 2.0 < outer / core < 14.0:
            continue
        quad = _quadrilateral(contour)
        if quad is None:
            continue
        quads.append(quad)
    quads.sort(key=lambda q: -cv2.contourArea(q.astype(np.float32)))
    return quads[:MAX_FINDERS]


def _corner_labels(quad: np.ndarray, centre: np.ndarray, axes_inv: np.ndarray) -> np.ndarray | None:
    """Module offsets (4, 2) of a finder quad's corners from its centre: (+-3.5, +-3.5), by quadrant."""
    local = (quad - centre) @ axes_inv.T
    signs = np.sign(local)
    if len({(sx, sy) for sx, sy in signs}) != 4 or np.any(signs == 0):
        return None
    return 3.5 * signs


def _candidates_from_finders(grey: np.ndarray, quads: list[np.ndarray]) -> list[tuple[np.ndarray, int]]:
    """(corners V1..V4, modules) for each plausible triple of finder quads, best pattern fit first."""
    out = []
    centres = [q.mean(axis=0) for q in quads]
    areas = [cv2.contourArea(q.astype(np.float32)) for q in quads]
    for trio in itertools.combinations(range(len(quads)), 3):
        if max(areas[i] for i in trio) > 4.0 * min(areas[i] for i in trio):
            continue
        # Under strong perspective the corner finder (top-left) is not always at the widest angle of
        # the triangle of centres: each of the three is tried, the patterns decide.
        for a in range(3):
            tl, b, c = trio[a], trio[(a + 1) % 3], trio[(a + 2) % 3]
            eb, ec = centres[b] - centres[tl], centres[c] - centres[tl]
            cross = eb[0] * ec[1] - eb[1] * ec[0]
            if abs(cross) < 1e-6:
                continue
            tr, bl = (b, c) if cross > 0 else (c, b)  # clockwise on screen (y down): TL -> TR -> BL
            fit = _fit_symbol(grey, quads, centres, tl, tr, bl)
            if fit is not None and fit[0] >= 0.8:
                out.append(fit)
    out.sort(key=lambda item: -item[0])
    return [(corners, n) for _, corners, n in out]


def _fit_symbol(
    grey: np.ndarray, quads: list[np.ndarray], centres: list[np.ndarray], tl: int, tr: int, bl: int
) -> tuple[float, np.ndarray, int] | None:
    """(pattern score, corners V1..V4, modules) for finders ``tl``, ``tr``, ``bl``; None if implausible."""
    e_u, e_v = centres[tr] - centres[tl], centres[bl] - centres[tl]
    axes = np.column_stack([e_u, e_v])
    if abs(np.linalg.det(axes)) < 1.0:
        return None
    axes_inv = np.linalg.inv(axes)
    labels = [_corner_labels(quads[i], centres[i], axes_inv) for i in (tl, tr, bl)]
    if any(lab is None for lab in labels):
        return None
    # Finder half-size in units of the centre distance (n - 7 modules): estimates n.
    half = np.mean([np.abs((quads[i] - centres[i]) @ axes_inv.T).mean() for i in (tl, tr, bl)])
    if half <= 0:
        return None
    estimate = 7.0 + 3.5 / half
    best = None
    dst = np.concatenate([quads[i] for i in (tl, tr, bl)])
    for n in ALL_MODULES:
        if abs(n - estimate) > max(6.0, 0.2 * estimate):
            continue
        finder_centres = ((3.5, 3.5), (n - 3.5, 3.5), (3.5, n - 3.5))
        src = np.concatenate([np.array(fc) + lab for fc, lab in zip(finder_centres, labels, strict=True)])
        h, _ = cv2.findHomography(src, dst, 0)
        if h is None:
            continue
        square = np.array([[0, 0], [n, 0], [n, n], [0, n]], dtype=np.float64)
        p = square @ h[:, :2].T + h[:, 2]
        if np.any(p[:, 2] <= 0):
            continue
        corners = p[:, :2] / p[:, 2:3]
        check = check_patterns(grey, corners, n)
        if best is None or check.score > best[0]:
            best = (check.score, corners, n)
    return best


def decode_rectified(
    grey: np.ndarray, corners: np.ndarray, modules: int
) -> tuple[str | None, np.ndarray | None, np.ndarray]:
    """Warp the symbol at ``corners`` (V1..V4) upright with a quiet zone and decode it with zxing-cpp:
    (text, (n, n) bool module matrix, corners V1..V4) or (None, None, ``corners``). The corners are
    ``corners`` in the order zxing-cpp read the symbol: it decodes a symbol turned by quarter
    turns all the same (a triple of finders taken in the wrong order), and its V1 is then
    another of ours. (A mirrored symbol it reads too, reporting its corners clockwise: that is
    not seen here; the decoded matrix's check against the image refuses it later.)"""
    from qrfield.detect.backends import read_qr_barcodes  # here: backends imports this module
    from qrfield.detect.symbol import matrix_from_zxing

    q, s = RECTIFIED_QUIET, RECTIFIED_PX
    dst = np.array([[q, q], [q + modules, q], [q + modules, q + modules], [q, q + modules]], np.float32) * s
    h = cv2.getPerspectiveTransform(corners.astype(np.float32), dst)
    size = (modules + 2 * q) * s
    upright = cv2.warpPerspective(
        grey, h, (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    barcodes = read_qr_barcodes(upright)
    if not barcodes or not barcodes[0].valid:
        return None, None, corners
    turn = _quarter_turns(barcodes[0].position, dst.astype(np.float64))
    if turn is None:
        return None, None, corners
    # zxing-cpp's V1 is our V(turn + 1): steep seed 2037 view 258 came with the right text and
    # every corner one place round (223 px off, not reported good: its patterns did not check out)
    ordered = np.roll(corners, -turn, axis=0)
    matrix = matrix_from_zxing(barcodes[0])
    return barcodes[0].text, matrix if matrix is not None and matrix.shape[0] == modules else None, ordered


def _quarter_turns(position, square: np.ndarray) -> int | None:
    """How many places round (0-3) the symbol's own V1..V4 as zxing-cpp read them (``position``:
    top_left .. bottom_left in the rectified image) lie from the rectified corners ``square``
    (4, 2) of our V1..V4; None when they are not our corners in their cyclic order."""
    seen = np.array(
        [
            [p.x, p.y]
            for p in (position.top_left, position.top_right, position.bottom_right, position.bottom_left)
        ],
        dtype=np.float64,
    )
    nearest = [int(np.argmin(np.linalg.norm(square - point, axis=1))) for point in seen]
    turn = nearest[0]
    if nearest != [(turn + k) % 4 for k in range(4)]:
        return None
    return turn


def locate_by_finders(
    grey: np.ndarray, decode: bool = True
) -> list[tuple[np.ndarray, int, str | None, np.ndarray | None]]:
    """Codes located by their finder patterns: (corners V1..V4 px, modules, text or None, decoded
    module matrix or None).

    With ``decode`` False the symbols are only located (text None), e.g. to re-seed a refinement.
    """
    found: list[tuple[np.ndarray, int, str | None, np.ndarray | None]] = []
    small = cv2.resize(
        grey, (max(grey.shape[1] // 8, 1), max(grey.shape[0] // 8, 1)), interpolation=cv2.INTER_AREA
    )
    if float(small.max()) - float(small.min()) < MIN_CONTRAST:
        return found  # a flat (blank or noise-only) frame: nothing to find, and noise is slow to trace
    rows = grey[:: max(grey.shape[0] // 64, 1)]
    if np.median(np.abs(np.diff(rows.astype(np.int16), axis=1))) > MAX_ROUGHNESS:
        return found  # mostly noise or fine texture: millions of contours and no finder pattern
    _, otsu = cv2.threshold(grey, 0, 255, cv2.THRESH_BINARY_INV | cv2.THRESH_OTSU)
    block = max(15, (min(grey.shape) // 16) | 1)
    adaptive = cv2.adaptiveThreshold(grey, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV, block, 7)
    for binary in (otsu, adaptive):
        for corners, n in _candidates_from_finders(grey, _finder_quads(binary)):
            if any(
                np.linalg.norm(corners.mean(axis=0) - c.mean(axis=0)) < 0.2 * np.ptp(c, axis=0).max()
                for c, _, _, _ in found
            ):
                continue
            text, matrix, corners = decode_rectified(grey, corners, n) if decode else (None, None, corners)
            found.append((corners, n, text, matrix))
        if found:
            break
    return found
