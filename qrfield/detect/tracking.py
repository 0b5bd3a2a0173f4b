"""Tracking a QR code through video: look around the last corners first, the whole frame when lost.

Per frame and per code tracked, cheapest first:
1. refine directly from the corners predicted by constant velocity (no decoding: the text is carried
   over) and check the symbol's fixed patterns there;
2. else run the first backend on a region around the prediction (``track_margin_px`` plus a quarter
   of the code's size), refine and check; the text must be the one tracked;
3. else (any code lost) a full-frame detection with every backend, which also picks up new codes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from qrfield.detect.backends import Candidate, find_candidates
from qrfield.detect.detection import Detection, DetectorSettings
from qrfield.detect.detector import Detector, as_grey
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
        last_mode: how the last frame was processed: "refined" (step 1 for every code), "roi"
            (step 2 for at least one), "full" (full-frame detection) or "" before the first frame.
    """

    def __init__(self, settings: DetectorSettings | None = None) -> None:
        self.detector = Detector(settings)
        self.settings = self.detector.settings
        self._tracks: list[_Track] = []
        self.last_mode = ""

    def reset(self) -> None:
        """Forget the tracked codes: the next frame gets a full-frame detection."""
        self._tracks = []
        self.last_mode = ""

    def update(self, image: np.ndarray) -> list[Detection]:
        """Detections in the next video frame (grey or BGR uint8); never raises on image content."""
        grey = as_grey(image)
        if self.settings.track and self._tracks:
            modes = []
            found = []
            for track in self._tracks:
                detection, mode = self._follow(grey, track)
                if detection is None:
                    break
                found.append(detection)
                modes.append(mode)
            else:
                for track, detection in zip(self._tracks, found, strict=True):
                    track.previous_corners = track.detection.corners_px
                    if detection.backend != "track":  # re-found by a backend: re-read its polarity
                        track.inverted = check_patterns(
                            grey, detection.corners_px, detection.modules
                        ).inverted
                    track.detection = detection
                self.last_mode = "roi" if "roi" in modes else "refined"
                return found
        detections = self.detector.detect(grey)
        self._tracks = [
            _Track(d, inverted=check_patterns(grey, d.corners_px, d.modules).inverted) for d in detections
        ]
        self.last_mode = "full"
        return detections

    def _follow(self, grey: np.ndarray, track: _Track) -> tuple[Detection | None, str]:
        settings = self.settings
        last = track.detection
        predicted = track.predicted()
        if settings.refine and last.refined:
            fit = refine_corners(
                grey,
                predicted,
                last.modules,
                inverted=track.inverted,
                search_px=settings.search_px,
                from_finders=False,
            )
            if fit.ok:
                check = check_patterns(grey, fit.corners_px, last.modules)
                if check.score >= settings.min_quality and check.inverted == track.inverted:
                    detection = Detection(
                        fit.corners_px, last.text, check.score, fit.corner_rms_px, "track", True, last.modules
                    )
                    return detection, "refined"
        h, w = grey.shape
        size = float(np.ptp(predicted, axis=0).max())
        margin = settings.track_margin_px + 0.25 * size
        x0, y0 = np.floor(predicted.min(axis=0) - margin).astype(int)
        x1, y1 = np.ceil(predicted.max(axis=0) + margin).astype(int) + 1
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 - x0 < 21 or y1 - y0 < 21:
            return None, ""
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
                return detection, "roi"
        return None, ""
