"""QR code detection: corners V1..V4 to a tenth of a pixel, decoded text, quality; tracking; selection.

    from qrfield.detect import Detector, Tracker, select_code
    detections = Detector().detect(image)          # grey or BGR uint8, any size
    code = select_code(detections, select_text="")  # the largest, or the one with that text

Vertex order V1..V4 and pixel convention: DESIGN.md. Modules: backends (zxing-cpp, OpenCV),
patterns (checks against the symbol's fixed patterns), refine (sub-pixel edges), detector,
tracking, select.
"""

from qrfield.detect.backends import BACKEND_NAMES, BackendError
from qrfield.detect.detection import Detection, DetectorSettings
from qrfield.detect.detector import Detector, DetectorInputError
from qrfield.detect.select import select_code
from qrfield.detect.tracking import Tracker

__all__ = [
    "BACKEND_NAMES",
    "BackendError",
    "Detection",
    "Detector",
    "DetectorInputError",
    "DetectorSettings",
    "Tracker",
    "select_code",
]
