"""Tracking a QR code through video: look around the last corners first, the whole frame when lost.

Per frame and per code tracked, cheapest first:
1. fit the whole symbol (qrfield.detect.symbol_fit) warm: from the corners predicted by constant
   velocity, with the last frame's edge width and lighting, two Gauss-Newton steps, on the
   module layout of the first decode (no decoding: the text is carried over); the fit must still
   see the code (its contrast and residual) and the symbol's fixed patterns must check out there.
   When the warm fit from the prediction does not hold (a new track has no velocity yet; a code
   that swings back and forth is far from where constant velocity puts it), the move since the
   last frame is measured by phase correlation of a small patch around the code in both frames,
   and the warm fit starts from there (more steps, the patterns checked). If it does not hold,
   the full symbol fit, else the edge-line refinement and a full symbol fit, from the measured
   start (or the prediction when the move cannot be measured);
2. else run the first backend on a region around the prediction (``track_margin_px`` plus a quarter
   of the code's size), refine and check; the text must be the one tracked;
3. else (any code lost) a full-frame detection with every backend. Every ``redetect_frames``
   frames a full-frame detection also runs beside the tracking, to pick up codes that came into view.

Every fit of step 1 starts only a module or two from the code: all of them are local, and from
a start two modules off they can settle a fraction of a module to a module off (1.5-7 px at 5 px
modules, measured on the virtual bench wobbling 20-30 deg at 0.5 s), where the fixed patterns,
sampled at module centres, still check out. What tells such a fit from a right one is its residual:
right fits stay within MAX_RESIDUAL_GROWTH of the residual the track had when a backend last found
it (its *reference*, not the last frame's: a wrong fit let through would loosen the next frame's
bar); every fit of step 1 must pass that bar (docs/detection.md, "Tracking under fast motion").
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from qrfield.camera import CameraModel
from qrfield.detect.backends import Candidate, find_candidates
from qrfield.detect.detection import Detection, DetectorSettings, quality_of
from qrfield.detect.detector import Detector, Refined, as_grey, same_code, symbol_cells
from qrfield.detect.patterns import check_patterns
from qrfield.detect.symbol_fit import START_EDGE_PX, FitState, SymbolFit, fit_symbol
from qrfield.detect.symbol_track import WarmFit

#: Gauss-Newton steps of a warm fit: at most TRACK_ITERATIONS, stopping after a step that moved
#: no corner by TRACK_SETTLE_PX. From a prediction 0.1 px off one step of TEMPLATE_POINTS = 800
#: leaves about 0.02 px, less than a second step's own noise: it costs 20 % less than two steps of
#: 600 and its corners are better (issue 13h, docs/detection.md "Speed"). A prediction that
#: missed by more (a jerk) takes more steps here rather than the costly measured move.
TRACK_ITERATIONS = 3
TRACK_SETTLE_PX = 0.3
#: A fit of step 1 still sees the code while its residual stays below this share of its contrast ...
MAX_RESIDUAL_SHARE = 0.2
#: ... and below this multiple of the track's reference residual (the fit's when a backend last
#: found the code) plus 2 grey levels. On the virtual bench (noise 2, blur 0.6 px) right fits are
#: 0.75-1.2 times the reference, fits 1.5 px or more off 1.8-10 times (residual 8-46 grey levels
#: against 4-5): measured. 2.4 since issue 26 (2.0 before): a cold detection's reference (the
#: inverse-compositional fit's, qrfield.detect.symbol_cold) came out 16 % lower on one rendered
#: stream (2.07 against 2.47 grey levels), which sent two of its 60 frames to the full fit; on the
#: hard set's four sequences right warm fits are 1.51 times their reference in median (1.58
#: before), 2.03 at the 90th percentile (2.12), and the fast-swing tests give no wrong pose.
MAX_RESIDUAL_GROWTH = 2.4
#: A warm fit that settled (or ran out of steps) with a residual above this multiple of the
#: track's reference may not have converged: near a fast swing's turn at modules of 1.4 px the
#: steps along the code's perspective shrink below TRACK_SETTLE_PX while the far corner V3 is
#: still 1.5-3.4 px off (its covariance saying 0.2-0.5 px; seed 53 of ``qrfield benchmark
#: stream``, "fast swing far 1.4 px", frames 8-12: residual 2.1-2.8 times the reference). Such a
#: fit goes on for up to SETTLE_ITERATIONS more steps, stopping after one that moved no corner by
#: SETTLE_PX, and the further fit is kept when it explains the image at least as well. Right fits
#: are 1.2-1.4 times their reference in median, 1.4-2.1 at the 90th percentile on the stream
#: benchmark's tuning seeds 1 and 2: most frames take no further step.
SETTLE_RESIDUAL_GROWTH = 1.8
SETTLE_ITERATIONS = 6
SETTLE_PX = 0.05
#: Gauss-Newton steps of the warm fit from a measured move (a new track's first frame).
JUMP_ITERATIONS = 5
#: Side of the square patch (px) on which a new track's move is measured, and the margin (px)
#: around the code it covers beyond a quarter of the code's size.
MOTION_PATCH_PX = 128
MOTION_MARGIN_PX = 16.0
#: Least phase-correlation response for a measured move to be used.
MIN_MOTION_RESPONSE = 0.3


#: A grey crop of a frame and its offset (x, y) in the camera image.
_View = tuple[np.ndarray, tuple[int, int]]


@dataclass(frozen=True)
class _Motion:
    """A new track's patch for measuring its first move: the region (x0, y0, x1, y1) of the image
    around the code and that region resized to MOTION_PATCH_PX square (float32 grey)."""

    region: tuple[int, int, int, int]
    patch: np.ndarray


def _motion_patch(image: np.ndarray, region: tuple[int, int, int, int]) -> np.ndarray:
    import cv2

    x0, y0, x1, y1 = region
    grey = as_grey(image[y0:y1, x0:x1])
    size = (MOTION_PATCH_PX, MOTION_PATCH_PX)
    return cv2.resize(grey, size, interpolation=cv2.INTER_AREA).astype(np.float32)


def motion_reference(
    image: np.ndarray, corners: np.ndarray, offset: tuple[int, int] = (0, 0)
) -> _Motion | None:
    """The patch around ``corners`` (4, 2) px of the camera image to measure a move from, cut from
    ``image`` (grey or BGR): the camera image, or a crop of it at ``offset`` (x, y)."""
    h, w = image.shape[:2]
    ox, oy = offset
    margin = MOTION_MARGIN_PX + 0.25 * float(np.ptp(corners, axis=0).max())
    x0, y0 = (max(int(v), o) for v, o in zip(np.floor(corners.min(axis=0) - margin), offset, strict=True))
    x1, y1 = (
        min(int(v), m)
        for v, m in zip(np.ceil(corners.max(axis=0) + margin) + 1, (ox + w, oy + h), strict=True)
    )
    if x1 - x0 < 21 or y1 - y0 < 21:
        return None
    region = (x0, y0, x1, y1)
    return _Motion(region, _motion_patch(image, (x0 - ox, y0 - oy, x1 - ox, y1 - oy)))


def measured_move(reference: _Motion, image: np.ndarray) -> np.ndarray | None:
    """(dx, dy) px by which the content of the reference's region moved in ``image`` (phase
    correlation of the two patches, Hann-windowed), or None when the correlation is unsure."""
    import cv2

    x0, y0, x1, y1 = reference.region
    if image.shape[0] < y1 or image.shape[1] < x1:
        return None
    now = _motion_patch(image, reference.region)
    window = _hann(MOTION_PATCH_PX)
    (dx, dy), response = cv2.phaseCorrelate(reference.patch, now, window)
    if not response >= MIN_MOTION_RESPONSE:
        return None
    return np.array([dx * (x1 - x0) / MOTION_PATCH_PX, dy * (y1 - y0) / MOTION_PATCH_PX])


@functools.lru_cache(maxsize=2)
def _hann(size: int) -> np.ndarray:
    import cv2

    return cv2.createHanningWindow((size, size), cv2.CV_32F)


@dataclass
class _Track:
    detection: Detection
    previous_corners: np.ndarray | None = None
    inverted: bool = False
    cells: np.ndarray | None = None
    fit_state: FitState | None = None
    residual: float = np.nan
    warm: WarmFit | None = None
    #: the pattern score of the last check (the warm fit does not check the patterns each frame)
    score: float | None = None
    #: the patch around the code in the last frame, to measure the move when the prediction fails
    #: (made from ``last_view`` only then: most frames do not need it)
    motion: _Motion | None = None
    #: the grey crop of the last frame around the code and its offset (x, y) in the image
    last_view: _View | None = None
    #: the residual of the fit when a backend last found the code (the bar of every tracked fit)
    reference_residual: float = np.nan

    def reference(self) -> _Motion | None:
        """The last frame's patch to measure this frame's move from (None when there is none)."""
        if self.motion is None and self.last_view is not None:
            grey, offset = self.last_view
            self.motion = motion_reference(grey, self.detection.corners_px, offset)
            self.last_view = None
        return self.motion

    def predicted(self) -> np.ndarray:
        corners = self.detection.corners_px
        if self.previous_corners is None:
            return corners.copy()
        return corners + (corners - self.previous_corners)


def _fits_reference(residual: float, track: _Track) -> bool:
    """A tracked fit's ``residual`` (grey levels) is within MAX_RESIDUAL_GROWTH of the track's
    reference (True while the track has none: a backend's corners without a symbol fit)."""
    return not residual > MAX_RESIDUAL_GROWTH * track.reference_residual + 2.0


def _warm_holds(fit: SymbolFit, track: _Track) -> bool:
    """A fit of step 1 still sees the tracked code: its polarity, its residual against its contrast
    and against the track's reference."""
    return bool(
        fit.ok
        and (fit.contrast < 0) == track.inverted
        and fit.residual < MAX_RESIDUAL_SHARE * abs(fit.contrast)
        and _fits_reference(fit.residual, track)
    )


def _refined(fit: SymbolFit, score: float, cells: np.ndarray) -> Refined:
    return Refined(
        fit.corners_px, fit.corners_cov, fit.corners_std_px, score, True, fit.state, fit.residual, cells
    )


class Tracker:
    """Follow QR codes from frame to frame; ``update`` returns what :meth:`Detector.detect` would.

    Attributes:
        last_mode: how the last frame was processed: "refined" (step 1 for every code, on a crop
            around them), "roi" (step 2), "full" (full-frame detection), "recheck" (the frame
            detected again from scratch, :meth:`recheck`) or "" before the first frame.
    """

    def __init__(self, settings: DetectorSettings | None = None, camera: CameraModel | None = None) -> None:
        self.detector = Detector(settings, camera)
        self.settings = self.detector.settings
        self._tracks: list[_Track] = []
        self._frames_since_full = 0
        self.last_mode = ""

    def set_camera(self, camera: CameraModel | None) -> None:
        """The camera model of the frames to come (see Detector.set_camera)."""
        self.detector.set_camera(camera)

    def reset(self) -> None:
        """Forget the tracked codes: the next frame gets a full-frame detection."""
        self._tracks = []
        self.last_mode = ""

    def update(self, image: np.ndarray) -> list[Detection]:
        """Detections in the next video frame (grey or BGR uint8); never raises on image content."""
        self._frames_since_full += 1
        every = self.settings.redetect_frames
        due = bool(every) and self._frames_since_full >= every
        found: list[Detection] | None = None
        grey = None
        if self.settings.track and self._tracks:
            refined = self._refine_all(image)
            if refined is not None:
                found, view = refined
                self._advance(found, view)
                self.last_mode = "refined"
            else:
                grey = as_grey(image)
                found = self._search_all(grey)
                if found is not None:
                    self._advance(found, (grey, (0, 0)), refound=True)
                    self.last_mode = "roi"
        if found is not None and not due:
            return found
        grey = as_grey(image) if grey is None else grey
        known = [f.corners_px for f in found] if found is not None else None
        detections = self.detector.detect(grey, known)
        self._frames_since_full = 0
        if found is not None:
            # The periodic full look: keep the codes tracked (the backends may miss a code that
            # tracking holds), add the ones that came into view.
            new = [d for d in detections if not any(same_code(d.corners_px, f.corners_px) for f in found)]
            self._tracks += [self._new_track(grey, d) for d in new if self._follows(d)]
            return found + new
        self._tracks = [self._new_track(grey, d) for d in detections if self._follows(d)]
        self.last_mode = "full"
        return detections

    def recheck(self, image: np.ndarray) -> list[Detection]:
        """The frame just given to :meth:`update` detected again from scratch (every backend, as a
        full-frame detection), the tracks replaced by what it finds: for a caller that found the
        tracked corners wrong (qrfield.pipeline: their pose does not fit them). Never raises on
        image content."""
        grey = as_grey(image)
        detections = self.detector.detect(grey)
        self._frames_since_full = 0
        self._tracks = [self._new_track(grey, d) for d in detections if self._follows(d)]
        self.last_mode = "recheck"
        return detections

    def _follows(self, detection: Detection) -> bool:
        """Whether a detected code becomes a track: not one read with another text than the one
        selected (the detector reports it unrefined; following it would only cost)."""
        select = self.settings.select_text
        return not (select and detection.text is not None and detection.text != select)

    def _new_track(self, grey: np.ndarray, detection: Detection) -> _Track:
        lens = self.detector.lens
        check = check_patterns(grey, detection.corners_px, detection.modules, lens)
        cells = symbol_cells(
            grey, detection.corners_px, detection.modules, detection.symbol, check.inverted, lens
        )
        state = detection.fit_state
        if state is None and detection.corners_cov is not None and np.isfinite(check.light - check.dark):
            # Warm from the start: the light level and contrast the pattern check saw.
            state = FitState(START_EDGE_PX, np.array([check.light, 0, 0, check.light - check.dark, 0, 0]))
        motion = motion_reference(grey, detection.corners_px)
        reference = state.scale if state is not None and detection.fit_state is not None else np.nan
        return _Track(
            detection,
            inverted=check.inverted,
            cells=cells,
            fit_state=state,
            motion=motion,
            reference_residual=reference,
        )

    def _search_all(self, grey: np.ndarray) -> list[Detection] | None:
        """Step 2 for every track; None as soon as one is not found."""
        found = []
        for track in self._tracks:
            detection = self._search_around(grey, track)
            if detection is None:
                return None
            found.append(detection)
        return found

    def _advance(self, found: list[Detection], view: _View, refound: bool = False) -> None:
        """Move the tracks on to ``found`` in ``view``: the grey image, or a crop of it around the
        codes, and its offset (x, y); when ``refound`` (by a backend) the whole grey image."""
        grey, offset = view
        for track, detection in zip(self._tracks, found, strict=True):
            track.previous_corners = track.detection.corners_px
            if refound:  # re-read its polarity and layout, and its reference residual
                fresh = self._new_track(grey, detection)
                track.inverted, track.cells, track.fit_state = fresh.inverted, fresh.cells, fresh.fit_state
                track.motion, track.reference_residual = fresh.motion, fresh.reference_residual
                track.last_view = None
            else:
                # Kept, not cut into a patch yet (that costs about half a warm fit): most frames
                # hold without measuring their move.
                track.motion, track.last_view = None, (grey, offset)
            track.detection = detection

    def _refine_all(self, image: np.ndarray) -> tuple[list[Detection], _View] | None:
        """Step 1 for every track, on the grey of just the region around them (a cheap crop): the
        detections and that crop with its offset (x, y), or None when a track is not followed."""
        settings = self.settings
        if not settings.refine or not all(t.detection.refined for t in self._tracks):
            return None
        predictions = [t.predicted() for t in self._tracks]
        # The bounds in Python floats (numpy's per-axis min/max on (4, 2) cost more than the sums).
        us = [p[:, 0].tolist() for p in predictions]
        vs = [p[:, 1].tolist() for p in predictions]
        module = max(
            max(max(u) - min(u), max(v) - min(v)) / t.detection.modules
            for u, v, t in zip(us, vs, self._tracks, strict=True)
        )
        # Room for the edge profiles and the quiet-zone check (one module out) around the code,
        # and for a move that the prediction misses (measured then, see _follow).
        margin = 2.0 * module + settings.search_px + 6.0 + MOTION_MARGIN_PX
        h, w = image.shape[:2]
        lo_u, lo_v = min(min(u) for u in us) - margin, min(min(v) for v in vs) - margin
        hi_u, hi_v = max(max(u) for u in us) + margin, max(max(v) for v in vs) + margin
        if not math.isfinite(lo_u + lo_v + hi_u + hi_v):
            return None
        x0, y0 = max(math.floor(lo_u), 0), max(math.floor(lo_v), 0)
        x1, y1 = min(math.ceil(hi_u) + 1, w), min(math.ceil(hi_v) + 1, h)
        if x1 - x0 < 21 or y1 - y0 < 21:
            return None
        grey = as_grey(image[y0:y1, x0:x1])
        if np.shares_memory(grey, image):  # kept as the track's last view: not the caller's buffer
            grey = grey.copy()
        offset = (int(x0), int(y0))
        shape = (h, w)
        found = []
        for track, predicted in zip(self._tracks, predictions, strict=True):
            detection = self._follow(
                grey, track, predicted - np.array(offset, dtype=np.float64), offset, shape, image
            )
            if detection is None:
                return None
            found.append(detection)
        return found, (grey, offset)

    def _follow(
        self,
        grey: np.ndarray,
        track: _Track,
        predicted: np.ndarray,
        offset: tuple[int, int],
        shape: tuple[int, int],
        image: np.ndarray | None = None,
    ) -> Detection | None:
        """Step 1 for one track on a crop ``grey`` at ``offset`` of an image of ``shape`` (H, W):
        the warm whole-symbol fit from the prediction (refitted on a new template when it settled
        but misfits), else from the move measured in ``image`` (the whole frame), else the full fit
        or the detector's refinement from the measured start (the prediction when the move cannot
        be measured); each must pass the track's residual bar."""
        settings = self.settings
        if settings.symbol_fit and not np.isfinite(track.reference_residual):
            # A backend found this code but the symbol fit did not hold there: nothing to tell a
            # right fit from a wrong one here, so step 2 looks for it again.
            return None
        last = track.detection
        lens = self.detector.lens
        cells = track.cells
        if cells is None:
            cells = symbol_cells(grey, predicted, last.modules, last.symbol, track.inverted, lens, offset)
        result = None
        warm = track.fit_state is not None and settings.symbol_fit
        if warm:
            if track.warm is None or track.warm.cells is not cells or track.warm.lens is not lens:
                track.warm = WarmFit(cells, lens)
            fit = track.warm.fit(grey, predicted, track.fit_state, offset, TRACK_ITERATIONS, TRACK_SETTLE_PX)
            if not _warm_holds(fit, track) and fit.ok and fit.iterations < TRACK_ITERATIONS:
                # It settled where it stands but explains the image less well than the track's
                # reference: the template (made at another scale) may have aged. Once more with
                # one made here; a fit that slid off a module misfits a new template as much, and
                # goes on to the measured move below.
                track.warm.forget_template()
                fit = track.warm.fit(
                    grey, fit.corners_px, fit.state, offset, TRACK_ITERATIONS, TRACK_SETTLE_PX
                )
            if _warm_holds(fit, track) and fit.residual > SETTLE_RESIDUAL_GROWTH * track.reference_residual:
                further = track.warm.fit(
                    grey, fit.corners_px, fit.state, offset, SETTLE_ITERATIONS, SETTLE_PX
                )
                if _warm_holds(further, track) and further.residual <= fit.residual:
                    fit = further
            if _warm_holds(fit, track):
                score = track.detection.quality if track.score is None else track.score
                result = _refined(fit, score, cells)
        # The prediction failed (or there is no warm fit to try it): the fits below are local, so
        # they start from the measured move rather than from the prediction.
        start = predicted
        reference = track.reference() if result is None and image is not None else None
        if reference is not None:
            move = measured_move(reference, image)
            if move is not None:
                start = last.corners_px + move - np.array(offset, dtype=np.float64)
                if warm:
                    result = self._jump(grey, track, cells, offset, start)
        if result is None and warm:
            # A start too far for the warm fit (a jerk, a fast swing): the full fit from it.
            fit = fit_symbol(grey, start, cells, lens=lens, offset=offset, image_shape=shape)
            if _warm_holds(fit, track):
                result = self._checked(grey, fit, track, cells, offset)
        if result is None:
            # Cold: the edge lines and the whole symbol fit from the start (V3 is not
            # re-sought: it comes with the start).
            result = self.detector.refine(
                grey,
                start,
                last.modules,
                0.0,
                track.inverted,
                last.symbol,
                offset=offset,
                image_shape=shape,
            )
            if result is None or result.score < settings.min_quality:
                return None
            if not _fits_reference(result.residual, track):
                return None
            if check_patterns(grey, result.corners_px, last.modules, lens, offset).inverted != track.inverted:
                return None
        track.fit_state = result.fit_state
        track.residual = result.residual
        track.score = result.score
        if result.cells is not None:
            track.cells = result.cells
        return Detection(
            result.corners_px + np.array(offset, dtype=np.float64),
            last.text,
            quality_of(result.score, result.corners_cov),
            result.corner_quality,
            "track",
            True,
            last.modules,
            symbol=last.symbol,
            fit_state=result.fit_state,
            corners_cov=result.corners_cov,
        )

    def _jump(
        self, grey: np.ndarray, track: _Track, cells: np.ndarray, offset: tuple[int, int], start: np.ndarray
    ) -> Refined | None:
        """The warm fit from ``start`` (corners in ``grey``: the last ones moved by the measured
        move), with the patterns checked; None when the fit does not hold."""
        assert track.warm is not None and track.fit_state is not None
        fit = track.warm.fit(grey, start, track.fit_state, offset, JUMP_ITERATIONS)
        return self._checked(grey, fit, track, cells, offset) if _warm_holds(fit, track) else None

    def _checked(
        self, grey: np.ndarray, fit: SymbolFit, track: _Track, cells: np.ndarray, offset: tuple[int, int]
    ) -> Refined | None:
        """A fit that moved the corners further than a warm step: kept when the symbol's fixed
        patterns check out there (and its polarity is the track's)."""
        check = check_patterns(grey, fit.corners_px, track.detection.modules, self.detector.lens, offset)
        if check.score < self.settings.min_quality or check.inverted != track.inverted:
            return None
        return _refined(fit, check.score, cells)

    def _search_around(self, grey: np.ndarray, track: _Track) -> Detection | None:
        """Step 2: the first backend on a region around the prediction, then the usual checks."""
        last = track.detection
        predicted = track.predicted()
        h, w = grey.shape
        size = float(np.ptp(predicted, axis=0).max())
        margin = self.settings.track_margin_px + 0.25 * size
        x0, y0 = np.floor(predicted.min(axis=0) - margin).astype(int)
        x1, y1 = np.ceil(predicted.max(axis=0) + margin).astype(int) + 1
        x0, y0, x1, y1 = max(int(x0), 0), max(int(y0), 0), min(int(x1), w), min(int(y1), h)
        if x1 - x0 < 21 or y1 - y0 < 21:
            return None
        roi = np.ascontiguousarray(grey[y0:y1, x0:x1])
        for candidate in find_candidates(roi, self.detector.backends[0]):
            if last.text is not None and candidate.text != last.text:
                continue
            shifted = Candidate(
                candidate.corners_px + np.array([x0, y0], dtype=np.float64),
                candidate.text,
                candidate.backend,
                candidate.modules,
            )
            detection = self.detector.accept(grey, shifted)
            if detection is not None:
                return detection
        return None
