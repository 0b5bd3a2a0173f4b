"""The module layout of a QR symbol as far as it is known: fixed patterns, and the data once decoded.

A *cell map* is an (n + 2 Q, n + 2 Q) float array over the symbol and Q = QUIET_RINGS rings of
its quiet zone, in module rows (y, from V1 towards V4) and columns (x, from V1 towards V2):
1.0 for a dark module, 0.0 for a light one, NaN where the colour is not known. Cell (Q + r, Q + c)
is module (row r, column c); module column c spans x in [c, c + 1) in the module coordinates of
:mod:`qrfield.detect.patterns` (V1 = (0, 0), V2 = (n, 0), V3 = (n, n), V4 = (0, n)).

Without a decoded matrix only what every symbol of that size has is known (ISO/IEC 18004): the
three finder patterns and their separators, the two timing patterns, the alignment patterns
(version 2 and up, centres from the standard's table E.1), the dark module beside the lower-left
finder, and the quiet zone. Format and version information and the data are left unknown.
"""

from __future__ import annotations

import functools

import numpy as np

#: Rings of the quiet zone taken as known light (ISO/IEC 18004 asks for 4; prints often have less
#: room, and the fit only looks about one module beyond the symbol).
QUIET_RINGS = 2

#: Centre rows/columns of the alignment patterns per version (ISO/IEC 18004, table E.1).
ALIGNMENT_CENTRES: dict[int, tuple[int, ...]] = {
    1: (),
    2: (6, 18),
    3: (6, 22),
    4: (6, 26),
    5: (6, 30),
    6: (6, 34),
    7: (6, 22, 38),
    8: (6, 24, 42),
    9: (6, 26, 46),
    10: (6, 28, 50),
    11: (6, 30, 54),
    12: (6, 32, 58),
    13: (6, 34, 62),
    14: (6, 26, 46, 66),
    15: (6, 26, 48, 70),
    16: (6, 26, 50, 74),
    17: (6, 30, 54, 78),
    18: (6, 30, 56, 82),
    19: (6, 30, 58, 86),
    20: (6, 34, 62, 90),
    21: (6, 28, 50, 72, 94),
    22: (6, 26, 50, 74, 98),
    23: (6, 30, 54, 78, 102),
    24: (6, 28, 54, 80, 106),
    25: (6, 32, 58, 84, 110),
    26: (6, 30, 58, 86, 114),
    27: (6, 34, 62, 90, 118),
    28: (6, 26, 50, 74, 98, 122),
    29: (6, 30, 54, 78, 102, 126),
    30: (6, 26, 52, 78, 104, 130),
    31: (6, 30, 56, 82, 108, 134),
    32: (6, 34, 60, 86, 112, 138),
    33: (6, 30, 58, 86, 114, 142),
    34: (6, 34, 62, 90, 118, 146),
    35: (6, 30, 54, 78, 102, 126, 150),
    36: (6, 24, 50, 76, 102, 128, 154),
    37: (6, 28, 54, 80, 106, 132, 158),
    38: (6, 32, 58, 84, 110, 136, 162),
    39: (6, 26, 54, 82, 110, 138, 166),
    40: (6, 30, 58, 86, 114, 142, 170),
}


def version_of(n: int) -> int:
    """QR version (1..40) of a symbol with ``n`` modules per side; ValueError otherwise."""
    version, rest = divmod(n - 17, 4)
    if rest or not 1 <= version <= 40:
        raise ValueError(f"a QR symbol has 17 + 4 v modules per side (v = 1..40), got {n}")
    return version


@functools.lru_cache(maxsize=64)
def fixed_cells(n: int) -> np.ndarray:
    """Cell map (see the module docstring) of what every symbol of ``n`` modules per side shows."""
    version = version_of(n)
    q = QUIET_RINGS
    cells = np.full((n + 2 * q, n + 2 * q), np.nan)
    cells[:q, :] = cells[-q:, :] = cells[:, :q] = cells[:, -q:] = 0.0
    inner = cells[q:-q, q:-q]

    def finder(r0: int, c0: int) -> None:
        ring = np.maximum(np.abs(np.arange(7)[:, None] - 3), np.abs(np.arange(7)[None, :] - 3))
        inner[r0 : r0 + 7, c0 : c0 + 7] = (ring != 2).astype(float)

    finder(0, 0)
    finder(0, n - 7)
    finder(n - 7, 0)
    # Separators: the light L around each finder inside the symbol.
    inner[7, :8] = inner[:8, 7] = 0.0
    inner[7, n - 8 :] = inner[:8, n - 8] = 0.0
    inner[n - 8, :8] = inner[n - 8 :, 7] = 0.0
    # Timing patterns: row 6 and column 6 between the separators, dark on even modules.
    timing = (np.arange(8, n - 8) % 2 == 0).astype(float)
    inner[6, 8 : n - 8] = timing
    inner[8 : n - 8, 6] = timing
    centres = ALIGNMENT_CENTRES[version]
    for r in centres:
        for c in centres:
            if (r, c) in ((6, 6), (6, centres[-1]), (centres[-1], 6)):
                continue  # where the finder patterns are
            ring = np.maximum(np.abs(np.arange(5)[:, None] - 2), np.abs(np.arange(5)[None, :] - 2))
            inner[r - 2 : r + 3, c - 2 : c + 3] = (ring != 1).astype(float)
    inner[n - 8, 8] = 1.0  # the dark module (ISO/IEC 18004, 7.9.1)
    cells.setflags(write=False)
    return cells


def decoded_cells(matrix: np.ndarray) -> np.ndarray:
    """Cell map of a decoded symbol: its (n, n) module matrix (True or 1 = dark, False or 0 = light,
    NaN = not known) with the quiet zone.

    The fixed patterns are taken from the standard rather than from ``matrix`` where they differ
    (a module misread by the decoder's sampling); ValueError for a matrix of a wrong shape.
    """
    matrix = np.asarray(matrix)
    if matrix.ndim != 2 or matrix.shape[0] != matrix.shape[1]:
        raise ValueError(f"a QR module matrix must be square, got shape {matrix.shape}")
    n = matrix.shape[0]
    fixed = fixed_cells(n)
    q = QUIET_RINGS
    cells = fixed.copy()
    inner = cells[q:-q, q:-q]
    unknown = np.isnan(inner)
    values = matrix.astype(np.float64)
    inner[unknown] = np.where(np.isnan(values), np.nan, values > 0.5)[unknown]
    cells.setflags(write=False)
    return cells


def verified_matrix(values: np.ndarray, matrix: np.ndarray, dark: float, light: float) -> np.ndarray:
    """The decoded ``matrix`` (n, n) as a float matrix (1 dark, 0 light) with NaN where the image
    does not confirm it: ``values`` (n, n) are the grey levels at the module centres (from a fit
    that did not need the data modules), ``dark``/``light`` the levels of the fixed patterns.

    zxing-cpp's matrix is the grid it sampled to decode, misread modules included (2 to 7 of 441
    on blurred views of the hard benchmark set): a misread module would pull the fit, so a module
    whose centre reads the other colour, or within 15 % of the contrast of the middle, is unknown.
    """
    m = np.asarray(matrix, dtype=np.float64)
    contrast = light - dark
    if not np.isfinite(contrast) or abs(contrast) < 1e-6:
        return np.full(m.shape, np.nan)
    darkness = (light - np.asarray(values, dtype=np.float64)) / contrast  # 0 light .. 1 dark
    confirmed = np.where(m > 0.5, darkness > 0.65, darkness < 0.35)
    return np.where(confirmed & np.isfinite(m), m, np.nan)


def matrix_from_zxing(barcode: object) -> np.ndarray | None:
    """(n, n) bool module matrix (True = dark) of a zxing-cpp Barcode, upright (V1 top-left), or None.

    zxing-cpp's ``Barcode.to_image(scale=1, add_quiet_zones=False)`` renders the symbol's module
    matrix as it was sampled when decoding (0 = dark, 255 = light), upright whatever the code's
    rotation in the image (checked in tests against segno's own matrices).
    """
    try:
        image = np.asarray(barcode.to_image(scale=1, add_hrt=False, add_quiet_zones=False))  # type: ignore[attr-defined]
    except Exception:  # an older zxing-cpp without to_image, or a barcode without a symbol
        return None
    if image.ndim != 2 or image.shape[0] != image.shape[1] or (image.shape[0] - 17) % 4:
        return None
    return image < 128


#: Blur widths (std, image px, besides the pixel's footprint) tried by :func:`blur_verified_matrix`.
BLUR_CANDIDATES_PX = tuple(np.round(np.arange(0.3, 1.61, 0.1), 2))
#: A data module is set to the colour that explains the image better (least squares over the
#: blurred neighbourhood) only when that lowers the squared residual by more than this share of
#: a module's own (a whole flip's) effect; a module whose two colours are within it is unknown.
FLIP_MARGIN = 0.25
#: Largest share of the data modules that may be corrected: beyond it the matrix is not this code's.
MOST_CORRECTED = 0.1


def _module_kernel(sigma_modules: float | np.ndarray) -> np.ndarray:
    """Shares (..., 5) of modules -2..2 in a point's blurred view of a module's centre: a Gaussian of
    ``sigma_modules`` (std, in modules; a float or an array of them, one kernel each) over unit
    modules (elementwise: each kernel is the one its sigma alone gives)."""
    from qrfield.detect.reading import gauss_cdf

    d = np.arange(-2, 3, dtype=np.float64)
    s = np.maximum(np.asarray(sigma_modules, dtype=np.float64), 1e-3)[..., None]
    return gauss_cdf((d + 0.5) / s) - gauss_cdf((d - 0.5) / s)


@functools.lru_cache(maxsize=16)
def _band_index(size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and kernel taps (0..4 for offsets -2..2) of the entries of a (size, size) band
    of half-width 2 (row i, column i + offset)."""
    rows, taps = [], []
    for tap, k in enumerate(range(-2, 3)):
        i = np.arange(max(0, -k), min(size, size - k))
        rows.append(i)
        taps.append(np.full(len(i), tap))
    r, t = np.concatenate(rows), np.concatenate(taps)
    c = r + t - 2
    for a in (r, c, t):
        a.setflags(write=False)
    return r, c, t


def _bands(size: int, kernels: np.ndarray) -> np.ndarray:
    """(b, size, size) matrices of the 1-D blurs ``kernels`` (b, 5): row i of each holds the shares
    of cells i-2..i+2 (set entry by entry: each entry is one tap)."""
    r, c, t = _band_index(size)
    out = np.zeros((len(kernels), size, size))
    out[:, r, c] = kernels[:, t]
    return out


def _blur_fits(base: np.ndarray, seen: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of ``target`` (k,) on the columns ``base`` (k, 3) and -``seen[b]`` for each
    blur b (``seen``: (blurs, k)): the solutions (blurs, 4) and their squared residuals (blurs,).
    By the normal equations, all blurs at once (the three shared columns' products computed once);
    where one is singular, numpy's lstsq for each (as one by one)."""
    count = len(seen)
    normal = np.empty((count, 4, 4))
    normal[:, :3, :3] = base.T @ base
    cross = -(seen @ base)  # (blurs, 3): the darkness column (-seen) against the basis
    normal[:, :3, 3] = normal[:, 3, :3] = cross
    normal[:, 3, 3] = np.einsum("bk,bk->b", seen, seen)
    rhs = np.empty((count, 4))
    rhs[:, :3] = base.T @ target
    rhs[:, 3] = -(seen @ target)
    try:
        solutions = np.linalg.solve(normal, rhs[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        basis = np.empty((len(target), 4))
        basis[:, :3] = base
        solutions = np.empty((count, 4))
        for b in range(count):
            basis[:, 3] = -seen[b]
            solutions[b] = np.linalg.lstsq(basis, target, rcond=None)[0]
    fitted = solutions[:, :3] @ base.T - solutions[:, 3:] * seen  # (blurs, k)
    fitted -= target
    return solutions, np.einsum("bk,bk->b", fitted, fitted)


def blur_verified_matrix(
    values: np.ndarray, matrix: np.ndarray, module_px: tuple[float, float]
) -> np.ndarray | None:
    """The decoded (n, n) ``matrix`` (bool, or float with NaN for unknown) checked against the image
    with the blur modelled: a float matrix (1 dark, 0 light), with the modules the decoder misread
    corrected and NaN where neither colour explains the image clearly; None when it does not agree
    with the image (more than MOST_CORRECTED of the data modules to correct).

    ``values`` (n + 2 Q, n + 2 Q) are the grey levels at the centres of the cells of the cell map
    (module rows y from V1 towards V4, columns x from V1 towards V2, Q = QUIET_RINGS rings of the
    quiet zone around), sampled at corners a few tenths of a pixel off at most; ``module_px`` (x, y)
    the module's size (px) along the columns and the rows.

    At modules of 1.2-2 px under a blur of about a module, a module's centre reads as much of its
    neighbours as of itself: zxing-cpp's sampled matrix then holds misread modules (9 of 625 on a
    far frontal card at 1.4 px) and the plain check of :func:`verified_matrix` passes some of them
    (4 of those 9), which pull the fit (V3 0.15 px off at a std of 0.05). Here every centre's grey
    level is predicted from the matrix through a Gaussian blur over the modules (its width, and
    the light level with its slope and the contrast, fitted on the fixed patterns and the quiet
    zone), and the data modules are flipped one at a time, the one that lowers the squared
    residual of its 5 x 5 neighbourhood most first, while a flip lowers it by more than FLIP_MARGIN
    of its own effect.
    """
    q = QUIET_RINGS
    m = np.asarray(matrix, dtype=np.float64)
    n = m.shape[0]
    values = np.asarray(values, dtype=np.float64)
    size = n + 2 * q
    if values.shape != (size, size) or m.shape != (n, n):
        raise ValueError(f"values must be ({size}, {size}) for a matrix of {n}, got {values.shape}")
    fixed = fixed_cells(n)
    known = np.isfinite(fixed) & np.isfinite(values)
    data = np.zeros((size, size), dtype=bool)
    data[q:-q, q:-q] = np.isnan(fixed[q:-q, q:-q]) & np.isfinite(m) & np.isfinite(values[q:-q, q:-q])
    cells = np.where(np.isfinite(fixed), fixed, 0.5)
    cells[data] = (np.pad(m, q) > 0.5)[data]
    if known.sum() < 50 or data.sum() < 10:
        return None
    rows, cols = np.mgrid[0:size, 0:size] / size - 0.5
    # Every blur at once: its kernels (elementwise), the predicted darkness at the centres (batched
    # products) and its least squares for the light level, its slopes and the contrast by the
    # normal equations (the basis 1, x, y is shared; only the darkness column changes), the blur
    # whose fit leaves the smallest squared residual kept (the first of equals).
    widths = np.sqrt(np.asarray(BLUR_CANDIDATES_PX) ** 2 + 1.0 / 12.0)
    bands_x = _bands(size, _module_kernel(widths / max(module_px[0], 1e-6)))
    bands_y = _bands(size, _module_kernel(widths / max(module_px[1], 1e-6)))
    seen = (bands_y @ cells @ bands_x.transpose(0, 2, 1)).reshape(len(widths), -1)[:, known.ravel()]
    target = values[known]
    base = np.empty((len(target), 3))
    base[:, 0], base[:, 1], base[:, 2] = 1.0, cols[known], rows[known]
    solutions, costs = _blur_fits(base, seen, target)
    choice = int(np.argmin(costs))
    ky, kx = bands_y[choice], bands_x[choice]
    a0, au, av, contrast = solutions[choice]
    if abs(contrast) < 1e-6:
        return None
    darkness = (a0 + au * cols + av * rows - values) / contrast
    darkness = np.where(np.isfinite(darkness), darkness, 0.0)
    self_effect = np.sum(ky * ky, axis=0)[:, None] * np.sum(kx * kx, axis=0)[None, :]
    residual = darkness - ky @ cells @ kx.T
    flips = 0
    most = max(1, int(MOST_CORRECTED * data.sum()))
    while True:
        gain = ky.T @ residual @ kx  # sum over each cell's neighbourhood of its share times the residual
        sign = 1.0 - 2.0 * cells  # +1 to darken a light module, -1 to lighten a dark one
        change = -2.0 * sign * gain + self_effect  # the change of the squared residual on a flip
        change = np.where(data, change, np.inf)
        j = np.unravel_index(int(np.argmin(change)), change.shape)
        if not change[j] < -FLIP_MARGIN * self_effect[j]:
            break
        flips += 1
        if flips > most:
            return None
        cells[j] = 1.0 - cells[j]
        residual -= sign[j] * np.outer(ky[:, j[0]], kx[:, j[1]])
    gain = ky.T @ residual @ kx
    change = -2.0 * (1.0 - 2.0 * cells) * gain + self_effect
    unsure = data & (np.abs(change) < FLIP_MARGIN * self_effect)
    out = np.where(data & ~unsure, cells, np.nan)[q:-q, q:-q]
    inner_fixed = np.isfinite(fixed[q:-q, q:-q])
    return np.where(inner_fixed, fixed[q:-q, q:-q], out)
