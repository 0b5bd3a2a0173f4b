"""The ``small`` backend: codes whose modules are 1.2-3 px, blurred, that the other backends miss.

At such sizes the finder patterns' one-module rings (1.2-3 px) are washed out by a blur of about
a module, so neither zxing-cpp nor the contour locator (:mod:`qrfield.detect.finders`) sees the
nested dark-light-dark squares. Here:

1. *Busy regions*: a code is a patch of many edges on a smooth card. The gradient magnitude,
   averaged over 9 x 9 px at half resolution, is thresholded (at 30 % of its 99th percentile,
   at least MIN_EDGE_LEVEL) and closed; its connected blobs of QR-like size and aspect are the
   regions, the largest first (at most MAX_REGIONS).
2. Each region, with a margin, is upscaled UPSCALE times (bicubic) and sharpened (unsharp mask
   of SHARPEN times the difference to a blur of one source pixel), which restores the rings'
   contrast enough for the contour locator; its corners and module count come back to the
   image's pixels, with the text when zxing-cpp reads the rectified symbol there.

Codes located but not read are read by :mod:`qrfield.detect.reading` once their fixed patterns
are fitted (:meth:`qrfield.detect.detector.Detector.accept`).
"""

from __future__ import annotations

import cv2
import numpy as np

#: Most regions searched per image, and their size range in px (codes of 2-3 px modules and more
#: are found by the other backends; a small code with its quiet zone is at most this big).
MAX_REGIONS = 4
MIN_REGION_PX = 16
MAX_REGION_PX = 240
#: Least mean gradient magnitude (Sobel, grey levels per px, 9 x 9 average) of a region.
MIN_EDGE_LEVEL = 40.0
#: Upscaling factor and unsharp-mask strength of a region.
UPSCALE = 3
SHARPEN = 4.0


#: The last image's busy blobs (busy_blobs): the small and steep backends both ask for them.
_LAST_BLOBS: list[tuple[np.ndarray, tuple[int, np.ndarray, np.ndarray]]] = []


def busy_blobs(grey: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """The connected blobs of :func:`busy_mask` (cv2.connectedComponentsWithStats at half
    resolution: count, (H // 2, W // 2) int32 labels, (count, 5) stats x, y, w, h, area). The last
    image's are kept (with a copy of the image, compared in full): the small and steep backends
    of one detection share them."""
    if _LAST_BLOBS:
        seen, blobs = _LAST_BLOBS[0]
        if seen.shape == grey.shape and np.array_equal(seen, grey):
            return blobs
    count, labels, stats, _ = cv2.connectedComponentsWithStats(busy_mask(grey))
    blobs = (int(count), labels, stats)
    _LAST_BLOBS[:] = [(grey.copy(), blobs)]
    return blobs


def busy_mask(grey: np.ndarray) -> np.ndarray:
    """(H // 2, W // 2) uint8 mask (1 = busy) at half resolution: the gradient magnitude (Sobel),
    averaged over 5 x 5 half px, above 30 % of its 99th percentile (at least MIN_EDGE_LEVEL),
    closed by 4 x 4."""
    half = cv2.resize(
        grey, (max(grey.shape[1] // 2, 1), max(grey.shape[0] // 2, 1)), interpolation=cv2.INTER_AREA
    )
    g = half.astype(np.float32)
    magnitude = cv2.magnitude(
        cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    )
    level = cv2.boxFilter(magnitude, -1, (5, 5))
    sample = level[::3, ::3].ravel()
    high = float(np.partition(sample, int(0.99 * (sample.size - 1)))[int(0.99 * (sample.size - 1))])
    mask = (level > max(MIN_EDGE_LEVEL, 0.3 * high)).astype(np.uint8)
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((4, 4), np.uint8))
    return mask


def busy_regions(grey: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Boxes (x0, y0, x1, y1) px of patches dense in edges, of a code's size, the largest first."""
    count, _, stats = busy_blobs(grey)
    boxes = []
    for x, y, w, h, area in stats[1:count]:
        w2, h2 = 2 * int(w), 2 * int(h)
        if min(w2, h2) < MIN_REGION_PX or max(w2, h2) > MAX_REGION_PX or max(w2, h2) > 3 * min(w2, h2):
            continue
        boxes.append((int(area), (2 * int(x), 2 * int(y), 2 * int(x) + w2, 2 * int(y) + h2)))
    boxes.sort(key=lambda item: -item[0])
    return [box for _, box in boxes[:MAX_REGIONS]]


def sharpened(grey: np.ndarray, factor: int = UPSCALE, strength: float = SHARPEN) -> np.ndarray:
    """``grey`` upscaled ``factor`` times (bicubic) and sharpened: an unsharp mask against a blur of
    one source px (blurred before upscaling: the same at a ninth of the cost)."""
    g = grey.astype(np.float32)
    big = cv2.resize(g, None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC)
    soft = cv2.resize(
        cv2.GaussianBlur(g, (0, 0), 1.0), None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC
    )
    return np.clip(cv2.addWeighted(big, 1.0 + strength, soft, -strength, 0.0), 0, 255).astype(np.uint8)


def locate_small(grey: np.ndarray) -> list[tuple[np.ndarray, int, str | None, np.ndarray | None]]:
    """Codes in the busy regions of ``grey``: (corners V1..V4 px, modules, text or None, decoded
    module matrix or None), as :func:`qrfield.detect.finders.locate_by_finders` gives them."""
    from qrfield.detect.finders import locate_by_finders

    h, w = grey.shape
    found: list[tuple[np.ndarray, int, str | None, np.ndarray | None]] = []
    for x0, y0, x1, y1 in busy_regions(grey):
        margin = int(0.25 * max(x1 - x0, y1 - y0)) + 8
        a0, b0 = max(x0 - margin, 0), max(y0 - margin, 0)
        a1, b1 = min(x1 + margin, w), min(y1 + margin, h)
        big = sharpened(np.ascontiguousarray(grey[b0:b1, a0:a1]))
        for corners, n, text, matrix in locate_by_finders(big):
            # pixel centres: x_small = (x_big + 0.5) / factor - 0.5
            here = (corners + 0.5) / UPSCALE - 0.5 + np.array([a0, b0], dtype=np.float64)
            if not any(np.abs(here - other[0]).max() < 2.0 for other in found):
                found.append((here, n, text, matrix))
    return found
