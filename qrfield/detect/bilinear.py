"""Bilinear sampling of a grey image at arbitrary sub-pixel points."""

from __future__ import annotations

import cv2
import numpy as np


def sample_bilinear(grey: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Grey values at ``points`` (..., 2) = (x, y) pixels, OpenCV convention; NaN outside the image.

    Args:
        grey: (H, W) uint8 image.
        points: (..., 2) float pixel coordinates.

    Returns:
        (...) float64 values, bilinear between pixel centres (in the outer half pixel, the edge
        pixel's value); NaN outside the image, i.e. beyond -0.5 or W - 0.5 (H - 0.5). OpenCV's
        remap computes only the requested points (fixed-point weights of 1/32 px, and with uint8
        input it rounds to whole grey levels: both far below the noise of a camera image).
    """
    shape = points.shape[:-1]
    maps = np.asarray(points, dtype=np.float32).reshape(1, -1, 2)
    if maps.shape[1] == 0:
        return np.zeros(shape)
    h, w = grey.shape
    out = cv2.remap(grey, maps, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out = out.reshape(-1).astype(np.float64)
    x, y = maps[0, :, 0], maps[0, :, 1]
    outside = ~((x >= -0.5) & (y >= -0.5) & (x <= w - 0.5) & (y <= h - 0.5))  # NaN counts as outside
    if outside.any():
        out[outside] = np.nan
    return out.reshape(shape)
