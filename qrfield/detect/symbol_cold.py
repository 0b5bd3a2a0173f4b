"""The whole-symbol fit from a backend's corners by inverse composition: a cold detection's refinement.

:func:`qrfield.detect.symbol_fit.fit_symbol` evaluates its model, and the model's derivatives, at
every sampled pixel on every Levenberg-Marquardt trial: about 14 evaluations and three sample sets
for a fit from a backend's corners (12-20 ms at 640x480 on the build machine, most of a cold
detection: docs/detection.md, "Speed"). Here the tracker's machinery
(:class:`qrfield.detect.symbol_track.WarmFit`: the model evaluated once at fixed points, each step
a resampling of the image and a small linear solve) does the same work from a backend's corners:

1. :func:`coarse_fit`: a template of the blurred model (edge width at least 1.5 px or a third of a
   module, as the full fit's coarse stage) at COARSE_POINTS points of the layout, from the
   backend's corners (about a pixel off, V3 sometimes several); the lighting starts from the
   pattern check's dark and light levels. This brings the corners within a few tenths of a pixel.
2. The caller confirms the decoded module matrix there (:func:`qrfield.detect.detector.confirmed_matrix`).
3. :func:`fine_fit`: a template of the sharp model at the image's own pixel centres near the
   known edges (the full fit's samples, FINE_POINTS of them) with the edge width free: the first
   step samples the image at its pixels exactly, later steps within their move of them; when the
   edge width moved by more than the template's tolerance, once more on a template made at the
   new width. The corners' covariance comes from the last step's normal matrix, as the tracker's.

Measured against the full fit on the hard set and the real photos (docs/detection.md, "Speed"):
the same corners to about 0.003 px in median, at a fifth of the cost. Where this does not hold
(a corner that moves far, a matrix that does not agree, a fit that does not converge) the detector
falls back to the edge lines and the full fit (:meth:`qrfield.detect.detector.Detector.refine`).
"""

from __future__ import annotations

import math

import numpy as np

from qrfield.detect.lens import Lens
from qrfield.detect.symbol import QUIET_RINGS
from qrfield.detect.symbol_fit import START_EDGE_PX, FitState, SymbolFit, polish
from qrfield.detect.symbol_track import WarmFit
from qrfield.geometry import shortest_module_px

#: Template points, Gauss-Newton steps (at most) and the move (px) below which a stage has settled.
COARSE_POINTS = 400
COARSE_ITERATIONS = 3
COARSE_SETTLE_PX = 0.05
FINE_POINTS = 1000
FINE_ITERATIONS = 3
FINE_SETTLE_PX = 0.01
#: Most Gauss-Newton steps of the full model at the end, and the largest corner move (px) of the
#: last one: a step that still moves a corner further is taken again, and a fit still moving
#: after POLISH_STEPS is not trusted (the full fit runs). On steep views the template's answer
#: was 0.3-0.6 px off where one step brought it within 0.03 px (or, from a poor start, not).
POLISH_STEPS = 3
POLISH_SETTLE_PX = 0.05
#: Modules of margin around the corners in the crop the fits work on (the quiet zone's first
#: rings, the coarse model's wide edges, a corner a module or two off).
CROP_MODULES = 4.0


def crop_around(
    shape: tuple[int, int], corners_px: np.ndarray, modules: int
) -> tuple[int, int, int, int] | None:
    """The region (x0, y0, x1, y1) of an image of ``shape`` (H, W) around corners V1..V4 (4, 2) px
    of a code of ``modules`` per side that the fits need; None when it is too small to fit."""
    h, w = shape
    size = float(np.ptp(corners_px, axis=0).max())
    margin = CROP_MODULES * size / max(modules, 1) + 8.0
    x0, y0 = (max(int(v), 0) for v in np.floor(corners_px.min(axis=0) - margin))
    x1 = min(math.ceil(float(corners_px[:, 0].max()) + margin) + 1, w)
    y1 = min(math.ceil(float(corners_px[:, 1].max()) + margin) + 1, h)
    if x1 - x0 < 21 or y1 - y0 < 21:
        return None
    return x0, y0, x1, y1


def coarse_fit(
    grey: np.ndarray,
    corners_px: np.ndarray,
    cells: np.ndarray,
    lens: Lens,
    light: float,
    dark: float,
    offset: tuple[int, int] = (0, 0),
) -> SymbolFit:
    """Stage 1: corners V1..V4 (pixels of ``grey``, a crop at ``offset`` of the camera's image)
    from a backend's corners (4, 2) px, with the blurred model of ``cells``; ``light`` and ``dark``
    (grey levels, as seen) start the lighting. Never raises for image content (ok False)."""
    n = cells.shape[0] - 2 * QUIET_RINGS
    # The module along the code's shortest side: a code seen at a steep angle has modules several
    # times as long one way as the other, and a blur sized by the long way washes out the short.
    module_px = shortest_module_px(corners_px, n)
    edge = max(1.5, 0.35 * module_px, START_EDGE_PX)
    start = FitState(edge, np.array([light, 0.0, 0.0, light - dark, 0.0, 0.0]))
    warm = WarmFit(cells, lens, COARSE_POINTS)
    return warm.fit(grey, corners_px, start, offset, COARSE_ITERATIONS, COARSE_SETTLE_PX, covariance=False)


def fine_fit(
    grey: np.ndarray,
    corners_px: np.ndarray,
    cells: np.ndarray,
    lens: Lens,
    state: FitState,
    offset: tuple[int, int] = (0, 0),
) -> SymbolFit:
    """Stage 3: corners V1..V4 and their covariance from corners (4, 2) px of ``grey`` (a crop at
    ``offset``) a few tenths of a pixel off, the sharp model of ``cells`` at the image's pixel
    centres, the edge width fitted from START_EDGE_PX and ``state``'s lighting level and contrast.
    Never raises for image content (ok False).

    A few steps on a template made at the pixel centres where the corners start, then Gauss-Newton
    steps of the full model on the same pixels from there (:func:`qrfield.detect.symbol_fit.polish`,
    until a step moves no corner by POLISH_SETTLE_PX): the model evaluated where the corners now
    are, at the pixel centres exactly, and the covariance. (Further steps on the template sample
    between pixels, where cv2.remap rounds the positions to 1/32 px: after a common sub-pixel move
    every sample rounds alike, and the corners drifted 0.01-0.03 px: measured.)"""
    warm = WarmFit(cells, lens, FINE_POINTS, pixel_centred=True, free_edge=True)
    # The lighting's level and contrast carry over; its slopes do not (the coarse template's basis
    # is the module coordinates, this one's the image's).
    light = np.asarray(state.lighting, dtype=np.float64)
    begin = FitState(START_EDGE_PX, np.array([light[0], 0.0, 0.0, light[3], 0.0, 0.0]), state.scale)
    fit = warm.fit(grey, corners_px, begin, offset, FINE_ITERATIONS, COARSE_SETTLE_PX, covariance=False)
    samples = warm.samples
    if not fit.ok or fit.state is None or samples is None:
        return fit
    for _ in range(POLISH_STEPS):
        last = fit.corners_px
        fit = polish(samples, last, fit.state, lens, offset)
        if not fit.ok or fit.state is None:
            return fit
        if float(np.abs(fit.corners_px - last).max()) < POLISH_SETTLE_PX:
            return fit
    # Still moving: the template's answer was not near one the full model holds.
    return SymbolFit(False, np.asarray(corners_px, dtype=np.float64).copy(), None, "the fit does not settle")
