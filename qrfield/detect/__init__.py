"""QR code detection: corners V1..V4 to a tenth of a pixel, decoded text, quality; tracking; selection.

    from qrfield.detect import Detector, Tracker, select_code
    detections = Detector().detect(image)          # grey or BGR uint8, any size
    code = select_code(detections, select_text="")  # the largest, or the one with that text

Vertex order V1..V4 and pixel convention: docs/conventions.md. Modules: backends (zxing-cpp, OpenCV),
finders (finder patterns by contours, for strong perspective), small (finder patterns in busy
regions upscaled and sharpened, for modules of 1.2-3 px), patterns (checks against the symbol's
fixed patterns), refine (sub-pixel edges), symbol_fit and symbol_track (the whole-symbol fit, and
kept warm), symbol_cold (the whole-symbol fit from a backend's corners by inverse composition, a
cold detection's refinement), reading (the modules of a located code by least squares), detector,
tracking, select.

Names are imported on first use, so that declaring settings (``DetectorSettings``, e.g. for CLI
options) does not load OpenCV or zxing-cpp.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "BACKEND_NAMES": "qrfield.detect.backends",
    "BackendError": "qrfield.detect.backends",
    "Detection": "qrfield.detect.detection",
    "DetectorSettings": "qrfield.detect.detection",
    "Detector": "qrfield.detect.detector",
    "DetectorInputError": "qrfield.detect.detector",
    "select_code": "qrfield.detect.select",
    "Tracker": "qrfield.detect.tracking",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'qrfield.detect' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
