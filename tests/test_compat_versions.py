"""The headless path on the versions 32-bit Raspberry Pi OS / Debian 12 package: zxing-cpp 1.4 and
OpenCV 4.6 (numpy 1.24 too: scripts/check-os-packages.sh runs the whole suite on the real packages).

The twins below reproduce those versions' Python APIs where they differ from what we install, from
their sources:
- zxing-cpp 1.4.0, wrappers/python/zxing.cpp (tag v1.4.0): ``read_barcodes(image, formats,
  try_rotate, try_downscale, binarizer, is_pure, ean_add_on_symbol)`` (pybind11 rejects any other
  keyword with a TypeError); no ``TextMode``; a Result has valid, text, bytes, format,
  symbology_identifier, content_type, position, orientation, and no ``extra``.
- OpenCV 4.6: no ``cv2.QRCodeDetectorAruco`` (added in 4.8, opencv/opencv#23264) and no
  ``detectAndDecodeBytes*`` (tests/test_detect_robustness.py covers that one).
"""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest

from qrfield.detect import Detector, DetectorSettings
from qrfield.detect.backends import BackendError, parse_backends
from qrfield.geometry import Pose
from qrfield.render import render_view


def zxing_cpp_1_4() -> types.ModuleType:
    """A module with zxing-cpp 1.4's Python API, decoding with the installed zxing-cpp (which is
    returned as it is when it is 1.4 itself: scripts/check-os-packages.sh runs these tests there)."""
    import zxingcpp as real

    if not hasattr(real, "TextMode"):
        return real

    class Point:
        def __init__(self, p):
            self.x, self.y = int(p.x), int(p.y)

    class Position:
        def __init__(self, pos):
            self.top_left, self.top_right = Point(pos.top_left), Point(pos.top_right)
            self.bottom_right, self.bottom_left = Point(pos.bottom_right), Point(pos.bottom_left)

    class Result:  # exactly 1.4's properties: no `extra`
        __slots__ = ("bytes", "content_type", "format", "orientation", "position", "symbology_identifier",
                     "text", "valid")  # fmt: skip

        def __init__(self, r):
            self.valid, self.text, self.bytes = r.valid, r.text, r.bytes
            self.format, self.position, self.orientation = r.format, Position(r.position), r.orientation
            self.content_type, self.symbology_identifier = r.content_type, r.symbology_identifier

    def read_barcodes(image, formats=None, try_rotate=True, try_downscale=True, binarizer=None,
                      is_pure=False, ean_add_on_symbol=None, **unknown):  # fmt: skip
        if unknown:  # what pybind11 says for a keyword 1.4 does not have
            raise TypeError(f"read_barcodes(): incompatible function arguments: {sorted(unknown)}")
        plain = real.TextMode.Plain  # 1.4's text is the plain payload
        return [Result(r) for r in real.read_barcodes(image, formats=formats, text_mode=plain)]

    module = types.ModuleType("zxingcpp")
    module.BarcodeFormat = types.SimpleNamespace(QRCode=real.BarcodeFormat.QRCode)
    module.read_barcodes = read_barcodes
    return module


def test_the_zxing_twin_refuses_what_1_4_refuses():
    twin = zxing_cpp_1_4()
    assert not hasattr(twin, "TextMode")
    with pytest.raises(TypeError, match="incompatible function arguments"):
        twin.read_barcodes(np.zeros((10, 10), np.uint8), text_mode=1)


@pytest.mark.parametrize("backend", ["zxing", "finders"])
def test_detection_works_with_zxing_cpp_1_4(camera_vga, monkeypatch, backend):
    pose = Pose([5.0, -4.0, 260.0], [12.0, -18.0, 30.0])
    view = render_view(camera_vga, 50.0, pose, text="old zxing", noise_sigma=1.0, seed=3)
    monkeypatch.setitem(sys.modules, "zxingcpp", zxing_cpp_1_4())
    detections = Detector(DetectorSettings(backends=backend)).detect(view.image)
    assert [d.text for d in detections] == ["old zxing"]
    # Corners refined to sub-pixel against the renderer's exact vertices.
    assert np.abs(detections[0].corners_px - view.corners_px).max() < 0.5


class OpenCV46:
    """cv2 as OpenCV 4.6 offers it: everything but the names added later."""

    MISSING = ("QRCodeDetectorAruco",)

    def __init__(self, real):
        self._real = real

    def __getattr__(self, name):
        if name in self.MISSING:
            raise AttributeError(f"module 'cv2' has no attribute {name!r}")
        return getattr(self._real, name)


def test_opencv_aruco_backend_says_it_needs_opencv_4_8(monkeypatch):
    import cv2

    import qrfield.detect.backends as backends

    monkeypatch.setattr(backends, "cv2", OpenCV46(cv2))
    with pytest.raises(BackendError, match=r"opencv-aruco needs OpenCV 4\.8 or newer"):
        parse_backends("zxing,opencv-aruco")
    assert parse_backends(DetectorSettings().backends)  # the default backends need nothing newer
