"""Full-frame QR detection: backends in order, sub-pixel refinement, checks; never raises on image content."""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np

from qrfield.camera import CameraModel
from qrfield.detect.backends import Candidate, find_candidates, parse_backends
from qrfield.detect.bilinear import sample_bilinear
from qrfield.detect.detection import Detection, DetectorSettings, quality_of
from qrfield.detect.lens import Lens, module_points_px
from qrfield.detect.patterns import PatternCheck, best_module_count, check_patterns, small_median
from qrfield.detect.refine import refine_corners
from qrfield.detect.symbol import (
    QUIET_RINGS,
    blur_verified_matrix,
    decoded_cells,
    fixed_cells,
    verified_matrix,
)
from qrfield.detect.symbol_fit import FitState, fit_symbol
from qrfield.geometry import shortest_module_px
from qrfield.settings import validated


class DetectorInputError(ValueError):
    """The image is not a numpy uint8 grey (H, W) or colour (H, W, 3|4) array."""


def as_grey(image: np.ndarray) -> np.ndarray:
    """(H, W) uint8 grey view of a grey, BGR or BGRA uint8 image; DetectorInputError otherwise."""
    import cv2

    if not isinstance(image, np.ndarray):
        raise DetectorInputError(f"image must be a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise DetectorInputError(f"image must be uint8 (0..255), got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 2:
        return np.ascontiguousarray(image)
    if image.ndim == 3 and image.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        if image.strides[1:] != (image.shape[2], 1):  # not a crop of a packed image: pack it first
            image = np.ascontiguousarray(image)
        return cv2.cvtColor(image, code)  # a crop (rows with a stride) is read in place
    raise DetectorInputError(f"image must be (H, W) grey or (H, W, 3) BGR, got shape {image.shape}")


#: An unrefined detection's quality is its pattern score times this: its corners are the backend's
#: (about 1 px, V3 sometimes several px off), checked only to within a fraction of a module.
UNREFINED_QUALITY_FACTOR = 0.5
#: Pattern score an unrefined detection needs (its text was decoded; checking rough corners against
#: modules of 1-2 px is noisy, so the bar is lower than ``min_quality``).
UNREFINED_MIN_SCORE = 0.7
#: Smallest module (px, along the code's shortest side) whose cold detection takes the
#: inverse-compositional fit (:meth:`Detector.refine_cold`); smaller modules take the edge lines
#: and the full fit. (The smallest the backends read; below BLUR_CHECK_MODULE_PX the decoded
#: matrix is checked with the blur modelled.)
COLD_FIT_MIN_MODULE_PX = 1.2
#: Below this module (px, along the shortest side) the cold fit's matrix is checked with the blur
#: modelled (:func:`blur_confirmed`), misread modules corrected, at the coarse corners and again at
#: the fitted ones: the plain check passed misread modules of a far frontal card at 1.4 px, and
#: the fit settled with V3 0.15-0.2 px off at a std of 0.03-0.06 px in every frame
#: (docs/detection.md, "Cold detection").
BLUR_CHECK_MODULE_PX = 2.0
#: How much worse (pattern score) a code under BLUR_CHECK_MODULE_PX may check out at the cold fit's
#: corners than at the backend's (0.02 above): at 1.4 px the score at the backend's corners was
#: 0.93-0.95 and at corners within 0.03 px of the truth 0.90, and the gate sent 35 of 82 cold
#: frames of a far frontal card to the full fit, whose own gate refused them too.
PATTERN_SLACK_BLURRED = 0.05


#: Cells (modules) per side of the block at each corner whose colours must back that corner: the
#: symbol's 8 modules nearest the corner (V1, V2, V4: the finder pattern and its separator) and
#: the QUIET_RINGS rings of quiet zone beyond it.
CORNER_BLOCK_CELLS = 8 + QUIET_RINGS
#: Least share of a corner's block (its known cells: the fixed patterns and the data modules the
#: image confirmed) that must show its colour at the fitted corners for the corner's own
#: covariance to stand. Below it (a glare spot on a finder pattern, a finger or another card over
#: the corner) the corner is extrapolated from the rest of the symbol and can be 0.5-1 px off at a
#: std of 0.02-0.08 px (docs/detection.md, "Adversity"); its covariance is widened to what a
#: backend's own corner is off by (UNREFINED_STD_MODULES), so it is not reported good and its
#: pose's std covers it. On the hard set's good detections the least block share is 0.80 (seed
#: 2024, 150 views; modules of 1.3-1.6 px), on the adversity set's wrong ones 0.63-0.67.
MIN_CORNER_SUPPORT = 0.75


#: Grey level from which a pixel is taken as clipped (a specular glare spot's core).
SATURATED_GREY = 250.0
#: A refined code with at least this many of its dark modules (the darker colour's cells of the
#: decoded matrix, else of the fixed patterns) reading SATURATED_GREY or more at their centres
#: lies under a glare spot: the clipped pixels, outliers the fit's Huber weights bound but do not
#: drop, pull every corner by 0.1-0.25 px, 3-6 times the fit's std (adversity set, seed 3031).
GLARE_MIN_CELLS = 2
#: Each corner's std is then taken GLARE_STD_FACTOR times larger (its covariance times the square).
GLARE_STD_FACTOR = 3.0


def glare_cells(
    grey: np.ndarray, corners: np.ndarray, cells: np.ndarray, inverted: bool, lens: Lens | None = None
) -> int:
    """How many of the darker-colour cells of the cell map ``cells`` (dark modules; light ones for
    an ``inverted`` code) read SATURATED_GREY or more at their centres, at ``corners`` V1..V4 px."""
    n = cells.shape[0] - 2 * QUIET_RINGS
    rows, cols = np.nonzero(cells < 0.5 if inverted else cells > 0.5)
    if not rows.size:
        return 0
    xy = np.column_stack([cols + 0.5 - QUIET_RINGS, rows + 0.5 - QUIET_RINGS])
    values = sample_bilinear(grey, module_points_px(lens, corners, n, xy))
    return int(np.sum(values >= SATURATED_GREY))


#: Least share of a decoded matrix's modules that must show their colour in the image (sampled at
#: module centres from the starting corners) for the fit to use the data modules; else (a matrix
#: of another code, mirrored, or corners too far off) the fixed patterns alone are fitted.
MATRIX_AGREEMENT = 0.85


@dataclass(frozen=True)
class Refined:
    """Corners after refinement (see :meth:`Detector.refine`)."""

    corners_px: np.ndarray
    corners_cov: np.ndarray | None
    corner_quality: np.ndarray
    score: float
    refined: bool
    fit_state: FitState | None = None
    residual: float = np.nan
    cells: np.ndarray | None = None
    #: the decoded module matrix as confirmed by the image (float, NaN where not), when decoded
    matrix: np.ndarray | None = None


@functools.lru_cache(maxsize=32)
def _module_centres(n: int) -> np.ndarray:
    """Module coordinates (n * n, 2) of the centres of an n x n grid, row by row (read-only, cached:
    every cold refinement samples them two to four times)."""
    out = np.stack(np.meshgrid(np.arange(n) + 0.5, np.arange(n) + 0.5), axis=-1).reshape(-1, 2)
    out.setflags(write=False)
    return out


def matrix_agrees(
    grey: np.ndarray,
    corners: np.ndarray,
    matrix: np.ndarray,
    inverted: bool,
    lens: Lens | None = None,
    offset: tuple[int, int] = (0, 0),
) -> bool:
    """True when the (n, n) module matrix (bool, or float with NaN for unknown) shows its colours at
    ``corners`` V1..V4 in ``grey`` (see :func:`confirmed_matrix`)."""
    return confirmed_matrix(grey, corners, matrix, inverted, lens, offset) is not None


def confirmed_matrix(
    grey: np.ndarray,
    corners: np.ndarray,
    matrix: np.ndarray,
    inverted: bool,
    lens: Lens | None = None,
    offset: tuple[int, int] = (0, 0),
) -> np.ndarray | None:
    """The decoded (n, n) ``matrix`` (bool, or float with NaN for unknown) as the image at
    ``corners`` V1..V4 confirms it (float: 1 dark, 0 light, NaN where a module's centre reads the
    other colour or too near the middle: :func:`qrfield.detect.symbol.verified_matrix`), or None
    when it does not agree with the image: fewer than :data:`MATRIX_AGREEMENT` of its known
    modules on the right side of the middle between the dark and light modules' medians (the
    levels of the confirmation too). One sampling of the module centres for both."""
    n = matrix.shape[0]
    values = sample_bilinear(grey, module_points_px(lens, corners, n, _module_centres(n), offset))
    m = np.asarray(matrix, dtype=np.float64).reshape(-1)
    known = np.isfinite(m) & np.isfinite(values)
    if known.mean() < 0.5:
        return None
    seen, dark = values[known], m[known] > 0.5
    if dark.all() or not dark.any():
        return None
    dark_level, light_level = small_median(seen[dark]), small_median(seen[~dark])
    threshold = 0.5 * (dark_level + light_level)
    seen_dark = seen > threshold if inverted else seen < threshold
    if float(np.mean(seen_dark == dark)) < MATRIX_AGREEMENT:
        return None
    return verified_matrix(values.reshape(n, n), matrix, dark_level, light_level)


def corner_support(
    grey: np.ndarray,
    corners: np.ndarray,
    cells: np.ndarray,
    check: PatternCheck,
    lens: Lens | None = None,
    offset: tuple[int, int] = (0, 0),
) -> np.ndarray:
    """(4,) share of each corner's block (CORNER_BLOCK_CELLS square of the cell map ``cells`` at
    V1..V4, known cells only) whose centre shows its colour at ``corners`` (px of ``grey``, a crop
    at ``offset``), by the threshold between ``check``'s dark and light levels; NaN for a corner
    with no known cell in view."""
    size = cells.shape[0]
    n = size - 2 * QUIET_RINGS
    block = CORNER_BLOCK_CELLS
    threshold = 0.5 * (check.dark + check.light)
    out = np.full(4, np.nan)
    if not np.isfinite(threshold):
        return out
    for k, (r0, c0) in enumerate(
        ((0, 0), (0, size - block), (size - block, size - block), (size - block, 0))
    ):
        part = cells[r0 : r0 + block, c0 : c0 + block]
        rows, cols = np.nonzero(np.isfinite(part))
        if not rows.size:
            continue
        xy = np.column_stack([c0 + cols + 0.5 - QUIET_RINGS, r0 + rows + 0.5 - QUIET_RINGS])
        values = sample_bilinear(grey, module_points_px(lens, corners, n, xy, offset))
        seen = np.isfinite(values)
        if not seen.any():
            continue
        dark = part[rows, cols] > 0.5
        seen_dark = values > threshold if check.inverted else values < threshold
        out[k] = float(np.mean((seen_dark == dark)[seen]))
    return out


def backed_cov(
    grey: np.ndarray,
    corners: np.ndarray,
    cov: np.ndarray,
    cells: np.ndarray | None,
    lens: Lens | None = None,
) -> np.ndarray:
    """The fit's corner covariance ``cov`` (4, 2, 2) px^2, with each corner whose block the image
    does not back (:func:`corner_support` below MIN_CORNER_SUPPORT) widened to at least the
    assumed covariance of a backend's own corner (UNREFINED_STD_MODULES modules per coordinate)."""
    from qrfield.detect.detection import MIN_ASSUMED_STD_PX, UNREFINED_STD_MODULES

    n = cells.shape[0] - 2 * QUIET_RINGS if cells is not None else 0
    if cells is None or n < 21:
        return cov
    check = check_patterns(grey, corners, n, lens)
    support = corner_support(grey, corners, cells, check, lens)
    weak = support < MIN_CORNER_SUPPORT
    if not weak.any():
        return cov
    sides = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    module = float(sides.mean()) / n
    out = np.array(cov, dtype=np.float64)
    for k in np.nonzero(weak)[0]:
        std = max(UNREFINED_STD_MODULES[k] * module, MIN_ASSUMED_STD_PX)
        out[k] = out[k] + np.eye(2) * max(std**2 - float(np.linalg.eigvalsh(out[k]).min()), 0.0)
    return out


def symbol_cells(
    grey: np.ndarray,
    corners: np.ndarray,
    modules: int,
    matrix: np.ndarray | None,
    inverted: bool,
    lens: Lens | None = None,
    offset: tuple[int, int] = (0, 0),
) -> np.ndarray:
    """The cell map to fit: the decoded matrix's when it agrees with the image, else the fixed patterns'."""
    if (
        matrix is not None
        and matrix.shape == (modules, modules)
        and matrix_agrees(grey, corners, matrix, inverted, lens, offset)
    ):
        return decoded_cells(matrix)
    return fixed_cells(modules)


def _area(corners: np.ndarray) -> float:
    """Area (px^2) of the quadrilateral V1..V4 (shoelace)."""
    x, y = corners[:, 0], corners[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


def same_code(a: np.ndarray, b: np.ndarray) -> bool:
    """True when corner sets ``a`` and ``b`` (4, 2) outline the same code (centres and sizes close)."""
    size_a = float(np.linalg.norm(a[2] - a[0]))
    size_b = float(np.linalg.norm(b[2] - b[0]))
    close = np.linalg.norm(a.mean(axis=0) - b.mean(axis=0)) < 0.2 * max(size_a, size_b)
    return bool(close and 0.7 < size_a / max(size_b, 1e-9) < 1.0 / 0.7)


class Detector:
    """Find QR codes in one image: corners V1..V4 (sub-pixel when refined), text, quality.

    Backends run in the order of ``settings.backends`` until one of them yields an accepted code
    (a fast one first, slower ones as fallbacks). Each candidate is checked against the symbol's
    fixed patterns (:mod:`qrfield.detect.patterns`), refined (:mod:`qrfield.detect.refine`) and kept
    only when its quality reaches ``settings.min_quality`` (and its text was read, if required).
    """

    def __init__(self, settings: DetectorSettings | None = None, camera: CameraModel | None = None) -> None:
        self.settings = validated(settings or DetectorSettings())
        self.backends = parse_backends(self.settings.backends)
        self.lens = Lens(camera)
        self._camera_set: CameraModel | None = None

    def set_camera(self, camera: CameraModel | None) -> None:
        """The camera model of the images to come (its lens is modelled by the whole-symbol fit);
        None for a pinhole. Its size must be the images' size."""
        if camera is not None and camera is self._camera_set:
            return  # the same model as the last frame's (the pipeline sets it on every frame)
        self._camera_set = camera
        lens_camera = camera if camera is not None and camera.has_distortion else None
        current = self.lens.camera
        if lens_camera is not current and not (lens_camera is not None and lens_camera == current):
            self.lens = Lens(lens_camera)

    def detect(self, image: np.ndarray, known: list[np.ndarray] | None = None) -> list[Detection]:
        """All accepted codes in a grey or BGR uint8 image of any size (empty list when none).

        ``known``: corner sets (4, 2) of codes already followed (a tracker's periodic look for new
        codes): candidates on them are skipped before the costly refinement.

        Raises DetectorInputError only for a wrong array type/shape; never for image content.
        """
        grey = as_grey(image)
        if grey.shape[0] < 21 or grey.shape[1] < 21:
            return []
        found: list[Detection] = []
        settings = self.settings
        most = settings.max_codes or None
        for backend in self.backends:
            skipped = False
            candidates = find_candidates(grey, backend, self.lens)
            if len(candidates) > 1 and most is not None:  # the largest first: they are the ones kept
                candidates.sort(key=lambda c: -_area(c.corners_px))
            for candidate in candidates:
                if most is not None and len(found) >= most:
                    break
                if any(same_code(candidate.corners_px, d.corners_px) for d in found):
                    continue  # the same code seen again
                if known and any(same_code(candidate.corners_px, k) for k in known):
                    skipped = True
                    continue
                # A code read with another text than the one selected is not refined (its corners
                # could give no pose the pipeline would use): reported with the backend's corners.
                other = bool(settings.select_text) and candidate.text not in (None, settings.select_text)
                detection = self.accept(grey, candidate, refine=not other)
                if detection is not None:
                    found.append(detection)
            if found or skipped:
                break
        return found

    @staticmethod
    def _seeds(grey: np.ndarray, corners: np.ndarray):
        """Starting corners for refinement: the backend's, then (only if those fail) the corners the
        finder-pattern locator finds for the same code in a crop around it (backends sometimes miss
        a corner by more than the search window)."""
        yield corners
        from qrfield.detect.finders import locate_by_finders

        h, w = grey.shape
        margin = 0.3 * float(np.ptp(corners, axis=0).max()) + 8.0
        x0, y0 = (max(int(v), 0) for v in np.floor(corners.min(axis=0) - margin))
        x1, y1 = (int(v) for v in np.minimum(np.ceil(corners.max(axis=0) + margin) + 1, (w, h)))
        if x1 - x0 < 21 or y1 - y0 < 21:
            return
        offset = np.array([x0, y0], dtype=np.float64)
        for located, _, _, _ in locate_by_finders(np.ascontiguousarray(grey[y0:y1, x0:x1]), decode=False):
            if same_code(located + offset, corners):
                yield located + offset

    def accept(
        self, grey: np.ndarray, candidate: Candidate, backend: str | None = None, refine: bool = True
    ) -> Detection | None:
        """Check and refine one backend candidate on a grey image; None when it does not hold up.
        ``refine`` False: checked only, the backend's corners kept (quality at most half the
        pattern score, not refined)."""
        settings = self.settings
        if not refine:
            settings = replace(settings, refine=False)
        corners = candidate.corners_px
        if corners.shape != (4, 2) or not np.all(np.isfinite(corners)):
            return None
        if not candidate.text and candidate.modules and settings.refine and settings.symbol_fit:
            read = self.read(grey, candidate)
            if read is not None:  # from the read fit's corners: a backend's V3 can be modules off
                candidate, corners = read, read.corners_px
        if settings.require_text and not candidate.text:
            return None
        if candidate.modules:
            rough = check_patterns(grey, corners, candidate.modules, self.lens)
        else:
            rough = best_module_count(grey, corners)
        if rough.reason and rough.score == 0.0:
            return None
        modules = rough.modules
        result = Refined(corners, None, np.full(4, np.nan), rough.score, False)
        if settings.refine:
            symbol = candidate.symbol
            cold = symbol is not None and settings.symbol_fit
            cold = cold and shortest_module_px(corners, modules) >= COLD_FIT_MIN_MODULE_PX
            result = self.refine_cold(grey, corners, modules, rough, symbol) if cold else None
            if result is None:  # the edge lines and the full fit, from each seed in turn
                seeds = self._seeds(grey, corners)
                result = self.refine(grey, corners, modules, rough.score, rough.inverted, symbol, seeds)
            if result is None:
                result = Refined(corners, None, np.full(4, np.nan), rough.score, False)
        score, refined = result.score, result.refined
        if score < min(settings.min_quality, UNREFINED_MIN_SCORE):
            return None
        if (not refined or score < settings.min_quality) and not candidate.text:
            # Unrefined corners, and corners whose patterns check out less well than min_quality
            # (a worn print, a real photo's glare), are only kept for a code whose text was read;
            # their quality stays below GOOD_QUALITY.
            return None
        cov, corner_quality = result.corners_cov, result.corner_quality
        if refined and cov is not None:
            cells = result.cells if result.cells is not None else fixed_cells(modules)
            backed = backed_cov(grey, result.corners_px, cov, cells, self.lens)
            decoded = candidate.symbol
            if decoded is not None and decoded.shape == (modules, modules):
                cells = decoded_cells(decoded)  # as decoded: glare makes the confirmed matrix NaN
            inverted = check_patterns(grey, result.corners_px, modules, self.lens).inverted
            if glare_cells(grey, result.corners_px, cells, inverted, self.lens) >= GLARE_MIN_CELLS:
                backed = np.asarray(backed) * GLARE_STD_FACTOR**2
            if backed is not cov:  # the image does not back the fit's own std
                cov = backed
                corner_quality = np.sqrt(np.trace(cov, axis1=1, axis2=2))
        quality = quality_of(score, cov) if refined else UNREFINED_QUALITY_FACTOR * score
        return Detection(
            result.corners_px,
            candidate.text,
            quality,
            corner_quality,
            backend or candidate.backend,
            refined,
            modules,
            symbol=result.matrix,
            fit_state=result.fit_state,
            corners_cov=cov,
        )

    def read(self, grey: np.ndarray, candidate: Candidate) -> Candidate | None:
        """A located code that no backend read: its fixed patterns fitted, then its modules read by
        least squares (qrfield.detect.reading); the candidate with the fitted corners, the text and
        the module matrix, or None when it cannot be read."""
        from qrfield.detect.reading import LOGISTIC_STD, read_symbol

        n = int(candidate.modules or 0)
        rough = check_patterns(grey, candidate.corners_px, n, self.lens)
        if rough.reason and rough.score == 0.0:
            return None
        # (The edge lines and the full fit: with the fixed patterns alone, at modules of 1.2-2 px, the
        # inverse-compositional fit left V3 a few px off where these do not: measured.)
        fit = self.refine(
            grey,
            candidate.corners_px,
            n,
            rough.score,
            rough.inverted,
            None,
            self._seeds(grey, candidate.corners_px),
        )
        # The bar of a decoded code (accept()): at 1.2-2 px modules the pattern score is noisy
        # (0.78-0.87 on well-fitted views); a successful decode is the stronger check.
        if (
            fit is None
            or fit.fit_state is None
            or fit.score < min(self.settings.min_quality, UNREFINED_MIN_SCORE)
        ):
            return None
        # The fit's edge spread is a logistic of width s besides the pixel's footprint: its std.
        blur = LOGISTIC_STD * fit.fit_state.edge_px
        # (an inverted code needs nothing: its contrast B comes out negative)
        text, matrix = read_symbol(grey, fit.corners_px, n, blur, self.lens)
        if text is None:
            return None
        return Candidate(fit.corners_px, text, candidate.backend, n, matrix)

    def refine_cold(
        self,
        grey: np.ndarray,
        corners: np.ndarray,
        modules: int,
        rough: PatternCheck,
        matrix: np.ndarray | None,
    ) -> Refined | None:
        """Sub-pixel corners from a backend's ``corners`` by the inverse-compositional fits of
        qrfield.detect.symbol_cold (a third of :meth:`refine`'s cost): the blurred model, the
        decoded matrix confirmed there (``matrix``: the backend's, None when not decoded: then the
        fixed patterns alone, which hold V3 less well), the sharp model at the pixel centres. None
        when that does not hold (then :meth:`refine` runs): a corner that moved more than max(3 px,
        2 modules), a matrix the image does not confirm, another polarity than the pattern
        check's (``rough``), a residual above a fifth of the contrast, or patterns that fit worse
        than at ``corners`` (by 0.02)."""
        from qrfield.detect.symbol_cold import coarse_fit, crop_around, fine_fit

        lens = self.lens
        region = crop_around(grey.shape, corners, modules)
        if region is None or not lens.fits(grey.shape) or not np.isfinite(rough.light - rough.dark):
            return None
        x0, y0, x1, y1 = region
        crop, offset = grey[y0:y1, x0:x1], (x0, y0)
        shift = np.array(offset, dtype=np.float64)
        decoded = matrix is not None and matrix.shape == (modules, modules)
        cells = decoded_cells(matrix) if decoded else fixed_cells(modules)
        coarse = coarse_fit(crop, corners - shift, cells, lens, rough.light, rough.dark, offset)
        if not coarse.ok or coarse.state is None:
            return None
        confirmed = None
        blurred = decoded and shortest_module_px(corners, modules) < BLUR_CHECK_MODULE_PX
        if decoded:
            confirmed = confirmed_matrix(grey, coarse.corners_px + shift, matrix, rough.inverted, lens)
            if confirmed is not None and blurred:
                confirmed = blur_confirmed(crop, coarse.corners_px, matrix, lens, offset)
            if confirmed is None:
                return None
            cells = decoded_cells(confirmed)
        fine = fine_fit(crop, coarse.corners_px, cells, lens, coarse.state, offset)
        if blurred and fine.ok and fine.state is not None:
            # Checked again at the fitted corners (the coarse ones can be 0.2-0.5 px off at these
            # sizes); fitted again when that changes the matrix.
            again = blur_confirmed(crop, fine.corners_px, matrix, lens, offset)
            if again is None:
                return None
            if not np.array_equal(again, confirmed, equal_nan=True):
                confirmed, cells = again, decoded_cells(again)
                fine = fine_fit(crop, fine.corners_px, cells, lens, fine.state, offset)
        if not fine.ok or fine.state is None or fine.corners_cov is None:
            return None
        fitted = fine.corners_px + shift
        module_px = float(np.ptp(corners, axis=0).max()) / modules
        moved = float(np.linalg.norm(fitted - corners, axis=1).max())
        if (
            moved > max(3.0, 2.0 * module_px)
            or (fine.contrast < 0) != rough.inverted
            or not fine.residual < 0.2 * abs(fine.contrast)
        ):
            return None
        check = check_patterns(grey, fitted, modules, lens)
        if check.score < rough.score - (PATTERN_SLACK_BLURRED if blurred else 0.02):
            return None
        return Refined(
            fitted,
            fine.corners_cov,
            fine.corners_std_px,
            check.score,
            True,
            fine.state,
            fine.residual,
            cells,
            confirmed,
        )

    def refine(
        self,
        grey: np.ndarray,
        corners: np.ndarray,
        modules: int,
        rough_score: float,
        inverted: bool,
        matrix: np.ndarray | None,
        seeds=None,
        offset: tuple[int, int] = (0, 0),
        image_shape: tuple[int, int] | None = None,
    ) -> Refined | None:
        """Sub-pixel corners from ``corners``: the edge-line fit (qrfield.detect.refine) from each
        seed until one holds, then the whole-symbol fit (qrfield.detect.symbol_fit) from there;
        the symbol fit's corners unless its residual is worse than the edge-line corners' on the
        same pixels. None when neither fit holds (the patterns must fit at least as well as at
        ``corners``, within 0.02)."""
        settings = self.settings
        start, edge, tried = corners, None, []
        for seed in seeds if seeds is not None else (corners,):
            tried.append(seed)
            fit = refine_corners(grey, seed, modules, inverted=inverted, search_px=settings.search_px)
            if not fit.ok:
                continue
            fine = check_patterns(grey, fit.corners_px, modules, self.lens, offset)
            # A refinement that makes the patterns fit worse is not trusted.
            if fine.score >= rough_score - 0.02:
                edge = Refined(fit.corners_px, None, fit.corner_rms_px, fine.score, True)
                start = fit.corners_px
                break
        if not settings.symbol_fit:
            return edge
        # The whole symbol from the edge lines' corners, else from each seed in turn (a backend
        # can miss a corner by several modules; the finder patterns' locator does not).
        for begin in [start] if edge is not None else tried:
            whole = self._whole(
                grey, begin, modules, rough_score, inverted, matrix, edge is not None, offset, image_shape
            )
            if whole is not None:
                return whole
        return edge

    def _whole(
        self,
        grey: np.ndarray,
        start: np.ndarray,
        modules: int,
        rough_score: float,
        inverted: bool,
        matrix: np.ndarray | None,
        from_edges: bool,
        offset: tuple[int, int],
        image_shape: tuple[int, int] | None,
    ) -> Refined | None:
        """The whole-symbol fit from ``start`` (see :meth:`refine`); None when it does not hold
        (or, from the edge lines' corners, fits worse than they do)."""
        lens = self.lens
        cells = symbol_cells(grey, start, modules, matrix, inverted, lens, offset)
        decoded = cells is not fixed_cells(modules)
        whole = fit_symbol(grey, start, cells, lens=lens, offset=offset, image_shape=image_shape)
        if whole.ok and not (from_edges and whole.residual > whole.start_residual):
            if decoded:
                # The decoder's matrix may hold misread modules: keep those the image confirms
                # at the fitted corners, and fit again if any was dropped.
                values = sample_bilinear(
                    grey, module_points_px(lens, whole.corners_px, modules, _module_centres(modules), offset)
                ).reshape(modules, modules)
                levels = check_patterns(grey, whole.corners_px, modules, lens, offset)
                checked = verified_matrix(values, matrix, levels.dark, levels.light)
                if shortest_module_px(whole.corners_px, modules) < BLUR_CHECK_MODULE_PX:
                    blurred = blur_confirmed(grey, whole.corners_px, matrix, lens, offset)
                    checked = checked if blurred is None else blurred
                as_decoded = np.asarray(matrix, dtype=np.float64)
                if not np.array_equal(
                    checked, np.where(np.isnan(as_decoded), np.nan, as_decoded > 0.5), equal_nan=True
                ):
                    again_cells = decoded_cells(checked)
                    again = fit_symbol(
                        grey,
                        whole.corners_px,
                        again_cells,
                        lens=lens,
                        offset=offset,
                        image_shape=image_shape,
                        coarse=False,
                        max_iter=3,
                        warm=whole.state,
                    )
                    if again.ok:
                        whole, cells = again, again_cells
                matrix = checked
            check = check_patterns(grey, whole.corners_px, modules, lens, offset)
            if check.score >= rough_score - 0.02:
                return Refined(
                    whole.corners_px,
                    whole.corners_cov,
                    whole.corners_std_px,
                    check.score,
                    True,
                    whole.state,
                    whole.residual,
                    cells,
                    matrix if decoded else None,
                )
        return None


def blur_confirmed(
    grey: np.ndarray,
    corners: np.ndarray,
    matrix: np.ndarray,
    lens: Lens | None = None,
    offset: tuple[int, int] = (0, 0),
) -> np.ndarray | None:
    """The decoded (n, n) ``matrix`` checked with the blur modelled at ``corners`` V1..V4 (px of
    ``grey``, a crop at ``offset``): misread modules corrected, NaN where unclear, None when it does
    not agree (:func:`qrfield.detect.symbol.blur_verified_matrix`; the cell centres sampled over
    the symbol and QUIET_RINGS rings of its quiet zone)."""
    n = matrix.shape[0]
    size = n + 2 * QUIET_RINGS
    centres = _module_centres(size) - QUIET_RINGS
    values = sample_bilinear(grey, module_points_px(lens, corners, n, centres, offset)).reshape(size, size)
    c = np.asarray(corners, dtype=np.float64)
    along_x = 0.5 * (np.linalg.norm(c[1] - c[0]) + np.linalg.norm(c[2] - c[3])) / n
    along_y = 0.5 * (np.linalg.norm(c[3] - c[0]) + np.linalg.norm(c[2] - c[1])) / n
    return blur_verified_matrix(values, matrix, (along_x, along_y))
