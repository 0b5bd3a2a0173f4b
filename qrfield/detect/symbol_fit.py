"""Corners V1..V4 from the whole symbol: a model of the code's image fitted to the pixels.

The model. Module coordinates (u, v) (V1 = (0, 0), V2 = (n, 0), V3 = (n, n), V4 = (0, n), as in
:mod:`qrfield.detect.patterns`) map to *ideal pixels* (:mod:`qrfield.detect.lens`: the image a
distortion-free pinhole with the same K would see) by a homography, since the code is flat; the
lens then maps ideal pixels to the image. The expected grey level at an image pixel p is

    I(p) = A(p) - B(p) * D(u(p), v(p))

where D is the darkness of the known modules (:mod:`qrfield.detect.symbol`: every fixed pattern,
the quiet zone, and the data modules once decoded) seen through an edge spread of width s px:
each cell contributes its colour times F(u - left) - F(u - right) in u, the same in v, with
F the logistic (1 + tanh(z / s)) / 2 of the distance z in px across the edge, convolved with the
pixel's 1 px footprint (its variance across an edge of any direction).
A(p) (the light level) and B(p) (the contrast) are linear across the code, for uneven lighting;
B < 0 for an inverted code. Any symmetric edge spread places an edge without bias, so the logistic
F stands in for the real one (Gaussian blur, defocus, pixel area), and s is fitted.

The fit. Unknowns: the homography from ideal pixels to module coordinates (8, in coordinates
normalised about the code), s, and the six lighting terms. Samples are image pixel centres (no
interpolation of the image) within a band of about 1.5 s + 1 px around the edges between known
cells of different colour, at most ``budget`` of them (the edges taken in a fixed shuffled order,
so that a subset covers the whole symbol). Levenberg-Marquardt on the residuals I - model, with Huber
weights at 1.5 times a robust residual scale (MAD) so that misread modules, specular spots or
a finger over the code do not pull the corners. Coarse to fine: from a backend's or the edge
fit's corners, first a blurred model (s at least 1.5 px or a third of a module) over a wider band,
then the sharp model with s free. Tracking keeps the fit warm another way
(:mod:`qrfield.detect.symbol_track`).

The uncertainty. The covariance of the parameters is the robust scale squared times the inverse
of the weighted normal matrix, J^T W J; the corners' (4, 2, 2) covariance follows through the
corners' (analytic) derivatives with respect to the homography and the lens, plus a model-error
floor (MODEL_FLOOR_PX).
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from qrfield.detect.lens import Lens
from qrfield.detect.symbol import QUIET_RINGS
from qrfield.homography import Homography
from qrfield.linalg import small_inverse, small_solve

#: Module coordinates of V1..V4.
_UNIT_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
#: Huber threshold in robust residual scales.
HUBER_K = 1.5
#: Most pixels sampled by a fit.
FULL_BUDGET = 1500
#: Most pixels of the coarse stage (it only brings the corners into the fine stage's reach).
COARSE_BUDGET = 600
#: Model error of a corner, px per coordinate, added in quadrature to the covariance from the
#: residual noise (which alone under-covers noise-free views: the model is not the exact optics).
#: Measured on the hard set (docs/detection.md): without it the whitened corner errors have an RMS
#: of 1.17 and 92 % lie within 2; 0.003 px (issue 13a's choice, from the corners alone) gives 1.03
#: and 95 %, but the poses solved from them came out over-confident in their angles (88-91 %
#: within 2 on seeds 2024, 7 and 11): the model's errors are partly shared by the four corners,
#: which the independent floor cannot express. 0.006 px: corners RMS 0.83-0.91 (96-98 % within 2),
#: poses 91-97 % within 2 for every component on those seeds (qrfield benchmark pose, section 3).
MODEL_FLOOR_PX = 0.006
#: The floor as a corner's (2, 2) covariance.
_FLOOR_COV = MODEL_FLOOR_PX**2 * np.eye(2)
_FLOOR_COV.setflags(write=False)
#: Smallest fitted contrast, grey levels (a code is not seen below it).
MIN_CONTRAST = 12.0
#: Row and column in G of each of the 8 parameters (see _g_from_params).
_ENTRY_ROWS = np.array([0, 0, 0, 1, 1, 1, 2, 2])
_ENTRY_COLS = np.array([2, 0, 1, 2, 0, 1, 0, 1])
#: Smallest edge width s, px (the pixel's own footprint is modelled besides).
MIN_EDGE_PX = 0.1
#: Starting edge width s (logistic scale), px: about a 0.6 px blur plus the pixel's area.
START_EDGE_PX = 0.9


@dataclass(frozen=True)
class FitState:
    """What a tracked fit carries to the next frame: edge width s (px), lighting (6 terms) and the
    robust residual scale (grey levels; NaN when not known yet)."""

    edge_px: float
    lighting: np.ndarray
    scale: float = math.nan


@dataclass(frozen=True)
class SymbolFit:
    """Outcome of :func:`fit_symbol`.

    Attributes:
        ok: True when the fit converged to a plausible symbol; else ``reason`` says why.
        corners_px: (4, 2) V1..V4 in image pixels (the starting corners when not ok).
        corners_cov: (4, 2, 2) covariance of each corner, px^2 (None when not ok).
        residual: robust residual scale of the fit, grey levels (noise plus model error).
        start_residual: the same on the same pixels at the starting corners (lighting refitted).
        contrast: fitted contrast B at the code's centre, grey levels (negative: inverted code).
        edge_px: fitted edge width s, px.
        samples: pixels used; iterations: LM iterations done (all stages).
        state: for a warm start on the next frame.
    """

    ok: bool
    corners_px: np.ndarray
    corners_cov: np.ndarray | None
    reason: str = ""
    residual: float = math.nan
    start_residual: float = math.nan
    contrast: float = math.nan
    edge_px: float = math.nan
    samples: int = 0
    iterations: int = 0
    state: FitState | None = None

    @property
    def corners_std_px(self) -> np.ndarray:
        """(4,) RMS radius of each corner's uncertainty, px (sqrt of the covariance's trace)."""
        if self.corners_cov is None:
            return np.full(4, np.nan)
        # In floats: every tracked frame asks (NaN for a negative trace, as np.sqrt gives).
        c = self.corners_cov.reshape(16).tolist()
        traces = (c[0] + c[3], c[4] + c[7], c[8] + c[11], c[12] + c[15])
        return np.array([math.sqrt(t) if t >= 0.0 else math.nan for t in traces])


# ---------------------------------------------------------------------------------------- helpers
def _apply(h: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Homography ``h`` applied to points (k, 2), float64."""
    return cv2.perspectiveTransform(np.asarray(xy, dtype=np.float64).reshape(1, -1, 2), h).reshape(-1, 2)


class _Layout:
    """What the fit needs of one cell map, for windows of 2 r + 1 cells: computed once per map.

    Attributes:
        colour: the cell map flattened, unknown cells 0.
        safe: per flat cell index, True when the window starting there holds only known cells.
        window: flat offsets of a window's cells from its first cell.
        mids, kinds: midpoints (k, 2) in module coordinates of the edges between known cells of
            different colour, and their orientation (0: the edge runs along v, separating cells
            left and right; 1: along u), in a fixed shuffled order so that the first few are
            spread over the whole symbol.
    """

    def __init__(self, cells: np.ndarray, r: int) -> None:
        size = cells.shape[0]
        self.size = size
        m = 2 * r + 1
        known = np.isfinite(cells)
        self.colour = np.where(known, cells, 0.0).ravel()
        # Windows of m x m cells with no unknown cell: an integral image of the unknown ones.
        unknown = np.zeros((size + 1, size + 1), dtype=np.int32)
        np.cumsum(np.cumsum(~known, axis=0, dtype=np.int32), axis=1, out=unknown[1:, 1:])
        full = np.zeros((size, size), dtype=bool)
        span = size - m + 1
        full[:span, :span] = (
            unknown[m:, m:] - unknown[:span, m:] - unknown[m:, :span] + unknown[:span, :span]
        ) == 0
        self.safe = full.ravel()
        self.window = (np.arange(m)[:, None] * size + np.arange(m)[None, :]).ravel()
        q = QUIET_RINGS
        left, right = cells[:, :-1], cells[:, 1:]
        rows, cols = np.nonzero(known[:, :-1] & known[:, 1:] & (left != right))
        vertical = np.column_stack([cols + 1 - q, rows - q + 0.5])
        top, bottom = cells[:-1, :], cells[1:, :]
        rows2, cols2 = np.nonzero(known[:-1, :] & known[1:, :] & (top != bottom))
        horizontal = np.column_stack([cols2 - q + 0.5, rows2 + 1 - q])
        mids = np.concatenate([vertical, horizontal]).astype(np.float64)
        kinds = np.concatenate([np.zeros(len(vertical)), np.ones(len(horizontal))]).astype(np.int8)
        order = _shuffle(len(mids))
        self.mids, self.kinds = mids[order], kinds[order]
        self._candidates: dict[tuple[int, int, int], np.ndarray] = {}

    def candidates(self, per_edge: int, module_px: float, band_px: float, budget: int) -> np.ndarray:
        """Module coordinates (k, 2) of points near the edges: ``per_edge`` along each, every 0.7 px
        across it within +-``band_px``; the first edges of the shuffle, enough for about twice
        ``budget`` pixels. Cached per (per_edge, module size and band to 5 %, budget), and made at
        the module size and band of that 5 % step."""
        key = (per_edge, round(math.log(module_px) * 20), round(math.log(band_px) * 20), budget)
        pts = self._candidates.get(key)
        if pts is not None:
            return pts
        # Made at the key's own module size and band, not the caller's: the points are a function
        # of the key alone, so a hit gives what a miss would make. The fixed patterns' cell map
        # (fixed_cells, cached) and so its layout are shared by every stream: made at the first
        # caller's size, a later stream within the same 5 % got the earlier one's points.
        module_px, band_px = math.exp(key[1] / 20.0), math.exp(key[2] / 20.0)
        along = (np.arange(per_edge) + 0.5) / per_edge - 0.5
        across = np.arange(-band_px, band_px + 1e-9, 0.7) / module_px
        wanted = math.ceil(2.0 * budget / max(len(along) * len(across) * 0.6, 1.0))
        mids, kinds = self.mids[:wanted], self.kinds[:wanted]
        # np.meshgrid's order (np.tile by a broadcast: np.tile's Python wrapper costs a dozen calls)
        a = np.broadcast_to(along, (len(across), len(along))).ravel()
        c = np.repeat(across, len(along))
        # The offsets (du, dv) from an edge's midpoint by its kind: an edge along v (kind 0) has u
        # across it; then every edge's points in one gather and one sum.
        offsets = np.empty((2, len(a), 2))
        offsets[0, :, 0], offsets[0, :, 1] = c, a
        offsets[1, :, 0], offsets[1, :, 1] = a, c
        pts = (mids[:, None, :] + offsets[kinds]).reshape(-1, 2)
        if len(self._candidates) > 32:
            self._candidates.clear()
        self._candidates[key] = pts
        return pts


@functools.lru_cache(maxsize=256)
def _shuffle(count: int) -> np.ndarray:
    """The fixed shuffled order of ``count`` edges (seeded by the count; a Generator costs 50 us)."""
    order = np.random.default_rng(count).permutation(count)
    order.setflags(write=False)
    return order


def _windows(layout: _Layout, uv: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For points at module coordinates ``uv`` (k, 2): which have a window of (2 r + 1)^2 known
    cells around the cell they lie in (k,) bool, those windows' colours (m, m, k') with the points
    on the last axis (as _Darkness takes them: gathered so, no transposed copy) and their first
    boundary in u and v (k', 2) (boundaries lie there + 0 .. 2 r + 1)."""
    size = layout.size
    m = 2 * r + 1
    first = np.floor(uv).astype(np.int64) + (QUIET_RINGS - r)  # the window's first column, row
    inside = ((first >= 0) & (first <= size - m)).all(axis=1)
    start = np.where(inside, first[:, 1] * size + first[:, 0], 0)
    ok = inside & layout.safe[start]
    colour_t = layout.colour[layout.window[:, None] + start[ok][None, :]].reshape(m, m, -1)
    return ok, colour_t, (first[ok] - QUIET_RINGS).astype(np.float64)


_LAYOUTS: dict[tuple[int, int], tuple[np.ndarray, _Layout]] = {}
#: The last few layouts by (r, the map's shape, dtype and bytes); a layout is a pure function of them.
_LAYOUTS_BY_CONTENT: dict[tuple, _Layout] = {}
#: Boundary offsets 0 .. m of a window of m cells, as a column (m + 1, 1) against a trailing axis
#: of points.
_SPANS = {m: np.arange(m + 1, dtype=np.float64)[:, None] for m in (3, 5)}


def _layout(cells: np.ndarray, r: int) -> _Layout:
    """The (cached) layout of a cell map: by the map object, which the callers keep. A map equal
    to a recent one (a code found again, as on a new stream's first frame) shares its cells and
    edges, not its candidates (those are cached to 5 % of the module size: sharing them would let
    the order of earlier fits change a fit)."""
    key = (id(cells), r)
    hit = _LAYOUTS.get(key)
    if hit is not None and hit[0] is cells:
        return hit[1]
    content = (r, cells.shape, cells.dtype.str, cells.tobytes())
    base = _LAYOUTS_BY_CONTENT.get(content)
    if base is None:
        if len(_LAYOUTS_BY_CONTENT) >= 8:
            _LAYOUTS_BY_CONTENT.clear()
        base = _LAYOUTS_BY_CONTENT[content] = _Layout(cells, r)
    layout = copy.copy(base)
    layout._candidates = {}
    if len(_LAYOUTS) > 64:
        _LAYOUTS.clear()
    _LAYOUTS[key] = (cells, layout)
    return layout


def darkness_at(
    uv: np.ndarray,
    corner: np.ndarray,
    inv_grad: np.ndarray,
    colour: np.ndarray,
    edge_px: float,
    derivatives: bool = True,
    edge_derivative: bool = True,
):
    """The model's darkness D (k,) at module coordinates ``uv`` (k, 2) of points whose windows of
    cells start at boundaries ``corner`` (k, 2) with colours ``colour`` (k, m, m) (_windows' transposed),
    ``inv_grad`` (k, 2) px per module unit across u and v edges there, edge width ``edge_px``.
    With ``derivatives`` also (dD/du, dD/dv) (k, 2) and dD/ds (k,) (None without ``edge_derivative``).
    """
    dark = _Darkness(
        np.ascontiguousarray((uv - corner).T),
        np.ascontiguousarray(inv_grad.T),
        np.ascontiguousarray(colour.transpose(1, 2, 0)),
        edge_px,
    )
    if not derivatives:
        return dark.value
    d_uv, d_s = dark.derivatives(edge_derivative)
    return dark.value, d_uv.T, d_s


class _Darkness:
    """The model's darkness at points along the last axis, its derivatives on demand.

    ``offset`` (2, k) = uv - corner, ``inv_grad_t`` (2, k) and ``colour_t`` (m, m, k)
    (colour_t[row, column] = colour[:, row, column]) as :func:`darkness_at`'s arguments transposed:
    points on the last axis keep every operation on contiguous runs of k (the (k, 2, m + 1) layout
    made numpy's loops strided and its small matmul/einsum contractions slow). ``value`` (k,) is
    D; :meth:`derivatives` adds (dD/du, dD/dv) (2, k) and dD/ds (k,) from the same edge terms (the
    fit asks for them only for a step it keeps).
    """

    def __init__(self, offset: np.ndarray, inv_grad_t: np.ndarray, colour_t: np.ndarray, edge_px: float):
        m = colour_t.shape[0]
        k = offset.shape[1]
        # Distance to each boundary in px across it, then F = the logistic of width s convolved
        # with the pixel's 1 px footprint (its variance across any edge direction is 1/12 px^2):
        # F(z) = 1/2 + s/2 [L((z + 1/2) / s) - L((z - 1/2) / s)], L = ln cosh.
        z = (offset[:, None, :] - _SPANS[m]) * inv_grad_t[:, None, :]  # (u|v, m+1 boundaries, k) px
        # In float32 (the transcendental functions are most of the cost; 1e-7 is far below noise).
        inv_s = 1.0 / edge_px
        x = np.empty((2, 2, m + 1, k), dtype=np.float32)  # (z + 1/2 | z - 1/2, u|v, boundary, point)
        np.multiply(z + 0.5, inv_s, out=x[0])
        np.multiply(z - 0.5, inv_s, out=x[1])
        ax = np.abs(x)
        e = np.multiply(ax, -2.0)
        np.exp(e, out=e)
        lc = np.log1p(e)
        lc += ax  # ln cosh x + ln 2 (the constant cancels in differences)
        f = lc[0] - lc[1]
        f *= 0.5 * edge_px
        f += 0.5
        # Each cell's share F(z_j) - F(z_j+1) (u|v, m cells, k); the cell map summed over u per row
        # with the shares across u (m rows, k); D sums those rows with the shares across v.
        share = (f[:, :-1] - f[:, 1:]).astype(np.float64)
        # One contraction over the columns (einsum: half the time of m products and sums).
        rows = np.einsum("rck,ck->rk", colour_t, share[0])
        self.value = (share[1] * rows).sum(axis=0)
        self._terms = (x, e, lc, share, rows, inv_grad_t, colour_t)

    def derivatives(self, edge_derivative: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """(dD/du, dD/dv) (2, k) and dD/ds (k,) (None without ``edge_derivative``)."""
        x, e, lc, share, rows, inv_grad_t, colour_t = self._terms
        m, k = rows.shape
        t = np.subtract(1.0, e)
        t /= 1.0 + e
        np.copysign(t, x, out=t)  # tanh x
        # The shares' derivatives (d/d(u|v) [, d/ds], across u|v, m cells, k) in one buffer: the
        # contractions below then take both at once.
        ds = np.empty((2 if edge_derivative else 1, 2, m, k))
        df = (0.5 * (t[0] - t[1])) * inv_grad_t[:, None, :]  # dF/du (module units)
        np.subtract(df[:, :-1], df[:, 1:], out=ds[0])
        if edge_derivative:
            xt = lc - x * t
            fs = xt[0] - xt[1]  # 2 dF/ds, s in px (the ln 2 cancels here too)
            np.subtract(fs[:, :-1], fs[:, 1:], out=ds[1])
            ds[1] *= 0.5
        rows_d = np.einsum("rck,sck->srk", colour_t, ds[:, 0])  # (d|s, m rows, k)
        by_v = np.einsum("rk,srk->sk", share[1], rows_d)  # dD/du, [dD/ds from u]
        by_rows = np.einsum("srk,rk->sk", ds[:, 1], rows)  # dD/dv, [dD/ds from v]
        d_uv = np.empty((2, k))
        d_uv[0] = by_v[0]
        d_uv[1] = by_rows[0]
        d_s = by_v[1] + by_rows[1] if edge_derivative else None
        return d_uv, d_s


class _Problem:
    """The samples of one fit stage (image pixels near known edges) and the model on them.

    What does not change within a stage is computed once here: the pixels, their normalised ideal
    coordinates, the cells around each (a window of 2R + 1 cells each way about the cell the pixel
    starts in: R = 1 when edges are sharp against the module size, else 2) and the edge width's
    scale factors |du/dp|, |dv/dp| (module units per px).
    """

    def __init__(
        self,
        grey: np.ndarray,
        lens: Lens,
        cells: np.ndarray,
        geo: np.ndarray,
        norm: tuple[np.ndarray, float],
        edge_px: float,
        band_px: float,
        budget: int,
        offset: tuple[int, int] = (0, 0),
    ) -> None:
        size = cells.shape[0]
        n = size - 2 * QUIET_RINGS
        origin, scale = norm
        self.scale = scale
        #: modules per side, and the geometry (homography parameters, normalisation) it was made at
        self.n, self.geo, self.norm = n, geo, norm
        h, w = grey.shape
        g = _g_from_params(geo)
        inv = np.linalg.inv(g)  # (LAPACK's, as main: the pixels sampled follow it to the bit)
        ideal_corners = _apply(inv, _UNIT_SQUARE * n)
        sides = ideal_corners - ideal_corners[[1, 2, 3, 0]]
        module_px = float(np.sqrt((sides * sides).sum(axis=1)).mean()) * scale / n
        self.module_px = module_px
        r = 1 if edge_px / module_px < 0.4 else 2
        layout = _layout(cells, r)
        pts = layout.candidates(max(1, min(8, round(module_px))), max(module_px, 0.05), band_px, budget)
        ox, oy = offset
        px = lens.distort(_apply(inv, pts) * scale + origin)
        xy = np.rint(px).astype(np.int64) - (ox, oy)
        xs, ys = xy[:, 0], xy[:, 1]
        inside = (xs >= 1) & (ys >= 1) & (xs < w - 1) & (ys < h - 1)
        flat = ys[inside] * w + xs[inside]
        if h * w <= 16 * len(flat):
            # The distinct pixels in order by a mark per pixel (a crop: a few times the candidates'
            # count), else by sorting (the whole frame): the same sorted distinct indices.
            mark = np.zeros(h * w, dtype=bool)
            mark[flat] = True
            flat = np.flatnonzero(mark)
        else:
            flat = np.sort(flat)
            if len(flat):
                distinct = np.empty(len(flat), dtype=bool)
                distinct[0] = True
                np.not_equal(flat[1:], flat[:-1], out=distinct[1:])
                flat = flat[distinct]
        if len(flat) > budget:
            flat = flat[np.linspace(0, len(flat) - 1, budget).astype(np.int64)]
        xs, ys = flat % w, flat // w
        ideal, jl = lens.ideal(xs + ox, ys + oy)
        p = (ideal - origin) / scale
        # Where each pixel starts in module coordinates; the cells around it must all be known.
        uvw = p @ g[:, :2].T + g[:, 2]
        uv = uvw[:, :2] / uvw[:, 2:3]
        ok, colour_t, corner = _windows(layout, uv, r)
        self.xs, self.ys = xs[ok], ys[ok]
        self.values = grey[self.ys, self.xs].astype(np.float64)
        # Per-pixel terms with the pixels along the last axis (see _darkness_t): p (2, k), the
        # lighting basis (1, x, y) (3, k), the windows' first boundaries (2, k), colours (m, m, k).
        self.p_t = np.ascontiguousarray(p[ok].T)
        self.ph_t = np.empty((3, len(self.xs)))
        self.ph_t[0] = 1.0
        self.ph_t[1:] = self.p_t
        self.corner_t = np.ascontiguousarray(corner.T)
        self.colour_t = colour_t
        #: the pixels' module coordinates at ``geo`` (2, k): a pixel-centred template's points
        #: (qrfield.detect.symbol_track._Template), not mapped again there
        self.uv_t = np.ascontiguousarray(uv[ok].T)
        # px per module unit across u and across v edges (2, k): 1 / |du/dp|, 1 / |dv/dp|, with
        # d(u, v)/d(normalised ideal) = (G[:2, :2] - (u, v) G[2, :2]) / w and the lens' d ideal /
        # d pixel, component by component (whole (k, 2, 2) arrays cost several times as much).
        u_ok, v_ok = uv[ok, 0], uv[ok, 1]
        inv_w = 1.0 / (uvw[ok, 2] * scale)
        ux, uy = (g[0, 0] - u_ok * g[2, 0]) * inv_w, (g[0, 1] - u_ok * g[2, 1]) * inv_w
        vx, vy = (g[1, 0] - v_ok * g[2, 0]) * inv_w, (g[1, 1] - v_ok * g[2, 1]) * inv_w
        if lens.distorted:
            j = jl[ok]
            j00, j01, j10, j11 = j[:, 0, 0], j[:, 0, 1], j[:, 1, 0], j[:, 1, 1]
            ux, uy = ux * j00 + uy * j10, ux * j01 + uy * j11
            vx, vy = vx * j00 + vy * j10, vx * j01 + vy * j11
        self.inv_grad_t = np.empty((2, len(u_ok)))
        np.hypot(ux, uy, out=self.inv_grad_t[0])
        np.hypot(vx, vy, out=self.inv_grad_t[1])
        np.divide(1.0, self.inv_grad_t, out=self.inv_grad_t)
        self.radius = r

    def __len__(self) -> int:
        return len(self.xs)

    def darkness(self, geo: np.ndarray, edge_px: float) -> tuple[_Darkness, np.ndarray, np.ndarray]:
        """The model's darkness at the pixels for homography parameters ``geo``, with their module
        coordinates (2, k) and the homography's w (k,)."""
        g = _g_from_params(geo)
        uvw = (self.p_t.T @ g[:, :2].T + g[:, 2]).T
        w = uvw[2]
        uv = uvw[:2] / w
        return _Darkness(uv - self.corner_t, self.inv_grad_t, self.colour_t, edge_px), uv, w

    def residuals(self, geo: np.ndarray, edge_px: float, light: np.ndarray) -> tuple[np.ndarray, tuple]:
        """Residuals (k,) image - model, and what :meth:`jacobian` needs for them."""
        dark, uv, w = self.darkness(geo, edge_px)
        ph = self.ph_t
        a, b = (ph.T @ light.reshape(2, 3).T).T  # light level A, contrast B
        return self.values - a + b * dark.value, (dark, uv, w, b)

    def jacobian(self, at: tuple, free_edge: bool) -> np.ndarray:
        """The residuals' Jacobian at ``at`` (from :meth:`residuals`): (k, 8 [+1] + 6) with respect
        to (homography, [edge width,] lighting): J = d resid / d parameters = -d model / d
        parameters."""
        return np.ascontiguousarray(self.jacobian_t(at, free_edge).T)

    def jacobian_t(self, at: tuple, free_edge: bool) -> np.ndarray:
        """:meth:`jacobian` transposed, (8 [+1] + 6, k): each parameter's row contiguous (filling it
        and forming J^T W J cost less than on (k, n)); no transposed copy."""
        dark, uv, w, b = at
        d_uv, d_s = dark.derivatives(edge_derivative=free_edge)
        d = dark.value
        ph = self.ph_t
        col = 9 if free_edge else 8
        jac = np.empty((col + 6, len(d)))
        # d model / d (u, v) = -B dD/d(u, v); du/dg0* = (1, x, y) / w, du/dg2* = -u (x, y) / w
        m = d_uv * (b / w)  # = -(d model / d (u, v)) / w, (2, k)
        np.multiply(ph, m[0], out=jac[0:3])
        np.multiply(ph, m[1], out=jac[3:6])
        np.multiply(self.p_t, -(m[0] * uv[0] + m[1] * uv[1]), out=jac[6:8])
        if free_edge:
            np.multiply(b, d_s, out=jac[8])
        np.negative(ph, out=jac[col : col + 3])
        np.multiply(ph, d, out=jac[col + 3 : col + 6])
        return jac


def _g_from_params(theta: np.ndarray) -> np.ndarray:
    """(3, 3) map from normalised ideal pixels (x, y, 1) to module coordinates, from its 8 free
    entries in the order (g02, g00, g01, g12, g10, g11, g20, g21) (g22 = 1): the order of the
    Jacobian's columns, which multiply (1, x, y)."""
    return np.array(
        [[theta[1], theta[2], theta[0]], [theta[4], theta[5], theta[3]], [theta[6], theta[7], 1.0]]
    )


def _params_from_g(g: np.ndarray) -> np.ndarray:
    g = g / g[2, 2]
    return np.array([g[0, 2], g[0, 0], g[0, 1], g[1, 2], g[1, 0], g[1, 1], g[2, 0], g[2, 1]])


def _corners_mapped(theta: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """G^-1 (3, 3) of the parameters ``theta`` and the corners V1..V4 it maps to, in normalised
    ideal pixels (4, 2)."""
    inv = np.linalg.inv(_g_from_params(theta))
    return inv, _apply(inv, _UNIT_SQUARE * n)


def _corners_ideal(theta: np.ndarray, n: int, norm: tuple[np.ndarray, float]) -> np.ndarray:
    origin, scale = norm
    return _corners_mapped(theta, n)[1] * scale + origin


def _corners_jacobian(
    theta: np.ndarray,
    n: int,
    norm: tuple[np.ndarray, float],
    mapped: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """(8, 8) d (V1..V4 ideal px, flattened x1 y1 x2 ...) / d theta, analytically. ``mapped``: G^-1
    (3, 3) and the corners in normalised ideal pixels (4, 2), when the caller has them.

    Corner x solves G (x, 1) ~ (m, 1); for a change dG, dx = -(G^-1 dG x~)[:2] + x (G^-1 dG x~)[2].
    """
    _, scale = norm
    inv, corners = _corners_mapped(theta, n) if mapped is None else mapped
    xh = np.column_stack([corners, np.ones(4)])
    # theta's entries (i, j) of G: g02 g00 g01 g12 g10 g11 g20 g21; G^-1 E_ij x~ = G^-1[:, i] x~_j
    y = inv[:, _ENTRY_ROWS].T[None, :, :] * xh[:, _ENTRY_COLS][:, :, None]  # (4 corners, 8, 3)
    dx = -y[:, :, :2] + corners[:, None, :] * y[:, :, 2:3]
    return (dx * scale).transpose(0, 2, 1).reshape(8, 8)


def corner_covariance(dc: np.ndarray, cov: np.ndarray, corners_ideal: np.ndarray, lens: Lens) -> np.ndarray:
    """(4, 2, 2) image-pixel covariance of V1..V4 from the homography parameters' covariance
    ``cov`` (8, 8), the corners' derivatives ``dc`` (4, 2, 8) in ideal pixels, the lens'
    Jacobian at ``corners_ideal`` (4, 2), and the model-error floor."""
    out = dc @ cov @ dc.transpose(0, 2, 1)
    if lens.distorted:
        jl = lens.distort_jacobian(corners_ideal)
        out = jl @ out @ jl.transpose(0, 2, 1)
    return out + _FLOOR_COV


class _Solver:
    """Levenberg-Marquardt (or plain Gauss-Newton) over homography, [edge width,] lighting."""

    def __init__(self, problem: _Problem, free_edge: bool, scale: float = math.nan) -> None:
        self.problem = problem
        self.free_edge = free_edge
        self.start_scale = scale

    @staticmethod
    def weights(resid: np.ndarray, scale: float) -> np.ndarray:
        # 1 within HUBER_K scales, else HUBER_K scale / |r| (the warm fit's form: three calls)
        huber = HUBER_K * scale
        w = np.abs(resid)
        np.maximum(w, huber, out=w)
        return np.divide(huber, w, out=w)

    @staticmethod
    def cost(resid: np.ndarray, scale: float) -> float:
        a = np.abs(resid) / scale
        return float(np.sum(np.where(a <= HUBER_K, 0.5 * a * a, HUBER_K * a - 0.5 * HUBER_K**2)))

    @staticmethod
    def robust_scale(resid: np.ndarray) -> float:
        """1.4826 times the median absolute residual (the lighting terms centre the residuals), at
        least 0.5 grey levels (uint8 rounding alone gives 0.29)."""
        a = np.abs(resid)
        half = len(a) // 2
        return max(1.4826 * float(np.partition(a, half)[half]), 0.5) if len(a) else 0.5

    def run(self, geo, edge_px, light, max_iter: int, n: int, norm, tol_px: float = 2e-3):
        """Iterate from (geo, edge_px, light); returns them, the last residuals and Jacobian, the
        robust scale and the iterations done."""
        pr = self.problem
        resid, at = pr.residuals(geo, edge_px, light)
        jac = pr.jacobian(at, self.free_edge)
        scale = self.start_scale if math.isfinite(self.start_scale) else self.robust_scale(resid)
        cost = self.cost(resid, scale)
        lam = 1e-4
        corners = _corners_ideal(geo, n, norm)
        iterations = 0
        for _ in range(max_iter):
            iterations += 1
            w = self.weights(resid, scale)
            jw = jac * w[:, None]
            normal = jw.T @ jac
            grad = jw.T @ resid
            step = None
            for _attempt in range(6):
                damped = normal + (lam + 1e-12) * np.diag(np.diag(normal) + 1e-9)
                try:
                    delta = -np.linalg.solve(damped, grad)  # J = d resid / d parameters
                except np.linalg.LinAlgError:
                    lam = max(lam, 1e-4) * 10
                    continue
                new_geo = geo + delta[:8]
                k = 8
                new_edge = edge_px
                if self.free_edge:
                    new_edge = float(np.clip(edge_px + delta[8], MIN_EDGE_PX, 6.0))
                    k = 9
                new_light = light + delta[k : k + 6]
                r2, at = pr.residuals(new_geo, new_edge, new_light)
                c2 = self.cost(r2, scale)
                if np.isfinite(c2) and c2 <= cost and np.all(np.isfinite(r2)):
                    # (the Jacobian only for a step that is kept)
                    step = (new_geo, new_edge, new_light, r2, pr.jacobian(at, self.free_edge), c2)
                    lam = lam / 10
                    break
                lam = max(lam, 1e-4) * 10
            if step is None:
                break
            geo, edge_px, light, resid, jac, cost = step
            new_corners = _corners_ideal(geo, n, norm)
            moved = float(np.abs(new_corners - corners).max())
            corners = new_corners
            if moved < tol_px:
                break
        return geo, edge_px, light, resid, jac, self.robust_scale(resid), iterations


def _solve_lighting(problem: _Problem, geo: np.ndarray, edge_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Lighting terms by linear least squares at a fixed geometry; returns them and the residuals."""
    d = problem.darkness(geo, edge_px)[0].value
    a_t = np.empty((6, len(d)))  # the design matrix, transposed: (1, x, y, -D, -D x, -D y)
    a_t[:3] = problem.ph_t
    np.multiply(problem.ph_t, -d, out=a_t[3:])
    a = np.ascontiguousarray(a_t.T)
    try:
        light = np.linalg.solve(a.T @ a, a.T @ problem.values)
    except np.linalg.LinAlgError:
        light = np.linalg.lstsq(a, problem.values, rcond=None)[0]
    return light, problem.values - a @ light


def fit_symbol(
    grey: np.ndarray,
    corners_px: np.ndarray,
    cells: np.ndarray,
    *,
    lens: Lens | None = None,
    offset: tuple[int, int] = (0, 0),
    image_shape: tuple[int, int] | None = None,
    budget: int = FULL_BUDGET,
    coarse: bool = True,
    max_iter: int = 8,
    warm: FitState | None = None,
) -> SymbolFit:
    """Fit the symbol's model to ``grey`` starting from corners V1..V4 (image pixels).

    Args:
        grey: (H, W) uint8 image.
        corners_px: (4, 2) starting corners V1..V4, pixels of ``grey`` (docs/conventions.md).
        cells: the symbol's cell map (qrfield.detect.symbol: fixed_cells(n) or decoded_cells(matrix)).
        lens: the camera's lens (None: pinhole); its camera must be for images of ``image_shape``.
        offset: (x, y) of ``grey``'s top-left pixel in the camera image, when ``grey`` is a crop.
        image_shape: (H, W) of the camera image (None: ``grey`` is the whole image).
        budget: most pixels sampled.
        coarse: first the blurred model over a wider band (for starting corners a pixel or more
            off); False when starting from a good fit (tracking).
        max_iter: most iterations of the fine stage.
        warm: the edge width and lighting of the last frame's fit.

    Returns:
        SymbolFit; never raises for image content (ok False with a reason).
    """
    lens = lens or Lens(None)
    start = np.asarray(corners_px, dtype=np.float64)
    if start.shape != (4, 2) or not np.all(np.isfinite(start)):
        raise ValueError(f"corners must be a finite (4, 2) array of pixels V1..V4, got shape {start.shape}")
    size = cells.shape[0]
    n = size - 2 * QUIET_RINGS
    if grey.ndim != 2:
        raise ValueError(f"grey must be an (H, W) image, got shape {grey.shape}")
    if not lens.fits(image_shape or grey.shape):
        return SymbolFit(False, start.copy(), None, "the camera model is for another image size")
    shift = np.asarray(offset, dtype=np.float64)

    def fail(reason: str, iterations: int = 0) -> SymbolFit:
        return SymbolFit(False, start.copy(), None, reason, iterations=iterations)

    if lens.distorted:
        from qrfield.detect.lens import undistort_pixels

        ideal_start = undistort_pixels(lens.camera, start + shift)
    else:
        ideal_start = start + shift
    origin = ideal_start.mean(axis=0)
    scale = float(np.linalg.norm(ideal_start[2] - ideal_start[0])) / 2.0
    if scale < 4.0:
        return fail("the code is too small to fit")
    norm = (origin, scale)
    try:
        g0 = Homography.from_points((ideal_start - origin) / scale, _UNIT_SQUARE * n).matrix
    except ValueError:
        return fail("degenerate corners")
    module_px = scale * 2.0 / (n * math.sqrt(2.0))
    geo = _params_from_g(g0)
    edge = warm.edge_px if warm is not None else START_EDGE_PX
    iterations = 0
    stages = []
    if coarse:
        coarse_edge = max(1.5, 0.35 * module_px, edge)
        stages.append((coarse_edge, 1.5 * coarse_edge + 2.0, False, 4, min(budget, COARSE_BUDGET)))
    stages.append((None, None, True, max_iter, budget))
    light = warm.lighting if warm is not None else None
    problem = None
    resid = jac = None
    robust = math.nan
    with np.errstate(all="ignore"):
        for stage_edge, band, free, iters, most in stages:
            use_edge = stage_edge if stage_edge is not None else edge
            band = band if band is not None else 1.5 * use_edge + 1.0
            problem = _Problem(grey, lens, cells, geo, norm, use_edge, band, most, offset)
            if len(problem) < 60:
                return fail(f"too few pixels on known edges ({len(problem)})", iterations)
            if light is None or stage_edge is not None:
                light, _ = _solve_lighting(problem, geo, use_edge)
            solver = _Solver(problem, free_edge=free, scale=warm.scale if warm is not None else math.nan)
            geo, use_edge, light, resid, jac, robust, done = solver.run(geo, use_edge, light, iters, n, norm)
            iterations += done
            if stage_edge is None:
                edge = use_edge
        assert problem is not None and resid is not None and jac is not None
        start_geo = _params_from_g(g0) if warm is None else None
    return _finish(
        problem, start, geo, edge, light, (resid, jac, robust), lens, shift, iterations, start_geo, module_px
    )


def _finish(
    problem: _Problem,
    start: np.ndarray,
    geo: np.ndarray,
    edge: float,
    light: np.ndarray,
    last: tuple[np.ndarray, np.ndarray, float],
    lens: Lens,
    shift: np.ndarray,
    iterations: int,
    start_geo: np.ndarray | None,
    module_px: float,
    normal: np.ndarray | None = None,
) -> SymbolFit:
    """A fit's result from its last state on ``problem`` (``last``: its residuals, Jacobian and
    robust scale): corners, checks and covariance (see :func:`fit_symbol`); ``start_geo``: the
    parameters of the starting corners, to measure the start's residual on the same pixels (None:
    not measured, NaN); ``module_px``: the module size a corner's move is measured against;
    ``normal``: J^T W J of ``last`` with its Huber weights, when the caller has formed it."""
    n, norm = problem.n, problem.norm
    resid, jac, robust = last

    def fail(reason: str) -> SymbolFit:
        return SymbolFit(False, start.copy(), None, reason, iterations=iterations)

    with np.errstate(all="ignore"):
        origin, scale = norm
        inv, corners_norm = _corners_mapped(geo, n)
        corners_ideal = corners_norm * scale + origin
        if not np.all(np.isfinite(corners_ideal)):
            return fail("the fit diverged")
        corners = lens.distort(corners_ideal) - shift
        contrast = float(light[3])
        step = corners - start
        moved = math.sqrt(float((step * step).sum(axis=1).max()))  # the largest corner's move
        if abs(contrast) < MIN_CONTRAST:
            return fail(f"too little contrast ({abs(contrast):.0f} grey levels)")
        # The starting corners on the same pixels (lighting refitted): the fallback's measure
        # (not for a warm start, where the start is a prediction, not a competing answer).
        start_scale = math.nan
        if start_geo is not None:
            _, start_resid = _solve_lighting(problem, start_geo, edge)
            start_scale = _Solver.robust_scale(start_resid)
        # A corner far from its start is trusted only when the fit explains the image much better
        # there (a backend may miss V3 by many pixels; a fit may also wander off a code).
        if moved > max(3.0, 2.0 * module_px) and not robust < 0.5 * start_scale:
            return fail(f"a corner moved {moved:.1f} px from its start")
        # Covariance: robust scale^2 (J^T W J)^-1, its homography block taken to the corners.
        if normal is None:
            w = _Solver.weights(resid, robust)
            normal = (jac * w[:, None]).T @ jac
        try:
            cov = robust**2 * small_inverse(normal, symmetric=True)[:8, :8]
        except np.linalg.LinAlgError:
            return fail("the fit is singular")
        dc = _corners_jacobian(geo, n, norm, (inv, corners_norm)).reshape(4, 2, 8)
        corners_cov = corner_covariance(dc, cov, corners_ideal, lens)
        if not np.all(np.isfinite(corners_cov)):
            return fail("the fit is singular")
    return SymbolFit(
        True,
        corners,
        corners_cov,
        "",
        robust,
        start_scale,
        contrast,
        edge,
        len(problem),
        iterations,
        FitState(edge, light.copy(), robust),
    )


def polish(
    problem: _Problem,
    corners_px: np.ndarray,
    state: FitState,
    lens: Lens,
    offset: tuple[int, int] = (0, 0),
) -> SymbolFit:
    """One Gauss-Newton step of the full fit's model (edge width free) on ``problem``'s pixels from
    corners V1..V4 (4, 2) px of its image (a crop at ``offset``) a few hundredths of a pixel from
    the answer, with ``state``'s edge width and lighting (in the problem's basis: normalised ideal
    pixels); the covariance as :func:`fit_symbol`'s, from the model's Jacobian and the robust
    scale of the residuals where the step starts. Never raises for image content (ok False).

    For a cold fit by inverse composition (qrfield.detect.symbol_cold), whose template's points are
    these pixels (so its lighting carries over): the step from its answer is the full fit's own
    (its model at the pixel centres exactly), without the Levenberg-Marquardt trials that would
    evaluate the model again."""
    start = np.asarray(corners_px, dtype=np.float64)
    shift = np.asarray(offset, dtype=np.float64)
    n, (origin, scale) = problem.n, problem.norm
    if lens.distorted:
        from qrfield.detect.lens import undistort_pixels

        ideal = undistort_pixels(lens.camera, start + shift)
    else:
        ideal = start + shift
    try:
        geo = _params_from_g(Homography.from_points((ideal - origin) / scale, _UNIT_SQUARE * n).matrix)
    except ValueError:
        return SymbolFit(False, start.copy(), None, "degenerate corners")
    light = np.asarray(state.lighting, dtype=np.float64)
    with np.errstate(all="ignore"):
        resid, at = problem.residuals(geo, state.edge_px, light)
        jac_t = problem.jacobian_t(at, True)  # (15, k): no transposed copy
        robust = _Solver.robust_scale(resid)
        jw_t = jac_t * _Solver.weights(resid, robust)
        normal = jw_t @ jac_t.T  # the covariance's too (_finish)
        damped = normal.copy()
        damped.flat[:: len(damped) + 1] += 1e-9
        try:
            delta = -small_solve(damped, jw_t @ resid, symmetric=True)  # J = d resid / d parameters
        except np.linalg.LinAlgError:
            return SymbolFit(False, start.copy(), None, "the fit is singular")
        geo = geo + delta[:8]
        edge = float(np.clip(state.edge_px + delta[8], MIN_EDGE_PX, 6.0))
        light = light + delta[9:15]
    last = (resid, jac_t.T, robust)  # (the Jacobian unused: ``normal`` is given)
    return _finish(problem, start, geo, edge, light, last, lens, shift, 1, None, problem.module_px, normal)
