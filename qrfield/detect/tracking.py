"""Tracking a QR code through video: look around the last corners first, the whole frame when lost.

Per frame and per code tracked, cheapest first:
1. refine directly from the corners predicted by constant velocity (no decoding: the text is carried
   over) and check the symbol's fixed patterns there;
2. else run the first backend on a region around the prediction (``track_margin_px`` plus a quarter
   of the code's size), refine and check; the text must be the one tracked;
3. else (any code lost) a full-frame detection with every backend. Every ``redetect_frames``
   frames a full-frame detection also runs beside the tracking, to pick up codes that came into view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from qrfield.detect.backends import Candidate, find_candidates
from qrfield.detect.detection import Detection, DetectorSettings
from qrfield.detect.detector import Detector, as_grey, same_code
from qrfield.detect.patterns import check_patterns
from qrfield.detect.refine import refine_corners


@dataclass
class _Track:
    detection: Detection
    previous_corners: np.ndarray | None = None
    inverted: bool = False

    def predicted(self) -> np.ndarray:
        corners = self.detection.corners_px
        if self.previous_corners is None:
            return corners.copy()
        return corners + (corners - self.previous_corners)


class Tracker:
    """Follow QR codes from frame to frame; ``update`` returns what :meth:`Detector.detect` would.

    Attributes:
        last_mode: how the last frame was processed: "refined" (step 1 for every code, on a crop
            around them), "roi" (step 2), "full" (full-frame detection) or "" before the first frame.
    """

    def __init__(self, settings: DetectorSettings | None = None) -> None:
        self.detector = Detector(settings)
        self.settings = self.detector.settings
        self._tracks: list[_Track] = []
        self._frames_since_full = 0
        self.last_mode = ""

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
            found = self._refine_all(image)
            if found is not None:
                self._advance(found)
                self.last_mode = "refined"
            else:
                grey = as_grey(image)
                found = self._search_all(grey)
                if found is not None:
                    self._advance(found, grey)
                    self.last_mode = "roi"
        if found is not None and not due:
            return found
        grey = as_grey(image) if grey is None else grey
        detections = self.detector.detect(grey)
        self._frames_since_full = 0
        if found is not None:
            # The periodic full look: keep the codes tracked (the backends may miss a code that
            # tracking holds), add the ones that came into view.
            new = [d for d in detections if not any(same_code(d.corners_px, f.corners_px) for f in found)]
            self._tracks += [self._new_track(grey, d) for d in new]
            return found + new
        self._tracks = [self._new_track(grey, d) for d in detections]
        self.last_mode = "full"
        return detections

    @staticmethod
    def _new_track(grey: np.ndarray, detection: Detection) -> _Track:
        return _Track(
            detection, inverted=check_patterns(grey, detection.corners_px, detection.modules).inverted
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

    def _advance(self, found: list[Detection], grey: np.ndarray | None = None) -> None:
        for track, detection in zip(self._tracks, found, strict=True):
            track.previous_corners = track.detection.corners_px
            if grey is not None:  # re-found by a backend: re-read its polarity
                track.inverted = check_patterns(grey, detection.corners_px, detection.modules).inverted
            track.detection = detection

    def _refine_all(self, image: np.ndarray) -> list[Detection] | None:
        """Step 1 for every track, on the grey of just the region around them (a cheap crop)."""
        settings = self.settings
        if not settings.refine or not all(t.detection.refined for t in self._tracks):
            return None
        predictions = [t.predicted() for t in self._tracks]
        everything = np.concatenate(predictions)
        module = max(
            float(np.ptp(p, axis=0).max()) / t.detection.modules
            for p, t in zip(predictions, self._tracks, strict=True)
        )
        # Room for the edge profiles and the quiet-zone check (one module out) around the code.
        margin = 2.0 * module + settings.search_px + 6.0
        h, w = image.shape[:2]
        x0, y0 = np.floor(everything.min(axis=0) - margin).astype(int)
        x1, y1 = np.ceil(everything.max(axis=0) + margin).astype(int) + 1
        x0, y0, x1, y1 = max(int(x0), 0), max(int(y0), 0), min(int(x1), w), min(int(y1), h)
        if x1 - x0 < 21 or y1 - y0 < 21:
            return None
        grey = as_grey(image[y0:y1, x0:x1])
        offset = np.array([x0, y0], dtype=np.float64)
        found = []
        for track, predicted in zip(self._tracks, predictions, strict=True):
            last = track.detection
            fit = refine_corners(
                grey,
                predicted - offset,
                last.modules,
                inverted=track.inverted,
                search_px=settings.search_px,
                from_finders=False,
            )
            if not fit.ok:
                return None
            check = check_patterns(grey, fit.corners_px, last.modules)
            if check.score < settings.min_quality or check.inverted != track.inverted:
                return None
            found.append(
                Detection(
                    fit.corners_px + offset,
                    last.text,
                    check.score,
                    fit.corner_rms_px,
                    "track",
                    True,
                    last.modules,
                )
            )
        return found

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
