"""What a detector reports for one QR code, and the detector's settings."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from qrfield.settings import setting


@dataclass(frozen=True)
class Detection:
    """One QR code found in an image.

    Attributes:
        corners_px: (4, 2) float pixels of V1..V4 (docs/conventions.md: V1 the outer corner of the top-left
            finder pattern, V2 top-right, V3 bottom-right (no finder pattern), V4 bottom-left, following
            the code when it is rotated); OpenCV pixel convention (top-left pixel centre = (0, 0)).
        text: the decoded payload, or None when it could not be read.
        quality: 0..1, see :func:`quality_of`: the *pattern score* (the share of the symbol's fixed
            modules - finder patterns, separators, timing patterns, first ring of the quiet zone -
            that show the expected colour at these corners: about 0.5 for corners that are not on
            a code, near 1 for a good detection), lowered when the corners' uncertainty is above
            GOOD_CORNER_STD_PX. quality >= GOOD_QUALITY (0.85) means sub-pixel corners from the
            whole-symbol fit that check out and whose uncertainty is small. Corners of the edge-line
            fallback (no covariance) get at most FALLBACK_QUALITY_FACTOR of their score, unrefined
            corners (the backend's, about 1 px off and V3 sometimes several px) half of it.
        corner_quality: (4,) px, smaller is better. With the whole-symbol fit (``corners_cov`` set):
            each corner's standard uncertainty (RMS radius, the square root of its covariance's
            trace). With the edge-line fallback: the RMS distance of the sub-pixel edge points to
            the two fitted sides that meet there. NaN when not refined.
        backend: which backend found the code ("zxing", "zxing-x2", "finders", "opencv-aruco",
            "opencv"), or "track" when the tracker re-found it by refinement alone.
        refined: True when the corners are the sub-pixel fit, False when they are the backend's.
        modules: modules per side of the symbol (21 for version 1).
        symbol: the decoded (n, n) module matrix as the image confirms it (float: 1 dark, 0 light,
            NaN for a module the decoder misread or the image leaves in doubt; row 0 and column 0
            at V1), None when the text was not decoded with a module matrix.
        fit_state: the whole-symbol fit's edge width and lighting (qrfield.detect.symbol_fit.FitState),
            from which a tracker starts warm; None without that fit.
        corners_cov: (4, 2, 2) covariance of V1..V4 in px^2 from the whole-symbol fit (its residual
            noise and Jacobian, qrfield.detect.symbol_fit), None when unknown.
    """

    corners_px: np.ndarray
    text: str | None
    quality: float
    corner_quality: np.ndarray
    backend: str
    refined: bool
    modules: int = 0
    symbol: np.ndarray | None = field(default=None, repr=False, compare=False)
    fit_state: Any = field(default=None, repr=False, compare=False)
    corners_cov: np.ndarray | None = None

    def __post_init__(self) -> None:
        corners = np.array(self.corners_px, dtype=np.float64)
        if corners.shape != (4, 2):
            raise ValueError(f"Detection.corners_px must have shape (4, 2) (V1..V4, px), got {corners.shape}")
        cq = np.array(self.corner_quality, dtype=np.float64).reshape(-1)
        if cq.shape != (4,):
            raise ValueError(f"Detection.corner_quality must have 4 values (px per corner), got {cq.shape}")
        corners.setflags(write=False)
        cq.setflags(write=False)
        object.__setattr__(self, "corners_px", corners)
        object.__setattr__(self, "corner_quality", cq)
        if self.corners_cov is not None:
            cov = np.array(self.corners_cov, dtype=np.float64)
            if cov.shape != (4, 2, 2):
                raise ValueError(f"Detection.corners_cov must have shape (4, 2, 2) (px^2), got {cov.shape}")
            cov.setflags(write=False)
            object.__setattr__(self, "corners_cov", cov)

    @property
    def corners_std_px(self) -> np.ndarray:
        """(4,) RMS radius of each corner's uncertainty, px (docs/conventions.md); NaN when unknown."""
        if self.corners_cov is None:
            return np.full(4, np.nan)
        return np.sqrt(np.trace(self.corners_cov, axis1=1, axis2=2))

    @property
    def module_px(self) -> float:
        """Mean side of the quadrilateral V1..V4 over the modules per side, px (21 modules when
        the count is unknown)."""
        sides = np.linalg.norm(np.roll(self.corners_px, -1, axis=0) - self.corners_px, axis=1)
        return float(sides.mean()) / (self.modules or 21)

    @property
    def pose_cov(self) -> np.ndarray:
        """(4, 2, 2) px^2: the covariance to solve the pose with. ``corners_cov`` when the fit gave
        one; else an assumed one, isotropic per corner, of :data:`EDGE_LINE_STD_MODULES` (refined
        corners of the edge-line fallback) or :data:`UNREFINED_STD_MODULES` (the backend's own
        corners) modules per coordinate: what such corners are off by on the hard benchmark set, so
        that the pose's std is honest for them too (docs/uncertainty.md)."""
        if self.corners_cov is not None:
            return self.corners_cov
        per_module = EDGE_LINE_STD_MODULES if self.refined else UNREFINED_STD_MODULES
        std = np.maximum(np.asarray(per_module) * self.module_px, MIN_ASSUMED_STD_PX)
        return np.eye(2)[None] * (std**2)[:, None, None]

    @property
    def untrusted(self) -> str:
        """Why no pose from these corners may be given as good, or "" when one may: corners that
        were not refined are the backend's own (about 1 px off, V3 often several px, once 17.9 px
        on the hard set), and nothing measures how far off they are here."""
        if self.refined:
            return ""
        return (
            f"the corners are the {self.backend} backend's, not refined (quality {self.quality:.2f}): "
            "they can be several px off, so no pose is given as good"
        )

    @property
    def area_px(self) -> float:
        """Area of the quadrilateral V1..V4 in square pixels (shoelace)."""
        x, y = self.corners_px[:, 0], self.corners_px[:, 1]
        return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))

    def to_json_dict(self) -> dict[str, Any]:
        """JSON-ready dict: corners as [[u, v], ...] V1..V4 in px, NaN written as null."""

        def num(value: float) -> float | None:
            return None if not math.isfinite(value) else round(float(value), 4)

        return {
            "corners": [[num(u), num(v)] for u, v in self.corners_px],
            "text": self.text,
            "quality": num(self.quality),
            "corner_quality_px": [num(q) for q in self.corner_quality],
            "corners_std_px": [num(q) for q in self.corners_std_px],
            "backend": self.backend,
            "refined": self.refined,
            "modules": self.modules,
        }


#: Assumed standard uncertainty per coordinate of corners without a covariance, in modules, for
#: V1..V4: the edge-line fallback's and a backend's own corners. Measured on the hard benchmark set
#: (seeds 2024 and 7, 400 views each; qrfield benchmark detect with symbol_fit or refine off): the
#: 95th percentile of |error| per coordinate is 0.19-0.26 modules at V1, V2, V4 and 0.68-0.75 at
#: V3 (extrapolated) for the edge lines, 0.39-0.45 and 0.71-0.75 for the backends' corners; these
#: are about half of that (2 std), with heavy tails beyond.
EDGE_LINE_STD_MODULES = (0.12, 0.12, 0.35, 0.12)
UNREFINED_STD_MODULES = (0.22, 0.22, 0.37, 0.22)
#: Least assumed standard uncertainty per coordinate, px.
MIN_ASSUMED_STD_PX = 0.1
#: Largest corner uncertainty (RMS radius, px) of a detection that may be reported as good.
GOOD_CORNER_STD_PX = 0.1
#: Quality from which a detection counts as good (sub-pixel, checked, small uncertainty).
GOOD_QUALITY = 0.85
#: Corners of the edge-line fallback have no covariance: their quality is at most this share of
#: their pattern score, below GOOD_QUALITY (the whole-symbol fit failed or fitted worse there).
FALLBACK_QUALITY_FACTOR = 0.8


def quality_of(score: float, corners_cov: np.ndarray | None) -> float:
    """Quality of refined corners: the pattern score times min(1, GOOD_CORNER_STD_PX / the largest
    corner uncertainty), or times FALLBACK_QUALITY_FACTOR when the uncertainty is unknown."""
    if corners_cov is None:
        return FALLBACK_QUALITY_FACTOR * score
    c = np.asarray(corners_cov).reshape(-1).tolist()  # (4, 2, 2); floats: every tracked frame runs this
    traces = [c[4 * i] + c[4 * i + 3] for i in range(4)]
    if not all(math.isfinite(t) and t >= 0.0 for t in traces):
        return FALLBACK_QUALITY_FACTOR * score
    std = math.sqrt(max(traces))
    if not math.isfinite(std):
        return FALLBACK_QUALITY_FACTOR * score
    return score * min(1.0, GOOD_CORNER_STD_PX / max(std, 1e-12))


def _check_backends(spec: str) -> None:
    """The backends setting's rule (BackendError, a ValueError, for an unknown name), so a wrong
    name stops a run at start rather than leaving it without a detector."""
    from qrfield.detect.backends import parse_backends  # the backends import this module

    parse_backends(spec)


@dataclass(frozen=True)
class DetectorSettings:
    """Settings of QR detection, refinement, tracking and selection (see qrfield.settings)."""

    backends: str = setting(
        "zxing,zxing-x2,finders,small,steep",
        label="detector backends",
        help="comma-separated, tried in order until one finds a code: zxing, zxing-x2 (zxing on the "
        "image upscaled 2x, for small codes), finders (finder patterns by contours, for strong "
        "perspective), small (finder patterns in busy regions upscaled 3x and sharpened, for "
        "modules of 1.2-3 px), steep (finder patterns by correlation in busy regions compressed by "
        "a steep tilt, stretched back), opencv-aruco, opencv",
        check=_check_backends,
    )
    refine: bool = setting(
        True, label="sub-pixel refinement", help="fit the symbol's outer edges for sub-pixel corners"
    )
    symbol_fit: bool = setting(
        True,
        label="whole-symbol fit",
        help="refine the corners by fitting a model of the whole symbol (every known edge, through "
        "the camera's lens) to the image, with a covariance per corner; off: the outer edges only",
    )
    search_px: float = setting(
        2.5,
        label="refinement search window",
        unit="px",
        minimum=0.5,
        maximum=10.0,
        help="how far the true edges may lie from the backend's corners",
    )
    min_quality: float = setting(
        0.85,
        label="minimum quality",
        minimum=0.0,
        maximum=1.0,
        help="share of the fixed QR modules (finders, timing, quiet zone) that must check out at the "
        "corners (the pattern score); below it a code is dropped",
    )
    require_text: bool = setting(
        True, label="require decoded text", help="drop codes whose text could not be read (safer corners)"
    )
    select_text: str = setting(
        "",
        label="code text to follow",
        help="with several codes in view, use the one with this text (none if absent); empty = the largest. "
        "Codes read with another text are reported with the backend's corners, unrefined (no pose)",
    )
    max_codes: int = setting(
        0,
        label="most codes per frame",
        minimum=0,
        maximum=64,
        help="refine and report at most this many codes per frame, the largest first (0 = every code "
        "in view); the costly refinement is skipped for the others",
    )
    track: bool = setting(
        True,
        label="track between frames",
        help="in video, search around the last corners before the whole frame",
    )
    redetect_frames: int = setting(
        30,
        label="full-frame check every",
        unit="frames",
        minimum=0,
        maximum=100000,
        help="while tracking, a full-frame detection every this many frames picks up codes that came "
        "into view (0 = only when a tracked code is lost)",
    )
    track_margin_px: float = setting(
        24.0,
        label="tracking search margin",
        unit="px",
        minimum=0.0,
        maximum=1000.0,
        help="how far beyond the last corners the tracker looks (plus a quarter of the code's size)",
    )
