"""Bilinear sampling of a grey image at arbitrary sub-pixel points."""

from __future__ import annotations

import cv2
import numpy as np

#: Up to this many points, gathering four pixels each in numpy beats converting a region for remap.
SMALL_SET = 256


def _gather(grey: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear values at (x, y) by gathering the four neighbouring pixels; NaN outside the image."""
    h, w = grey.shape
    inside = (x >= -0.5) & (y >= -0.5) & (x <= w - 0.5) & (y <= h - 0.5)
    xs = np.clip(np.where(inside, x, 0.0), 0.0, w - 1.0)  # the outer half pixel takes the edge value
    ys = np.clip(np.where(inside, y, 0.0), 0.0, h - 1.0)
    x0 = np.minimum(xs.astype(np.intp), max(w - 2, 0))
    y0 = np.minimum(ys.astype(np.intp), max(h - 2, 0))
    fx, fy = xs - x0, ys - y0
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    # float before subtracting: uint8 would wrap
    v00 = grey[y0, x0].astype(np.float64)
    v01 = grey[y0, x1].astype(np.float64)
    v10 = grey[y1, x0].astype(np.float64)
    v11 = grey[y1, x1].astype(np.float64)
    top = v00 + fx * (v01 - v00)
    bottom = v10 + fx * (v11 - v10)
    return np.where(inside, top + fy * (bottom - top), np.nan)


def sample_bilinear(grey: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Grey values at ``points`` (..., 2) = (x, y) pixels, OpenCV convention; NaN outside the image.

    Args:
        grey: (H, W) uint8 or float32 image.
        points: (..., 2) float pixel coordinates.

    Returns:
        (...) float64 values, bilinear between pixel centres (in the outer half pixel, the edge
        pixel's value); NaN outside the image, i.e. beyond -0.5 or W - 0.5 (H - 0.5).
    """
    shape = points.shape[:-1]
    flat = points.reshape(-1, 2)
    if flat.shape[0] == 0:
        return np.zeros(shape)
    h, w = grey.shape
    x, y = flat[:, 0], flat[:, 1]
    x_min, x_max, y_min, y_max = x.min(), x.max(), y.min(), y.max()  # per column: fast, unlike axis=0
    if not (np.isfinite(x_min) and np.isfinite(x_max) and np.isfinite(y_min) and np.isfinite(y_max)):
        return np.full(shape, np.nan)
    if flat.shape[0] <= SMALL_SET:
        return _gather(grey, x, y).reshape(shape)
    x0, y0 = max(int(np.floor(x_min)) - 1, 0), max(int(np.floor(y_min)) - 1, 0)
    x1, y1 = min(int(np.ceil(x_max)) + 2, w), min(int(np.ceil(y_max)) + 2, h)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return np.full(shape, np.nan)
    # Only the region the points need is converted to float (cheap for a code in a large frame).
    roi = np.ascontiguousarray(grey[y0:y1, x0:x1], dtype=np.float32)
    maps = np.empty((1, flat.shape[0], 2), dtype=np.float32)
    maps[0, :, 0] = x - x0
    maps[0, :, 1] = y - y0
    # Replicating the border only matters at the image's own border (the ROI has a margin elsewhere).
    out = cv2.remap(roi, maps, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out = out.reshape(-1).astype(np.float64)
    if x_min < -0.5 or y_min < -0.5 or x_max > w - 0.5 or y_max > h - 0.5:
        out[(x < -0.5) | (y < -0.5) | (x > w - 0.5) | (y > h - 0.5)] = np.nan
    return out.reshape(shape)
