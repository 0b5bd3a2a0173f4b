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
it counts, with its module matrix. (Issue 26q: the same reads at about half the CPU time: fewer
quadrature nodes where the view is little sheared, the normal matrix's stencil without its
negligible offsets, and one blur retry instead of two; docs/detection.md, "issue 26q".)
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
#: The steps end earlier once the preconditioned residual r^T M^-1 r is this share of its start
#: (issue 26q): d then moves by less than ~1e-6 more, far below what the threshold at 1/2 and
#: FIX_MARGIN resolve.
CONVERGED = 1e-12
#: A pair of window cells, or a stencil offset, whose weight is at most this share of the normal
#: matrix's largest diagonal entry is left out (issue 26q: the reads unchanged, module for module).
NEGLIGIBLE = 1e-7
#: Pixels of the clean symbol per module, and its quiet zone, for the decoder.
DRAWN_PX = 4
DRAWN_QUIET = 4
#: Blur widths tried, as factors of the given one (the fit's edge width is an estimate). 1.3 times
#: it was tried too before issue 26q: of 294 reads (the hard set's of seed 2024, the steep set's
#: from the true corners of seed 2026 and end to end on seeds 2026, 2027, 2031) it read none the
#: other two did not (0.75 read 2 of 2031's that 1.0 did not), and cost a third of each failure.
BLUR_FACTORS = (1.0, 0.75)
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
#: Fewer nodes where the view's largest correlation |rho| is at most the bound (issue 26q): on the
#: 129 reads of the hard set (seed 2024) and the steep set (seed 2026, true corners) each cell's
#: share stays within 0.005 of the 7 nodes' (2 nodes up to 0.12: 0.004; 3 up to 0.3: 0.0043; 5
#: up to 0.5: 0.004), a quarter of the 7 nodes' own error against the sheared Gaussian.
FEWER_NODES = tuple(
    (bound, (lambda nodes, weights: (nodes, weights / weights.sum()))(*hermegauss(count)))
    for bound, count in ((0.12, 2), (0.3, 3), (0.5, 5))
)


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
    tried: set[bytes] = set()  # the thresholded matrices zxing-cpp already failed on
    for factor in BLUR_FACTORS:
        found = _read(values, uv, jac, n, factor * blur_px, tried)
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
    values: np.ndarray, uv: np.ndarray, jac: np.ndarray, n: int, blur_px: float, tried: set[bytes]
) -> tuple[str | None, np.ndarray | None]:
    """The first decode of the estimates' thresholded matrices (each decoded once: ``tried``
    holds those that failed, across rounds and blur widths)."""
    for darkness in _estimates(values, uv, jac, n, blur_px):
        matrix = darkness > 0.5
        key = np.packbits(matrix).tobytes()
        if key in tried:
            continue
        found = _decode(matrix)
        if found[0] is not None:
            return found
        tried.add(key)
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
    over the pixels and back. Pairs of window cells whose shares overlap by at most NEGLIGIBLE of
    the largest diagonal entry over all pixels, and the offsets left at most that, are left out
    (issue 26q: 20-35 % of the 81 offsets on sharp or unsheared views)."""

    def __init__(self, share: np.ndarray, col: np.ndarray, size: int) -> None:
        width = 2 * WINDOW + 1
        reach = 2 * WINDOW
        cells = size * size
        self.pad = reach * (size + 1)
        offsets: list[int] = []
        weights: list[np.ndarray] = []
        floor = -1.0  # NEGLIGIBLE of the diagonal's largest entry, once the diagonal is known
        most, total = share.max(axis=1).tolist(), share.sum(axis=1).tolist()
        for ov in range(0, reach + 1):
            for ou in range(-reach if ov else 0, reach + 1):
                weight = np.zeros(cells)
                for dv1 in range(width - ov):
                    for du1 in range(max(0, -ou), min(width, width - ou)):
                        j1, j2 = dv1 * width + du1, (dv1 + ov) * width + du1 + ou
                        # sum_p a_p b_p <= max(a) sum(b) bounds every cell's share of the pair
                        if min(most[j1] * total[j2], most[j2] * total[j1]) <= floor:
                            continue
                        weight += np.bincount(col[j1], weights=share[j1] * share[j2], minlength=cells)
                offset = ov * size + ou
                if not offset:
                    self.diagonal_weight = weight
                    floor = NEGLIGIBLE * float(weight.max(initial=0.0))
                elif weight.max(initial=0.0) <= floor:
                    continue
                offsets.append(offset)
                weights.append(weight)
                if offset:  # symmetric: cell c + offset sees c with the same weight
                    mirror = np.zeros(cells)
                    mirror[offset:] = weight[:-offset]
                    offsets.append(-offset)
                    weights.append(mirror)
        self.cells = cells
        self.starts = self.pad + np.asarray(offsets)
        self.weights = np.stack(weights)
        self.padded = np.zeros(cells + 2 * self.pad)  # x with zeros around, for the shifts
        self.windows = np.lib.stride_tricks.sliding_window_view(self.padded, cells)

    def diagonal(self) -> np.ndarray:
        return self.diagonal_weight

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """K^T K x, x over the cell map (flat)."""
        self.padded[self.pad : self.pad + self.cells] = x
        # the map shifted by each offset, one row each (a copy of contiguous rows)
        return np.einsum("ij,ij->j", self.weights, self.windows[self.starts])


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
    enough = max(CONVERGED * rz, 1e-12)
    for _ in range(ITERATIONS):
        if rz < enough:
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
    largest = float(np.abs(rho).max()) if k else 0.0
    nodes, weights = next((rule for bound, rule in FEWER_NODES if largest <= bound), QUADRATURE)
    edges = np.arange(-WINDOW, WINDOW + 2, dtype=np.int64)[:, None]
    for t, wt in zip(nodes, weights, strict=True):
        cu, cv = uv[:, 0] + t * along_u, uv[:, 1] + t * along_v
        # The CDF at the window's 2 WINDOW + 2 cell edges along each axis, each edge once.
        ku_all = np.diff(gauss_cdf((base[None, :, 0] + edges - cu) / spread_u), axis=0)
        kv_all = np.diff(gauss_cdf((base[None, :, 1] + edges - cv) / spread_v), axis=0) * wt
        share += (kv_all[:, None, :] * ku_all[None, :, :]).reshape(width * width, k)
    steps = np.arange(-WINDOW, WINDOW + 1, dtype=np.int64)[:, None]
    mu, mv = base[None, :, 0] + steps, base[None, :, 1] + steps  # (width, k) each
    on_u, on_v = (mu >= -q) & (mu < n + q), (mv >= -q) & (mv < n + q)
    ok = (on_v[:, None, :] & on_u[None, :, :]).reshape(width * width, k) & (share > 1e-4)
    share[~ok] = 0.0
    cell = ((mv + q) * size)[:, None, :] + (mu + q)[None, :, :]
    col = np.where(ok, cell.reshape(width * width, k), 0)
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
