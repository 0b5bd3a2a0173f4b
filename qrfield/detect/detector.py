"""Full-frame QR detection: backends in order, sub-pixel refinement, checks; never raises on image content."""

from __future__ import annotations

import numpy as np

from qrfield.detect.backends import Candidate, find_candidates, parse_backends
from qrfield.detect.detection import Detection, DetectorSettings
from qrfield.detect.patterns import best_module_count, check_patterns
from qrfield.detect.refine import refine_corners
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
        return cv2.cvtColor(np.ascontiguousarray(image), code)
    raise DetectorInputError(f"image must be (H, W) grey or (H, W, 3) BGR, got shape {image.shape}")


#: An unrefined detection's quality is its pattern score times this: its corners are the backend's
#: (about 1 px, V3 sometimes several px off), checked only to within a fraction of a module.
UNREFINED_QUALITY_FACTOR = 0.5
#: Pattern score an unrefined detection needs (its text was decoded; checking rough corners against
#: modules of 1-2 px is noisy, so the bar is lower than ``min_quality``).
UNREFINED_MIN_SCORE = 0.7


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

    def __init__(self, settings: DetectorSettings | None = None) -> None:
        self.settings = validated(settings or DetectorSettings())
        self.backends = parse_backends(self.settings.backends)

    def detect(self, image: np.ndarray) -> list[Detection]:
        """All accepted codes in a grey or BGR uint8 image of any size (empty list when none).

        Raises DetectorInputError only for a wrong array type/shape; never for image content.
        """
        grey = as_grey(image)
        if grey.shape[0] < 21 or grey.shape[1] < 21:
            return []
        found: list[Detection] = []
        for backend in self.backends:
            for candidate in find_candidates(grey, backend):
                if any(same_code(candidate.corners_px, d.corners_px) for d in found):
                    continue  # the same code seen again
                detection = self.accept(grey, candidate)
                if detection is not None:
                    found.append(detection)
            if found:
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
        for located, _, _ in locate_by_finders(np.ascontiguousarray(grey[y0:y1, x0:x1]), decode=False):
            if same_code(located + offset, corners):
                yield located + offset

    def accept(self, grey: np.ndarray, candidate: Candidate, backend: str | None = None) -> Detection | None:
        """Check and refine one backend candidate on a grey image; None when it does not hold up."""
        settings = self.settings
        corners = candidate.corners_px
        if corners.shape != (4, 2) or not np.all(np.isfinite(corners)):
            return None
        if settings.require_text and not candidate.text:
            return None
        if candidate.modules:
            rough = check_patterns(grey, corners, candidate.modules)
        else:
            rough = best_module_count(grey, corners)
        if rough.reason and rough.score == 0.0:
            return None
        modules = rough.modules
        score, final, corner_quality, refined = rough.score, corners, np.full(4, np.nan), False
        if settings.refine:
            for seed in self._seeds(grey, corners):
                fit = refine_corners(
                    grey, seed, modules, inverted=rough.inverted, search_px=settings.search_px
                )
                if not fit.ok:
                    continue
                fine = check_patterns(grey, fit.corners_px, modules)
                # A refinement that makes the patterns fit worse is not trusted.
                if fine.score >= rough.score - 0.02:
                    score, final, corner_quality, refined = (
                        fine.score,
                        fit.corners_px,
                        fit.corner_rms_px,
                        True,
                    )
                    break
        if score < (settings.min_quality if refined else min(settings.min_quality, UNREFINED_MIN_SCORE)):
            return None
        if not refined and not candidate.text:
            return None  # unrefined corners are only trusted for a code whose text was read
        quality = score if refined else UNREFINED_QUALITY_FACTOR * score
        return Detection(
            final, candidate.text, quality, corner_quality, backend or candidate.backend, refined, modules
        )
