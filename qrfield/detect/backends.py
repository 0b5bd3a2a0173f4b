"""Detector backends: each finds QR codes in a grey image and returns rough corners in V1..V4 order.

V1..V4 (docs/conventions.md): V1 the outer corner of the top-left finder pattern, V2 top-right,
V3 bottom-right (no finder pattern), V4 bottom-left, following the code when it is rotated. Both
OpenCV detectors and zxing-cpp already report their four points in this order (zxing's
``top_left`` .. ``bottom_left`` are the symbol's own corners, not the image's); tests check it
against the renderer's truth under rotations of 0/90/180/270 degrees and tilts.

Pixels follow OpenCV (centre of the top-left pixel = (0, 0)). zxing-cpp's corners are whole
pixels; OpenCV's are about 0.5-1.5 px off: :mod:`qrfield.detect.refine` makes them sub-pixel.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from qrfield.detect.lens import Lens
from qrfield.settings import SettingError

#: Backend names accepted by the ``backends`` setting, fastest first. "zxing-x2" runs zxing-cpp on the
#: image upscaled twice (bicubic): slower, but it reads codes whose modules are 2-3 px. "finders"
#: locates finder patterns by contours and decodes the rectified symbol (strong perspective).
#: "small" does so in the busy regions of the image upscaled 3 times and sharpened (modules of
#: 1.2-3 px under a blur of about a module: qrfield.detect.small). "steep" finds the finder patterns by
#: correlation in busy regions compressed along one direction (a code tilted steeply), stretched
#: back (qrfield.detect.steep): run last, on what the others did not explain.
BACKEND_NAMES = ("zxing", "zxing-x2", "opencv-aruco", "opencv", "finders", "small", "steep")


class BackendError(SettingError):
    """An unknown backend name, or a backend that is not installed (a SettingError: the
    ``backends`` setting's own rule, a ValueError as before)."""


@dataclass(frozen=True)
class Candidate:
    """One code as a backend reports it, before refinement and checks.

    Attributes:
        corners_px: (4, 2) float pixels, V1..V4.
        text: the decoded payload, or None when the backend located the code but could not read it.
        backend: the backend's name.
        modules: modules per side of the symbol when the backend knows its version, else None.
        symbol: the decoded (n, n) bool module matrix (True = dark, upright: V1 top-left) when the
            backend gives it (zxing-cpp), else None.
    """

    corners_px: np.ndarray
    text: str | None
    backend: str
    modules: int | None = None
    symbol: np.ndarray | None = None


def read_qr_barcodes(grey: np.ndarray) -> list:  # type: ignore[type-arg]
    """zxing-cpp's results for the QR codes in a grey image, their text plain (as encoded).

    HRI text mode would spell control characters as <SOH> etc., so 2.x is asked for plain text.
    zxing-cpp 1.4 (Debian 12's python3-zxing-cpp, 32-bit Raspberry Pi OS) has no TextMode and no
    text_mode argument, and its text is the plain payload already (its wrappers/python/zxing.cpp at
    v1.4.0: read_barcodes(image, formats, try_rotate, try_downscale, binarizer, is_pure,
    ean_add_on_symbol); results have valid, text, bytes, format, position, orientation, no extra).
    """
    import zxingcpp

    options = {"formats": zxingcpp.BarcodeFormat.QRCode}
    text_mode = getattr(zxingcpp, "TextMode", None)
    if text_mode is not None:
        options["text_mode"] = text_mode.Plain
    return list(zxingcpp.read_barcodes(grey, **options))


def _zxing(grey: np.ndarray) -> list[Candidate]:
    from qrfield.detect.symbol import matrix_from_zxing

    out = []
    barcodes = read_qr_barcodes(grey)
    for barcode in barcodes:
        p = barcode.position
        corners = np.array(
            [
                [p.top_left.x, p.top_left.y],
                [p.top_right.x, p.top_right.y],
                [p.bottom_right.x, p.bottom_right.y],
                [p.bottom_left.x, p.bottom_left.y],
            ],
            dtype=float,
        )
        modules = None
        try:
            version = int(barcode.extra.get("Version", ""))
            modules = 17 + 4 * version if 1 <= version <= 40 else None
        except (AttributeError, TypeError, ValueError):
            modules = None
        symbol = matrix_from_zxing(barcode) if barcode.valid else None
        if symbol is not None and modules is not None and symbol.shape[0] != modules:
            symbol = None
        out.append(Candidate(corners, barcode.text if barcode.valid else None, "zxing", modules, symbol))
    return out


#: zxing-x2 skips images above this many pixels (12 MP and more after upscaling: slow, and in such
#: images a code with 2-3 px modules is rare).
X2_MAX_PIXELS = 3_000_000


def _zxing_x2(grey: np.ndarray) -> list[Candidate]:
    if grey.size > X2_MAX_PIXELS:
        return []
    big = cv2.resize(grey, None, fx=2.0, fy=2.0, interpolation=cv2.INTER_CUBIC)
    out = []
    for c in _zxing(big):
        # pixel centres: x_small = (x_big + 0.5) / 2 - 0.5
        out.append(Candidate((c.corners_px + 0.5) / 2.0 - 0.5, c.text, "zxing-x2", c.modules, c.symbol))
    return out


def _opencv_multi(
    detector: cv2.QRCodeDetector | cv2.QRCodeDetectorAruco, name: str, grey: np.ndarray
) -> list[Candidate]:
    """All codes by OpenCV's multi-code API; if it reads none, its single-code API (which decodes
    more of the real photos: 29 of 77 against 15)."""
    out = []
    # OpenCV before 4.12 (what numpy 1.x, hence Raspberry Pi OS's picamera2, gets) has no Bytes
    # variants; the text variants decode the same codes.
    decode_multi = getattr(detector, "detectAndDecodeBytesMulti", None) or detector.detectAndDecodeMulti
    decode_single = getattr(detector, "detectAndDecodeBytes", None) or detector.detectAndDecode
    try:
        ok, payloads, points, _ = decode_multi(grey)
    except cv2.error:
        ok, payloads, points = False, (), None
    if ok and points is not None:
        for payload, corners in zip(
            payloads, np.asarray(points, dtype=float).reshape(-1, 4, 2), strict=False
        ):
            if np.all(np.isfinite(corners)):
                out.append(Candidate(corners.copy(), _text(payload), name, None))
    if any(c.text for c in out):
        return out
    try:
        payload, points, _ = decode_single(grey)
    except cv2.error:
        return out
    if points is None:
        return out
    corners = np.asarray(points, dtype=float).reshape(-1, 2)
    if corners.shape != (4, 2) or not np.all(np.isfinite(corners)):
        return out
    single = Candidate(corners, _text(payload), name, None)
    return [single, *[c for c in out if np.abs(c.corners_px - corners).max() > 2.0]]


def _text(payload: bytes | str | None) -> str | None:
    """Payload bytes as text: UTF-8, else Latin-1 (QR's default byte charset); None when empty.
    Text already decoded by OpenCV's older text API is taken as it is."""
    if not payload:
        return None
    if isinstance(payload, str):
        return payload
    try:
        return bytes(payload).decode("utf-8")
    except UnicodeDecodeError:
        return bytes(payload).decode("latin-1")


def _opencv(grey: np.ndarray) -> list[Candidate]:
    return _opencv_multi(cv2.QRCodeDetector(), "opencv", grey)


def _opencv_aruco(grey: np.ndarray) -> list[Candidate]:
    return _opencv_multi(cv2.QRCodeDetectorAruco(), "opencv-aruco", grey)


def _finders(grey: np.ndarray) -> list[Candidate]:
    from qrfield.detect.finders import locate_by_finders

    return [
        Candidate(corners, text, "finders", n, symbol) for corners, n, text, symbol in locate_by_finders(grey)
    ]


def _small(grey: np.ndarray) -> list[Candidate]:
    from qrfield.detect.small import locate_small

    return [Candidate(corners, text, "small", n, symbol) for corners, n, text, symbol in locate_small(grey)]


def _steep(grey: np.ndarray, lens: Lens | None = None) -> list[Candidate]:
    from qrfield.detect.steep import locate_steep

    return [
        Candidate(corners, text, "steep", n, symbol) for corners, n, text, symbol in locate_steep(grey, lens)
    ]


_BACKENDS: dict[str, Callable[[np.ndarray], list[Candidate]]] = {
    "zxing": _zxing,
    "zxing-x2": _zxing_x2,
    "opencv-aruco": _opencv_aruco,
    "opencv": _opencv,
    "finders": _finders,
    "small": _small,
    "steep": _steep,
}


def parse_backends(spec: str) -> tuple[str, ...]:
    """``"zxing,opencv"`` -> ("zxing", "opencv"); BackendError naming an unknown entry."""
    names = tuple(part.strip().lower() for part in spec.split(",") if part.strip())
    if not names:
        raise BackendError(f"no detector backend given in {spec!r}; choose from {', '.join(BACKEND_NAMES)}")
    unknown = [name for name in names if name not in _BACKENDS]
    if unknown:
        raise BackendError(
            f"unknown detector backend(s) {', '.join(unknown)} in {spec!r}; "
            f"choose from {', '.join(BACKEND_NAMES)}"
        )
    if "opencv-aruco" in names and not hasattr(cv2, "QRCodeDetectorAruco"):
        # Added in OpenCV 4.8 (opencv/opencv#23264); Debian 12 / 32-bit Raspberry Pi OS have 4.6.
        others = ", ".join(n for n in BACKEND_NAMES if n != "opencv-aruco")
        raise BackendError(
            f"detector backend opencv-aruco needs OpenCV 4.8 or newer (cv2.QRCodeDetectorAruco); this is "
            f"OpenCV {cv2.__version__}: choose from {others}"
        )
    return names


#: Backends that model the camera's lens (given to :func:`find_candidates`); the others see the
#: image alone.
_LENS_BACKENDS: dict[str, Callable[[np.ndarray, Lens | None], list[Candidate]]] = {"steep": _steep}


def find_candidates(grey: np.ndarray, backend: str, lens: Lens | None = None) -> list[Candidate]:
    """Run one backend on a (H, W) uint8 grey image; never raises for image content. ``lens``:
    the camera's lens (qrfield.detect.lens.Lens, None for a pinhole), used by the steep backend
    (its canvas is made in ideal pixels)."""
    if backend in _LENS_BACKENDS:
        return _LENS_BACKENDS[backend](grey, lens)
    try:
        return _BACKENDS[backend](grey)
    except KeyError:
        raise BackendError(
            f"unknown detector backend {backend!r}; choose from {', '.join(BACKEND_NAMES)}"
        ) from None
