"""Choosing the one code the app measures when several are in view."""

from __future__ import annotations

from collections.abc import Sequence

from qrfield.detect.detection import Detection


def select_code(detections: Sequence[Detection], select_text: str = "") -> Detection | None:
    """The code to measure: with ``select_text`` set, the (largest) code whose text equals it, or
    None when no code has that text; with ``select_text`` empty, the largest code in view (by image
    area). None for an empty list.
    """
    if select_text:
        detections = [d for d in detections if d.text == select_text]
    if not detections:
        return None
    if len(detections) == 1:  # the usual frame: no area to compare (it costs a numpy pass)
        return detections[0]
    return max(detections, key=lambda d: d.area_px)
