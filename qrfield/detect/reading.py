"""Reading a symbol that the decoders could not read, from its fitted geometry.

Small codes (modules of 1.2-3 px) seen through a blur of about a module are located (finder
patterns, qrfield.detect.small) and their fixed patterns fitted (qrfield.detect.symbol_fit) to a
few hundredths of a pixel, but zxing-cpp cannot read them: sampling the image at the module
centres mixes each module with its neighbours. Here the module colours are estimated instead by
least squares from every pixel over the symbol, with the blur modelled:

    I(p) = A(p) - B(p) * sum_m K(p, m) d_m

d_m the darkness (0 light, 1 dark) of module m, K(p, m) the share of the blurred pixel p that
module m covers (a Gaussian spread of ``blur_px`` plus the pixel's 1 px footprint, along the
module axes, separable), A and B the light level and contrast, linear across the code. The
fixed patterns and the quiet zone are known; the data modules are solved for (conjugate
gradients, weakly held towards 1/2), then thresholded at 1/2, drawn as a clean symbol and handed
to zxing-cpp, whose error correction fixes the modules read wrong. Only a text zxing-cpp decodes
from it counts, with its module matrix.
"""

from __future__ import annotations

import math

import numpy as np

from qrfield.detect.lens import Lens, undistort_pixels
from qrfield.detect.symbol import QUIET_RINGS, fixed_cells
from qrfield.homography import Homography

#: Cells of the window around each pixel's cell, each way (a 5 x 5 window).
WINDOW = 2
#: Pull of each unknown module towards 1/2 (Tikhonov weight, relative to one pixel's share).
RIDGE = 0.05
#: Conjugate-gradient iterations.
ITERATIONS = 12
#: Pixels of the clean symbol per module, and its quiet zone, for the decoder.
DRAWN_PX = 4
DRAWN_QUIET = 4
#: Blur widths tried, as factors of the given one (the fit's edge width is an estimate).
BLUR_FACTORS = (1.0, 0.75, 1.3)
#: The edge spread (1 + tanh(z / s)) / 2 of width s (qrfield.detect.symbol_fit) is a logistic
#: distribution of scale s / 2, whose standard deviation is this times s.
LOGISTIC_STD = math.pi / (2.0 * math.sqrt(3.0))


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
    lens = lens or Lens(None)
    n = int(modules)
    corners = np.asarray(corners_px, dtype=np.float64)
    h, w = grey.shape
    lo = np.floor(corners.min(axis=0) - 3.0).astype(int)
    hi = np.ceil(corners.max(axis=0) + 3.0).astype(int)
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), w - 1), min(int(hi[1]), h - 1)
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None, None
    xs, ys = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
    xs, ys = xs.ravel(), ys.ravel()
    shift = np.asarray(offset, dtype=np.float64)
    ideal_corners = undistort_pixels(lens.camera, corners + shift) if lens.distorted else corners + shift
    square = np.array([[0.0, 0.0], [n, 0.0], [n, n], [0.0, n]])
    try:
        to_modules = Homography.from_points(ideal_corners, square).matrix
    except ValueError:  # three corners in a line
        return None, None
    ideal, scale = lens.ideal(xs + int(offset[0]), ys + int(offset[1]))
    uvw = np.column_stack([ideal, np.ones(len(ideal))]) @ to_modules.T
    uv = uvw[:, :2] / uvw[:, 2:3]
    keep = np.all((uv > -QUIET_RINGS) & (uv < n + QUIET_RINGS), axis=1)
    if keep.sum() < 4 * n:
        return None, None
    uv, uvw, scale = uv[keep], uvw[keep], scale[keep]
    values = grey[ys[keep], xs[keep]].astype(np.float64)
    # Module units per image px across u and v (the homography's and the lens' local scale).
    grad = (to_modules[None, :2, :2] - uv[:, :, None] * to_modules[None, 2:3, :2]) / uvw[:, 2:3, None]
    grad = grad @ scale
    per_px = np.sqrt((grad * grad).sum(axis=2))  # (k, 2): |du/dp|, |dv/dp|
    for factor in BLUR_FACTORS:
        found = _read(values, uv, per_px, n, factor * blur_px)
        if found[0] is not None:
            return found
    return None, None


def _read(
    values: np.ndarray, uv: np.ndarray, per_px: np.ndarray, n: int, blur_px: float
) -> tuple[str | None, np.ndarray | None]:
    q = QUIET_RINGS
    size = n + 2 * q
    cells = fixed_cells(n).ravel()
    known = np.isfinite(cells)
    colour = np.where(known, cells, 0.5)
    spread = np.sqrt(blur_px**2 + 1.0 / 12.0) * per_px  # (k, 2), in modules
    base = np.floor(uv).astype(np.int64)
    k = len(values)
    # The operator K as (window cells, pixels) arrays: each pixel's share of each cell of the
    # window around it and that cell's index (share 0 off the map), so that K d is one gather and
    # one sum, and K^T r one weighted bincount.
    width = 2 * WINDOW + 1
    share = np.empty((width * width, k))
    col = np.empty((width * width, k), dtype=np.int64)
    ku_all = []
    for du in range(-WINDOW, WINDOW + 1):
        mu = base[:, 0] + du
        ku = gauss_cdf((mu + 1 - uv[:, 0]) / spread[:, 0]) - gauss_cdf((mu - uv[:, 0]) / spread[:, 0])
        ku_all.append((mu, ku))
    j = 0
    for dv in range(-WINDOW, WINDOW + 1):
        mv = base[:, 1] + dv
        kv = gauss_cdf((mv + 1 - uv[:, 1]) / spread[:, 1]) - gauss_cdf((mv - uv[:, 1]) / spread[:, 1])
        on_v = (mv >= -q) & (mv < n + q)
        for mu, ku in ku_all:
            np.multiply(ku, kv, out=share[j])
            ok = on_v & (mu >= -q) & (mu < n + q) & (share[j] > 1e-4)
            share[j][~ok] = 0.0
            col[j] = np.where(ok, (mv + q) * size + mu + q, 0)
            j += 1
    flat_col = col.ravel()

    def forward(d: np.ndarray) -> np.ndarray:
        return (share * d[col]).sum(axis=0)

    def backward(r: np.ndarray) -> np.ndarray:
        return np.bincount(flat_col, weights=(share * r).ravel(), minlength=size * size)

    # Lighting A, B linear across the code, from the pixels that see mostly known cells.
    unknown_mass = forward((~known).astype(np.float64))
    darkness = forward(colour)
    sure = unknown_mass < 0.1
    if sure.sum() < 30:
        return None, None
    basis = np.column_stack([np.ones(k), uv / n - 0.5])
    a = np.concatenate([basis, -basis * darkness[:, None]], axis=1)
    try:
        light = np.linalg.lstsq(a[sure], values[sure], rcond=None)[0]
    except np.linalg.LinAlgError:
        return None, None
    level, contrast = basis @ light[:3], basis @ light[3:]
    if not np.all(np.abs(contrast) > 1.0):
        return None, None
    target = (level - values) / contrast - forward(np.where(known, colour, 0.0))  # = K_free d_free
    free = (~known).astype(np.float64)

    def normal(d: np.ndarray) -> np.ndarray:
        return (backward(forward(d * free)) + RIDGE * d) * free

    # Conjugate gradients preconditioned by the normal matrix's diagonal (Jacobi): sum_p K(p, m)^2.
    diagonal = np.bincount(flat_col, weights=(share * share).ravel(), minlength=size * size) + RIDGE
    inverse = free / diagonal
    d = 0.5 * free
    residual = (backward(target) + RIDGE * 0.5) * free - normal(d)
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
    read = np.where(known, cells, d).reshape(size, size)[q:-q, q:-q] > 0.5
    return _decode(read)


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
