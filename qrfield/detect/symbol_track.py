"""The whole-symbol fit kept warm from frame to frame: inverse compositional, for tracking.

:func:`qrfield.detect.symbol_fit.fit_symbol` evaluates its model (and the model's derivatives) at
every pixel it samples, on every iteration: accurate, but some milliseconds of numpy work. A
tracked code changes little from one frame to the next, so here the model is evaluated once, at
fixed points of the symbol (module coordinates near its known edges: the *template*), and each
frame only maps those points into the image, samples the image there (Lanczos, cv2.remap on a
float copy) and solves a small linear system (Baker and Matthews' inverse compositional
Lucas-Kanade: the Jacobian lives in the symbol's coordinates and does not change):

    residual(x) = I(W(x)) - (A(x) - B(x) T(x)),   W = lens o H,   H <- H o dH^-1

with T the template's darkness, A and B the lighting (linear across the code, fitted with the
geometry), H the homography from module coordinates to ideal pixels and dH the increment of the
step (8 terms). The template is rebuilt when the code's scale in the image, or the edge width,
has changed by more than TEMPLATE_TOLERANCE since it was made, and when the tracker asks (a
settled fit that misfits its aged template: :meth:`WarmFit.forget_template`). Huber weights at
1.5 robust residual scales, as in the full fit. The corners' covariance follows from the last
step's normal matrix, as there.

Sampling the image between pixel centres smooths it a little depending on where the points fall
(and cv2.remap rounds the positions to 1/32 px); over hundreds of points at all phases this
averages out (measured on the moving sequences of ``qrfield benchmark detect``: docs/detection.md).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from qrfield.detect.lens import Lens
from qrfield.detect.symbol import QUIET_RINGS
from qrfield.detect.symbol_fit import (
    HUBER_K,
    MIN_CONTRAST,
    MIN_EDGE_PX,
    FitState,
    SymbolFit,
    _Darkness,
    _layout,
    _params_from_g,
    _Problem,
    _windows,
    corner_covariance,
)
from qrfield.homography import square_to_quad_floats, usable_floats
from qrfield.linalg import small_inverse, small_solve

#: Template points (module coordinates near the known edges); see tracking.TRACK_ITERATIONS.
TEMPLATE_POINTS = 800
#: Relative change of the code's scale (px per module along u or v) or of the edge width after
#: which the template is made again.
TEMPLATE_TOLERANCE = 0.15
#: Module coordinates of V1..V4 per module of the symbol.
_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
_FLT_EPSILON = float(np.finfo(np.float32).eps)
#: How the image is sampled between pixel centres: Lanczos at the layout's points (the tracker's:
#: better than cubic there, issue 13h), cubic at pixel centres (Lanczos, whose cv2.remap weights
#: come from a table at 1/32 px, drifted there by 0.02-0.03 px over a few steps: measured).
LAYOUT_INTERPOLATION = cv2.INTER_LANCZOS4
PIXEL_INTERPOLATION = cv2.INTER_CUBIC


def _scales(h: list[float], n: int) -> tuple[float, float]:
    """px per module along u and along v at the symbol's centre for homography ``h`` (module -> px,
    9 floats row by row; Python floats: this runs on every tracked frame)."""
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = h

    def mapped(u: float, v: float) -> tuple[float, float]:
        w = h20 * u + h21 * v + h22
        w = 1.0 / w if abs(w) > _FLT_EPSILON else 0.0  # as cv2.perspectiveTransform
        return (h00 * u + h01 * v + h02) * w, (h10 * u + h11 * v + h12) * w

    c = n / 2
    x0, y0 = mapped(c, c)
    xu, yu = mapped(c + 1, c)
    xv, yv = mapped(c, c + 1)
    return math.hypot(xu - x0, yu - y0), math.hypot(xv - x0, yv - y0)


def _inv_grad(uv: np.ndarray, h: np.ndarray, lens: Lens | None) -> np.ndarray:
    """(2, k) px per module unit across u and across v edges at module points ``uv`` (k, 2) for
    the homography ``h`` (3, 3, module -> ideal px), through the lens: the edges are blurred in the
    image's pixels, not the ideal ones (as the full fit's samples). Component by component: the
    rows of the inverse of d px / d uv are the gradients of u and v."""
    u, v = uv[:, 0], uv[:, 1]
    w = 1.0 / (h[2, 0] * u + h[2, 1] * v + h[2, 2])
    x = (h[0, 0] * u + h[0, 1] * v + h[0, 2]) * w
    y = (h[1, 0] * u + h[1, 1] * v + h[1, 2]) * w
    a, b = (h[0, 0] - x * h[2, 0]) * w, (h[0, 1] - x * h[2, 1]) * w  # d x / d (u, v)
    c, d = (h[1, 0] - y * h[2, 0]) * w, (h[1, 1] - y * h[2, 1]) * w  # d y / d (u, v)
    if lens is not None and lens.distorted:
        j = lens.distort_jacobian(np.column_stack([x, y]))
        j00, j01, j10, j11 = j[:, 0, 0], j[:, 0, 1], j[:, 1, 0], j[:, 1, 1]
        a, b, c, d = j00 * a + j01 * c, j00 * b + j01 * d, j10 * a + j11 * c, j10 * b + j11 * d
    det = np.abs(a * d - b * c)
    # grad u = (d, -b) / det, grad v = (-c, a) / det: their lengths' inverses.
    out = np.empty((2, len(u)))
    np.divide(det, np.hypot(d, b), out=out[0])
    np.divide(det, np.hypot(c, a), out=out[1])
    return out


def pixel_samples(
    cells: np.ndarray,
    h: np.ndarray,
    edge_px: float,
    budget: int,
    lens: Lens,
    grey: np.ndarray,
    offset: tuple[int, int],
) -> _Problem:
    """The full fit's samples at homography ``h`` (3, 3, module -> ideal camera px) for edge width
    ``edge_px``: at most ``budget`` pixel centres of ``grey`` (a crop at ``offset``) near the known
    edges of ``cells`` (qrfield.detect.symbol_fit._Problem, in its normalisation: the code's
    centre and half diagonal in ideal pixels)."""
    n = cells.shape[0] - 2 * QUIET_RINGS
    corners = cv2.perspectiveTransform((_SQUARE * n).reshape(1, 4, 2), h).reshape(4, 2)
    origin = corners.mean(axis=0)
    scale = float(np.linalg.norm(corners[2] - corners[0])) / 2.0
    # The full fit's parameters: module coordinates of normalised ideal pixels (x - origin) / scale.
    g = np.linalg.inv(h) @ np.array([[scale, 0.0, origin[0]], [0.0, scale, origin[1]], [0.0, 0.0, 1.0]])
    band = 1.5 * edge_px + 1.0
    return _Problem(grey, lens, cells, _params_from_g(g), (origin, scale), edge_px, band, budget, offset)


class _Template:
    """The model evaluated at fixed symbol points for one scale and edge width.

    The points are module coordinates near the known edges: spread by the layout
    (:meth:`_Layout.candidates`, the tracker's), or, with ``samples`` (a cold fit's last stage,
    :mod:`qrfield.detect.symbol_cold`), the module coordinates of those pixel centres of the image
    at the samples' own geometry (:func:`pixel_samples`, the full fit's samples): the first step
    then samples the image exactly at its pixels, later ones within the steps' move of them; the
    lighting basis is then the full fit's (normalised image coordinates: a light ramp across the
    image is linear there, not in the module coordinates of a tilted code; that left fits 0.02-0.03
    px off the full fit's). ``free_edge`` adds the model's derivative with respect to the edge width
    (the edge width is then fitted, to first order about ``edge_px``).
    """

    def __init__(
        self,
        cells: np.ndarray,
        h: np.ndarray,
        edge_px: float,
        points: int,
        lens: Lens | None = None,
        samples: _Problem | None = None,
        free_edge: bool = False,
    ) -> None:
        size = cells.shape[0]
        n = size - 2 * QUIET_RINGS
        self.scales = _scales(h.ravel().tolist(), n)
        self.edge_px = edge_px
        self.free_edge = free_edge
        module_px = 0.5 * (self.scales[0] + self.scales[1])
        r = 1 if edge_px / max(module_px, 1e-6) < 0.4 else 2
        band = 1.5 * edge_px + 1.0
        # Per-point terms with the points on the last axis (as the full fit's: every operation on
        # contiguous runs; the Jacobian is filled row by row, transposed).
        if samples is not None:
            uv_t = samples.uv_t  # the pixels' module coordinates at the samples' geometry
            dark = _Darkness(uv_t - samples.corner_t, samples.inv_grad_t, samples.colour_t, edge_px)
            xy_t = samples.p_t
        else:
            layout = _layout(cells, r)
            pts = layout.candidates(max(1, min(8, round(module_px))), max(module_px, 0.05), band, points)
            if len(pts) > points:
                pts = pts[np.linspace(0, len(pts) - 1, points).astype(np.int64)]
            ok, colour_t, corner = _windows(layout, pts, r)
            uv = pts[ok]
            uv_t = np.ascontiguousarray(uv.T)
            dark = _Darkness(np.ascontiguousarray((uv - corner).T), _inv_grad(uv, h, lens), colour_t, edge_px)
            xy_t = uv_t / (n / 2.0) - 1.0
        t = dark.value
        (du, dv), dts = dark.derivatives(free_edge)
        k = len(t)
        self.t = t
        #: dT/ds at the points (the edge width's derivative), None without ``free_edge``
        self.dts = dts
        u, v = uv_t
        # -dT / d dH, dH = I + [[d0 d1 d2], [d3 d4 d5], [d6 d7 0]] at the identity: dT/du (u, v, 1,
        # 0, 0, 0, -u u, -u v) + dT/dv (0, 0, 0, u, v, 1, -u v, -v v).
        radial = du * u + dv * v
        self.neg_geo_t = neg = np.empty((8, k))
        np.multiply(du, u, out=neg[0])
        np.multiply(du, v, out=neg[1])
        neg[2] = du
        np.multiply(dv, u, out=neg[3])
        np.multiply(dv, v, out=neg[4])
        neg[5] = dv
        np.multiply(radial, -u, out=neg[6])
        np.multiply(radial, -v, out=neg[7])
        np.negative(neg, out=neg)
        self.n = n
        # Lighting basis 1, x, y as rows (3, k): normalised module coordinates, or the samples'
        # (see above); (A, B) = light.reshape(2, 3) @ basis_t in one product.
        self.basis_t = basis = np.empty((3, k))
        basis[0] = 1.0
        basis[1:] = xy_t
        # The Jacobian's buffer, transposed (14, k): each parameter's column is one contiguous row,
        # so filling the geometry's rows (-B dT/d dH, each step) and forming J^T W J cost half as
        # much as on (k, 14) (measured). The lighting's rows (basis, -T basis) do not change; with
        # the edge width free its row is the 9th (15 rows).
        self.light_row = 9 if free_edge else 8
        self.jac_t = np.empty((self.light_row + 6, k))
        self.jac_t[self.light_row : self.light_row + 3] = basis
        np.multiply(basis, -t, out=self.jac_t[self.light_row + 3 :])
        self.uv = uv_t.T
        self.uv_cv = np.ascontiguousarray(self.uv.reshape(1, -1, 2))
        # float32 points: cv2.perspectiveTransform then gives the float32 map cv2.remap takes.
        self.uv_cv32 = self.uv_cv.astype(np.float32)
        # The points' box in module coordinates: where a homography keeps w > 0 over it, the box's
        # image is the convex quad of its mapped corners, so those four inside the crop put every
        # point inside (a test in floats instead of two passes over the (k, 2) pixels).
        self.box = (float(u.min()), float(v.min()), float(u.max()), float(v.max()))

    def fits(self, h: list[float], edge_px: float) -> bool:
        """Whether this template serves homography ``h`` (9 floats) and edge width ``edge_px``."""
        su, sv = _scales(h, self.n)
        change = max(abs(su / self.scales[0] - 1.0), abs(sv / self.scales[1] - 1.0))
        return bool(change < TEMPLATE_TOLERANCE and abs(edge_px / self.edge_px - 1.0) < TEMPLATE_TOLERANCE)


def _maps_inside(h: list[float], box: tuple[float, float, float, float], width: float, height: float) -> bool:
    """The homography ``h`` (9 floats) maps the module box (u0, v0, u1, v1) into [0, width] x
    [0, height] with w > 0 at its four corners (so over all of it: w is linear in u, v)."""
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = h
    u0, v0, u1, v1 = box
    for u, v in ((u0, v0), (u1, v0), (u1, v1), (u0, v1)):
        w = h20 * u + h21 * v + h22
        if not w > 0.0:
            return False
        x, y = (h00 * u + h01 * v + h02) / w, (h10 * u + h11 * v + h12) / w
        if not (0.0 <= x <= width and 0.0 <= y <= height):
            return False
    return True


def _compose_inverse(h: list[float], delta: np.ndarray) -> list[float] | None:
    """H o dH^-1 (9 floats, row by row) for the step dH = I + [[d0 d1 d2], [d3 d4 d5], [d6 d7 0]]
    (delta[:8]), None when dH is singular or the result not finite (in Python floats: a 3x3
    inverse by its adjugate)."""
    d0, d1, d2, d3, d4, d5, d6, d7 = delta[:8].tolist()
    a, b, c = 1.0 + d0, d1, d2
    d, e, f = d3, 1.0 + d4, d5
    g, hh, i = d6, d7, 1.0
    co = (e * i - f * hh, f * g - d * i, d * hh - e * g)
    det = a * co[0] + b * co[1] + c * co[2]
    if not (abs(det) > 1e-12 and math.isfinite(det)):
        return None
    q = 1.0 / det
    i00, i01, i02 = co[0] * q, (c * hh - b * i) * q, (b * f - c * e) * q
    i10, i11, i12 = co[1] * q, (a * i - c * g) * q, (c * d - a * f) * q
    i20, i21, i22 = co[2] * q, (b * g - a * hh) * q, (a * e - b * d) * q
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = h
    out = [
        h00 * i00 + h01 * i10 + h02 * i20,
        h00 * i01 + h01 * i11 + h02 * i21,
        h00 * i02 + h01 * i12 + h02 * i22,
        h10 * i00 + h11 * i10 + h12 * i20,
        h10 * i01 + h11 * i11 + h12 * i21,
        h10 * i02 + h11 * i12 + h12 * i22,
        h20 * i00 + h21 * i10 + h22 * i20,
        h20 * i01 + h21 * i11 + h22 * i21,
        h20 * i02 + h21 * i12 + h22 * i22,
    ]
    if not math.isfinite(sum(out)):
        return None
    return out


def _largest_move(before: list[float], after: list[float], n: float) -> float:
    """The largest distance (px) between the corners V1..V4 of an n-module symbol through the
    homographies ``before`` and ``after`` (9 floats each)."""
    largest = 0.0
    for u, v in ((0.0, 0.0), (n, 0.0), (n, n), (0.0, n)):
        moved = []
        for h00, h01, h02, h10, h11, h12, h20, h21, h22 in (before, after):
            q = 1.0 / (h20 * u + h21 * v + h22)
            moved.append(((h00 * u + h01 * v + h02) * q, (h10 * u + h11 * v + h12) * q))
        (x0, y0), (x1, y1) = moved
        largest = max(largest, math.hypot(x1 - x0, y1 - y0))
    return largest


def _shifted(h: list[float], sx: float, sy: float) -> list[float]:
    """T o H for the translation T by (-sx, -sy): H's pixels in a crop whose origin is at (sx, sy)."""
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = h
    return [
        h00 - sx * h20, h01 - sx * h21, h02 - sx * h22,
        h10 - sy * h20, h11 - sy * h21, h12 - sy * h22,
        h20, h21, h22,
    ]  # fmt: skip


@functools.lru_cache(maxsize=64)
def _corner_warp_jacobian(n: int) -> np.ndarray:
    """d W(m_k; dH) / d dH at the identity for the corners V1..V4 of an n-module symbol, (4, 2, 8)
    (see _Template: dH's terms d0..d7); read-only, one per module count."""
    m = _SQUARE * n
    u, v = m[:, 0], m[:, 1]
    zero, one = np.zeros(4), np.ones(4)
    out = np.stack(
        [
            np.column_stack([u, v, one, zero, zero, zero, -u * u, -u * v]),
            np.column_stack([zero, zero, zero, u, v, one, -u * v, -v * v]),
        ],
        axis=1,
    )
    out.setflags(write=False)
    return out


class WarmFit:
    """The warm whole-symbol fit of one tracked code (its cell map and lens fixed).

    ``pixel_centred``: the template's points are the image's pixel centres near the edges where
    the template is made (a cold fit's last stage: :func:`pixel_samples`, kept as ``samples``); that
    template belongs to that image and crop and is not made again until :meth:`forget_template`.
    ``free_edge``: the edge width is fitted too (else it stays the state's).
    """

    def __init__(
        self,
        cells: np.ndarray,
        lens: Lens | None = None,
        points: int = TEMPLATE_POINTS,
        pixel_centred: bool = False,
        free_edge: bool = False,
    ) -> None:
        self.cells = cells
        self.n = cells.shape[0] - 2 * QUIET_RINGS
        self.lens = lens or Lens(None)
        self.points = points
        self.pixel_centred = pixel_centred
        self.free_edge = free_edge
        #: the pixel-centred template's samples (qrfield.detect.symbol_fit._Problem), else None
        self.samples: _Problem | None = None
        self._template: _Template | None = None
        self._dw = _corner_warp_jacobian(self.n)

    def _corners(self, h: list[float]) -> np.ndarray | None:
        """Corners V1..V4 (4, 2) through the homography ``h`` (9 floats) and, when distorted,
        the lens (ideal pixels to the camera's); None when not finite."""
        n = self.n
        h00, h01, h02, h10, h11, h12, h20, h21, h22 = h
        points = []
        for u, v in ((0.0, 0.0), (n, 0.0), (n, n), (0.0, n)):
            q = 1.0 / (h20 * u + h21 * v + h22)
            points.append([(h00 * u + h01 * v + h02) * q, (h10 * u + h11 * v + h12) * q])
        if not math.isfinite(sum(sum(p) for p in points)):
            return None
        corners = np.array(points)
        return self.lens.distort(corners) if self.lens.distorted else corners

    def forget_template(self) -> None:
        """Make the template again at the next fit (whatever its scale)."""
        self._template = None
        self.samples = None

    def fit(
        self,
        grey: np.ndarray,
        predicted_px: np.ndarray,
        state: FitState,
        offset: tuple[int, int] = (0, 0),
        iterations: int = 2,
        settle_px: float = 0.0,
        covariance: bool = True,
    ) -> SymbolFit:
        """Corners V1..V4 (pixels of ``grey``, a crop at ``offset`` of the camera's image) from the
        predicted corners and the last frame's edge width and lighting; never raises for content.

        At most ``iterations`` Gauss-Newton steps; with ``settle_px`` > 0 it stops after a step
        that moved no corner by ``settle_px`` or more (a good prediction needs one step).
        ``covariance`` False: ``corners_cov`` is None and the fit's ``residual`` NaN (a stage whose
        answer only starts another: :mod:`qrfield.detect.symbol_cold`).

        The homography, its updates and the corners are kept in Python floats, and through a
        pinhole the crop's offset is folded into the homography (every tracked frame runs this:
        each numpy call on small arrays costs 2-5 us here)."""
        start = np.asarray(predicted_px, dtype=np.float64)
        lens = self.lens
        distorted = lens.distorted
        sx, sy = float(offset[0]), float(offset[1])

        def fail(reason: str) -> SymbolFit:
            return SymbolFit(False, start.copy(), None, reason)

        def _fitted(corners: np.ndarray, corners_cov: np.ndarray | None, residual: float) -> SymbolFit:
            # The fit's answer, from the state the steps below leave (edge, light, robust, k, done).
            return SymbolFit(
                ok=True,
                corners_px=corners,
                corners_cov=corners_cov,
                residual=residual,
                contrast=contrast,
                edge_px=edge,
                samples=k,
                iterations=done,
                state=FitState(edge, light, robust),
            )

        if start.shape != (4, 2):
            raise ValueError(f"predicted corners must be (4, 2) pixels V1..V4, got shape {start.shape}")
        if distorted:
            from qrfield.detect.lens import undistort_pixels

            quad = undistort_pixels(lens.camera, start + np.array([sx, sy])).tolist()
        else:
            quad = [[x + sx, y + sy] for x, y in start.tolist()]
        n = self.n
        h = square_to_quad_floats(float(n), quad)  # module -> ideal camera pixels
        if h is None or not usable_floats(h):
            return fail("degenerate corners")
        edge = state.edge_px
        template = self._template
        if template is None or not (self.pixel_centred or template.fits(h, edge)):
            hm = np.array(h).reshape(3, 3)
            if self.pixel_centred:
                self.samples = pixel_samples(
                    self.cells, hm, edge, self.points, lens, grey, (int(sx), int(sy))
                )
            template = self._template = _Template(
                self.cells, hm, edge, self.points, lens, self.samples, self.free_edge
            )
        if len(template.t) < 60:
            return fail("too few template points")
        image = grey.astype(np.float32)
        hh, ww = grey.shape
        light = np.asarray(state.lighting, dtype=np.float64)
        scale = state.scale if math.isfinite(state.scale) else 2.0
        huber = HUBER_K * scale
        k = len(template.t)
        jac_t = template.jac_t
        t = template.t
        free = template.free_edge
        interpolation = PIXEL_INTERPOLATION if self.pixel_centred else LAYOUT_INTERPOLATION
        first_light = template.light_row  # the lighting's first row of the Jacobian
        # Through a pinhole the iteration runs on the crop's pixels directly (T o H); through a
        # lens on the ideal pixels, distorted and shifted at each step.
        if not distorted:
            h = _shifted(h, sx, sy)
        with np.errstate(all="ignore"):
            done = 0
            for done in range(1, iterations + 1):
                hm = np.array(h).reshape(3, 3)
                inside = None  # all inside, the usual case
                if distorted:
                    px = lens.distort(cv2.perspectiveTransform(template.uv_cv, hm).reshape(-1, 2))
                    px -= (sx, sy)
                    grid = px.astype(np.float32)
                    if px.min() < 0 or (px > (ww - 1, hh - 1)).any():
                        inside = (
                            (px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] <= ww - 1) & (px[:, 1] <= hh - 1)
                        )
                else:
                    grid = cv2.perspectiveTransform(template.uv_cv32, hm)
                    if not _maps_inside(h, template.box, ww - 1, hh - 1):
                        px = grid.reshape(-1, 2)
                        inside = (
                            (px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] <= ww - 1) & (px[:, 1] <= hh - 1)
                        )
                if inside is not None and inside.mean() < 0.9:
                    return fail("the code leaves the region")
                values = cv2.remap(
                    image, grid.reshape(1, -1, 2), None, interpolation, borderMode=cv2.BORDER_REPLICATE
                ).reshape(-1)
                level, b = light.reshape(2, 3) @ template.basis_t  # lighting A and contrast B, (k,) each
                if free:  # the template at this edge width, to first order
                    t = template.t + template.dts * (edge - template.edge_px)
                    np.multiply(template.basis_t, -t, out=jac_t[12:])
                    np.multiply(template.dts, -b, out=jac_t[8])
                resid = values - level + b * t
                # Huber weights (1 within HUBER_K robust scales), none outside the region.
                w = huber / np.maximum(np.abs(resid), huber)
                if inside is not None:
                    w *= inside
                # d model / d dH = -B dT/d dH; d model / d light = (basis, -T basis)
                np.multiply(template.neg_geo_t, b, out=jac_t[:8])
                jw_t = jac_t * w
                normal = jw_t @ jac_t.T
                normal.flat[:: len(normal) + 1] += 1e-9
                try:
                    delta = small_solve(normal, jw_t @ resid, symmetric=True)
                except np.linalg.LinAlgError:
                    return fail("the fit is singular")
                before = h
                h = _compose_inverse(h, delta)
                if h is None:
                    return fail("the fit diverged")
                if free:
                    edge = min(max(edge + float(delta[8]), MIN_EDGE_PX), 6.0)
                light = light + delta[first_light:]
                if settle_px > 0.0 and done < iterations and _largest_move(before, h, n) < settle_px:
                    break
            half = k // 2
            # The noise scale of the covariance and of the next frame's weights: the last samples'
            # residuals, taken before the last step (they also hold what that step corrected,
            # which keeps the std honest for a fit of one step: docs/uncertainty.md).
            robust = max(1.4826 * float(np.partition(np.abs(resid), half)[half]), 0.5)
            # How well the fit explains the image where the last step went, to first order
            # (r - J delta, J = d model / d parameters): what the tracker's checks compare with
            # the track's reference (after one step from a prediction 0.5 px off the samples'
            # own residuals are half as large again).
            contrast = float(light[3])
            if abs(contrast) < MIN_CONTRAST:
                return fail(f"too little contrast ({abs(contrast):.0f} grey levels)")
            if not covariance:
                corners = self._corners(h)
                if corners is None:
                    return fail("the fit diverged")
                return _fitted(corners - (sx, sy) if distorted else corners, None, math.nan)
            fitted = max(1.4826 * float(np.partition(np.abs(resid - delta @ jac_t), half)[half]), 0.5)
            # The corners (ideal pixels through a lens, else the crop's) and d corner / d module.
            h00, h01, h02, h10, h11, h12, h20, h21, h22 = h
            points, dpx = [], []
            for u, v in ((0.0, 0.0), (n, 0.0), (n, n), (0.0, n)):
                q = 1.0 / (h20 * u + h21 * v + h22)
                x, y = (h00 * u + h01 * v + h02) * q, (h10 * u + h11 * v + h12) * q
                points.append([x, y])
                dpx.append(
                    [[(h00 - x * h20) * q, (h01 - x * h21) * q], [(h10 - y * h20) * q, (h11 - y * h21) * q]]
                )
            if not math.isfinite(sum(sum(p) for p in points)):
                return fail("the fit diverged")
            corners_model = np.array(points)
            corners = lens.distort(corners_model) - (sx, sy) if distorted else corners_model
            try:
                cov = robust**2 * small_inverse(normal, symmetric=True)[:8, :8]
            except np.linalg.LinAlgError:
                return fail("the fit is singular")
            # Corner k is H (m_k - dW(m_k) dH) to first order: d corner / d dH = -dpx/dm dW/ddH.
            corners_cov = corner_covariance(-(np.array(dpx) @ self._dw), cov, corners_model, lens)
        if not np.isfinite(corners_cov).all():
            return fail("the fit is singular")
        return _fitted(corners, corners_cov, fitted)
