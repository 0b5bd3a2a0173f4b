"""Reading a symbol that the decoders could not read, from its fitted geometry.

Small codes (modules of 1.2-3 px) seen through a blur of about a module are located (finder
patterns, qrfield.detect.small) and their fixed patterns fitted (qrfield.detect.symbol_fit) to a
few hundredths of a pixel, but zxing-cpp cannot read them: sampling the image at the module
centres mixes each module with its neighbours. Here the module colours are estimated instead by
least squares from every pixel over the symbol, with the blur modelled:

    I(p) = A(p) - B(p) * sum_m K(p, m) d_m

d_m the darkness (0 light, 1 dark) of module m, K(p, m) the share of the blurred pixel p that
module m covers, A and B the light level and contrast, linear across the code. The blur (a
Gaussian of ``blur_px`` plus the pixel's 1 px footprint) is isotropic in the image; in module
coordinates it is a Gaussian of covariance s^2 J J^T, J the local Jacobian of the homography
(and lens): wider across the foreshortened direction and, where the view is steep about both
axes, sheared (a correlation between u and v of 0.05-0.94, the median over a view, on 16 of the
steep set's views), which a blur along the module axes alone misses. (Issue 26r: with the true
corners and blur, 56 of seed 2026's 74 steep views of 1.2-2 px modules were read before; 70 with
the sheared blur, less ridge, more steps and the second round below.) The fixed patterns and
the quiet zone are known; the data modules are solved for (conjugate gradients, weakly held
towards 1/2), then thresholded at 1/2, drawn as a clean symbol and handed to zxing-cpp, whose
error correction fixes the modules read wrong. When that fails, the modules read with a margin
are taken as known and the rest solved again (a second round). Only a text zxing-cpp decodes from
it counts, with its module matrix.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
from numpy.polynomial.hermite_e import hermegauss

from qrfield.detect.lens import Lens, undistort_pixels
from qrfield.detect.symbol import QUIET_RINGS, fixed_cells
from qrfield.homography import Homography

#: Cells of the window around each pixel's cell, each way (a 5 x 5 window).
WINDOW = 2
#: Pull of each unknown module towards 1/2 (Tikhonov weight, relative to one pixel's share) and
#: conjugate-gradient steps: 0.05 and 12 before issue 26r (measured on seed 2026's steep views
#: with the true corners, before the shear was modelled: 0.2 read 45 of 74, 0.05 56, 0.01 60,
#: 0.003 63, 0.001 62; 25 steps lost one of 40's).
RIDGE = 0.003
ITERATIONS = 40
#: Pixels of the clean symbol per module, and its quiet zone, for the decoder.
DRAWN_PX = 4
DRAWN_QUIET = 4
#: Blur widths tried, as factors of the given one (the fit's edge width is an estimate).
BLUR_FACTORS = (1.0, 0.75, 1.3)
#: The edge spread (1 + tanh(z / s)) / 2 of width s (qrfield.detect.symbol_fit) is a logistic
#: distribution of scale s / 2, whose standard deviation is this times s.
LOGISTIC_STD = math.pi / (2.0 * math.sqrt(3.0))
#: Rounds of the reading (each after the first with the modules the previous one read beyond
#: 1/2 +- FIX_MARGIN taken as known): a second round read 3 more of those 74, a third none.
ROUNDS = 2
FIX_MARGIN = 0.3
#: Gauss-Hermite nodes and weights (probabilists', unit variance) for the shear's 1-D spread: 7
#: put each cell's share within 0.02 of the sheared Gaussian's at a correlation of 0.83 (3: 0.15).
QUADRATURE = (lambda nodes, weights: (nodes, weights / weights.sum()))(*hermegauss(7))


def gauss_cdf(x: np.ndarray) -> np.ndarray:
    """The standard normal CDF (Abramowitz and Stegun 7.1.26: |error| < 1.5e-7)."""
    z = np.abs(x) * (1.0 / math.sqrt(2.0))
    t = 1.0 / (1.0 + 0.3275911 * z)
    poly = ((((1.061405429 * t - 1.453152027) * t + 1.421413741) * t - 0.284496736) * t + 0.254829592) * t
    return 0.5 + np.copysign(0.5 - 0.5 * poly * np.exp(-z * z), x)


def read_symbol(
    grey: np.ndarray,
    corners_px: np.ndarray,
    modules: int,
    blur_px: float,
    lens: Lens | None = None,
    offset: tuple[int, int] = (0, 0),
) -> tuple[str | None, np.ndarray | None]:
    """(text, (n, n) bool module matrix as read, True = dark, upright: a few modules may be wrong,
    which the error correction put right for the text) of the symbol with corners V1..V4
    ``corners_px`` (sub-pixel, pixels of ``grey``, an image whose top-left pixel is at ``offset`` in
    the camera's) and ``modules`` per side seen through a blur of ``blur_px`` (standard deviation,
    px); (None, None) when zxing-cpp cannot decode what the least squares read."""
    n = int(modules)
    pixels = _pixels(grey, corners_px, n, lens or Lens(None), offset)
    if pixels is None:
        return None, None
    values, uv, jac = pixels
    for factor in BLUR_FACTORS:
        found = _read(values, uv, jac, n, factor * blur_px)
        if found[0] is not None:
            return found
    return None, None


def _pixels(
    grey: np.ndarray, corners_px: np.ndarray, n: int, lens: Lens, offset: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(grey values (k,), module coordinates (k, 2), module units per image px along u and v (k, 2))
    of the pixels over the symbol and its known quiet rings; None when too few."""
    corners = np.asarray(corners_px, dtype=np.float64)
    h, w = grey.shape
    lo = np.floor(corners.min(axis=0) - 3.0).astype(int)
    hi = np.ceil(corners.max(axis=0) + 3.0).astype(int)
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), w - 1), min(int(hi[1]), h - 1)
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None
    xs, ys = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
    xs, ys = xs.ravel(), ys.ravel()
    shift = np.asarray(offset, dtype=np.float64)
    ideal_corners = undistort_pixels(lens.camera, corners + shift) if lens.distorted else corners + shift
    square = np.array([[0.0, 0.0], [n, 0.0], [n, n], [0.0, n]])
    try:
        to_modules = Homography.from_points(ideal_corners, square).matrix
    except ValueError:  # three corners in a line
        return None
    ideal, scale = lens.ideal(xs + int(offset[0]), ys + int(offset[1]))
    uvw = np.column_stack([ideal, np.ones(len(ideal))]) @ to_modules.T
    uv = uvw[:, :2] / uvw[:, 2:3]
    keep = np.all((uv > -QUIET_RINGS) & (uv < n + QUIET_RINGS), axis=1)
    if keep.sum() < 4 * n:
        return None
    uv, uvw, scale = uv[keep], uvw[keep], scale[keep]
    values = grey[ys[keep], xs[keep]].astype(np.float64)
    # Module units per image px across u and v (the homography's and the lens' local scale).
    grad = (to_modules[None, :2, :2] - uv[:, :, None] * to_modules[None, 2:3, :2]) / uvw[:, 2:3, None]
    grad = grad @ scale
    return values, uv, grad


def _read(
    values: np.ndarray, uv: np.ndarray, jac: np.ndarray, n: int, blur_px: float
) -> tuple[str | None, np.ndarray | None]:
    for darkness in _estimates(values, uv, jac, n, blur_px):
        found = _decode(darkness > 0.5)
        if found[0] is not None:
            return found
    return None, None


def _estimates(
    values: np.ndarray, uv: np.ndarray, jac: np.ndarray, n: int, blur_px: float
) -> Iterator[np.ndarray]:
    """The (n, n) darkness of the modules (fixed patterns 0/1, the rest by least squares, upright)
    after each of at most ROUNDS rounds (none when the lighting cannot be fitted): each round
    solves the modules not yet known; those it reads with a margin of FIX_MARGIN are then taken as
    known for the next (their neighbours' estimates no longer share the blur's ambiguity with
    them). A generator: the caller stops once one decodes."""
    q = QUIET_RINGS
    size = n + 2 * q
    cells = fixed_cells(n).ravel().copy()
    share, col = _operator(uv, jac, n, blur_px)
    k = len(values)
    flat_col = col.ravel()

    def forward(d: np.ndarray) -> np.ndarray:
        return (share * d[col]).sum(axis=0)

    def backward(r: np.ndarray) -> np.ndarray:
        return np.bincount(flat_col, weights=(share * r).ravel(), minlength=size * size)

    gram = _Gram(share, col, size)
    diagonal = gram.diagonal() + RIDGE  # the Jacobi preconditioner
    basis = np.column_stack([np.ones(k), uv / n - 0.5])
    for _ in range(ROUNDS):
        known = np.isfinite(cells)
        colour = np.where(known, cells, 0.0)
        # Lighting A, B linear across the code, from the pixels that see mostly known cells.
        sure = forward((~known).astype(np.float64)) < 0.1
        if sure.sum() < 30:
            return
        a = np.concatenate([basis, -basis * forward(colour)[:, None]], axis=1)
        try:
            light = np.linalg.lstsq(a[sure], values[sure], rcond=None)[0]
        except np.linalg.LinAlgError:
            return
        level, contrast = basis @ light[:3], basis @ light[3:]
        if not np.all(np.abs(contrast) > 1.0):
            return
        target = (level - values) / contrast - forward(colour)  # = K_free d_free
        free = (~known).astype(np.float64)
        d = _solve(gram, backward(target), free, free / diagonal)
        yield np.where(known, cells, d).reshape(size, size)[q:-q, q:-q]
        sure_cells = (free > 0) & (np.abs(d - 0.5) > FIX_MARGIN)
        if not sure_cells.any():
            return
        cells[sure_cells] = (d[sure_cells] > 0.5).astype(np.float64)


class _Gram:
    """The normal matrix K^T K of the blur operator (``share``, ``col`` of :func:`_operator`) as a
    stencil over the (size x size) cell map: a cell and the cells up to 2 WINDOW away each way are
    the only ones a pixel's window holds together. Built once per operator (a bincount per pair
    of window cells), it makes each conjugate-gradient step one pass over the cells instead of one
    over the pixels and back."""

    def __init__(self, share: np.ndarray, col: np.ndarray, size: int) -> None:
        width = 2 * WINDOW + 1
        reach = 2 * WINDOW
        cells = size * size
        self.pad = reach * (size + 1)
        self.offsets: list[int] = []
        self.weights: list[np.ndarray] = []
        for ov in range(0, reach + 1):
            for ou in range(-reach if ov else 0, reach + 1):
                weight = np.zeros(cells)
                for dv1 in range(width - ov):
                    for du1 in range(max(0, -ou), min(width, width - ou)):
                        j1, j2 = dv1 * width + du1, (dv1 + ov) * width + du1 + ou
                        weight += np.bincount(col[j1], weights=share[j1] * share[j2], minlength=cells)
                offset = ov * size + ou
                self.offsets.append(offset)
                self.weights.append(weight)
                if offset:  # symmetric: cell c + offset sees c with the same weight
                    mirror = np.zeros(cells)
                    mirror[offset:] = weight[:-offset]
                    self.offsets.append(-offset)
                    self.weights.append(mirror)
        self.cells = cells

    def diagonal(self) -> np.ndarray:
        return self.weights[self.offsets.index(0)]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """K^T K x, x over the cell map (flat)."""
        padded = np.zeros(self.cells + 2 * self.pad)
        padded[self.pad : self.pad + self.cells] = x
        out = np.zeros(self.cells)
        for offset, weight in zip(self.offsets, self.weights, strict=True):
            start = self.pad + offset
            out += weight * padded[start : start + self.cells]
        return out


def _solve(gram: _Gram, rhs: np.ndarray, free: np.ndarray, inverse: np.ndarray) -> np.ndarray:
    """The free cells' darkness d minimising |K d - target|^2 + RIDGE |d - 1/2|^2 (``rhs`` = K^T
    target; conjugate gradients preconditioned by ``inverse``, ITERATIONS at most); 0 on the other
    cells."""

    def normal(d: np.ndarray) -> np.ndarray:
        return (gram(d * free) + RIDGE * d) * free

    d = 0.5 * free
    residual = (rhs + RIDGE * 0.5) * free - normal(d)
    z = inverse * residual
    step = z.copy()
    rz = float(residual @ z)
    for _ in range(ITERATIONS):
        if rz < 1e-12:
            break
        ap = normal(step)
        alpha = rz / float(step @ ap)
        d += alpha * step
        residual -= alpha * ap
        z = inverse * residual
        new_rz = float(residual @ z)
        step = z + (new_rz / rz) * step
        rz = new_rz
    return d


def _operator(uv: np.ndarray, jac: np.ndarray, n: int, blur_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The blur operator K as (window cells, pixels) arrays: each pixel's share of each cell of the
    window around it and that cell's index into the cell map (share 0 off the map), so that K d is
    one gather and one sum, and K^T r one weighted bincount.

    The blur (``blur_px`` std, px, with the pixel's footprint) is isotropic in the image, so in
    module coordinates its covariance is s^2 J J^T (``jac`` (k, 2, 2): d(u, v)/d(x, y) at each
    pixel): variances a, b along u, v and, where foreshortening shears the module grid, a
    correlation rho. It is split as (1 - |rho|) diag(a, b) + |rho| w w^T, w = (sqrt a, sign(rho)
    sqrt b): a separable Gaussian (products of CDF differences) spread along w by a 1-D Gaussian,
    integrated by Gauss-Hermite quadrature."""
    q = QUIET_RINGS
    size = n + 2 * q
    s2 = blur_px**2 + 1.0 / 12.0
    a = s2 * (jac[:, 0, :] ** 2).sum(axis=1)
    b = s2 * (jac[:, 1, :] ** 2).sum(axis=1)
    c = s2 * (jac[:, 0, :] * jac[:, 1, :]).sum(axis=1)
    rho = np.clip(c / np.sqrt(a * b), -0.95, 0.95)
    spread_u, spread_v = np.sqrt(a * (1.0 - np.abs(rho))), np.sqrt(b * (1.0 - np.abs(rho)))
    along_u, along_v = np.sqrt(np.abs(rho) * a), np.sign(rho) * np.sqrt(np.abs(rho) * b)
    base = np.floor(uv).astype(np.int64)
    k = len(uv)
    width = 2 * WINDOW + 1
    share = np.zeros((width * width, k))
    nodes, weights = QUADRATURE
    for t, wt in zip(nodes, weights, strict=True):
        cu, cv = uv[:, 0] + t * along_u, uv[:, 1] + t * along_v
        ku_all = []
        for du in range(-WINDOW, WINDOW + 1):
            mu = base[:, 0] + du
            ku_all.append(gauss_cdf((mu + 1 - cu) / spread_u) - gauss_cdf((mu - cu) / spread_u))
        j = 0
        for dv in range(-WINDOW, WINDOW + 1):
            mv = base[:, 1] + dv
            kv = wt * (gauss_cdf((mv + 1 - cv) / spread_v) - gauss_cdf((mv - cv) / spread_v))
            for ku in ku_all:
                share[j] += ku * kv
                j += 1
    col = np.empty((width * width, k), dtype=np.int64)
    j = 0
    for dv in range(-WINDOW, WINDOW + 1):
        mv = base[:, 1] + dv
        on_v = (mv >= -q) & (mv < n + q)
        for du in range(-WINDOW, WINDOW + 1):
            mu = base[:, 0] + du
            ok = on_v & (mu >= -q) & (mu < n + q) & (share[j] > 1e-4)
            share[j][~ok] = 0.0
            col[j] = np.where(ok, (mv + q) * size + mu + q, 0)
            j += 1
    return share, col


def _decode(matrix: np.ndarray) -> tuple[str | None, np.ndarray | None]:
    """zxing-cpp's reading of a clean drawing of ``matrix`` (n, n) bool: (text, its module matrix)."""
    import zxingcpp

    from qrfield.detect.symbol import matrix_from_zxing

    n = matrix.shape[0]
    s, quiet = DRAWN_PX, DRAWN_QUIET
    image = np.full(((n + 2 * quiet) * s,) * 2, 255, np.uint8)
    image[quiet * s : (quiet + n) * s, quiet * s : (quiet + n) * s] = np.where(
        np.kron(matrix, np.ones((s, s), bool)), 0, 255
    )
    barcodes = zxingcpp.read_barcodes(
        image, formats=zxingcpp.BarcodeFormat.QRCode, text_mode=zxingcpp.TextMode.Plain
    )
    if not barcodes or not barcodes[0].valid:
        return None, None
    decoded = matrix_from_zxing(barcodes[0])
    return barcodes[0].text, decoded if decoded is not None and decoded.shape == matrix.shape else None
