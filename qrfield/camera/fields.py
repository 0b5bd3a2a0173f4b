"""A camera model's fields: the error every camera problem raises, the checks of the intrinsics and
of the optional sensor fields (docs/cameras.md), and the JSON format's field lists.

Units: pixels for fx, fy, cx, cy, width, height (OpenCV's convention: the top-left pixel's centre is
(0, 0)); sensor rectangles in the sensor's full-resolution pixels; lens positions in dioptres.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from qrfield.limits import FOCAL_PX, IMAGE_SIDE_PX, LimitError

#: Fields every camera JSON file must have.
REQUIRED_FIELDS = ("width", "height", "fx", "fy", "cx", "cy")
#: Largest relative aspect-ratio mismatch accepted when rescaling to another resolution.
ASPECT_TOLERANCE = 0.01
#: Optional fields of the camera JSON format: the sensor geometry a profile was made at.
SENSOR_FIELDS = ("sensor_resolution", "sensor_crop", "sensor_mode", "lens_position", "focal_length_mm")
#: The camera model used when none is named (the virtual bench renders through it, too).
DEFAULT_CAMERA = "picam-v2@640x480"


class CameraModelError(ValueError):
    """A camera model, file or name that cannot be used; the message names file and field."""


def _validate(fx: float, fy: float, cx: float, cy: float, width: int, height: int, where: str) -> None:
    """Raise CameraModelError (prefixed with ``where``) for unusable intrinsics (qrfield.limits)."""
    if width <= 0 or height <= 0:
        raise CameraModelError(f"{where}: image size {width}x{height} must be positive")
    for key, value in (("width", width), ("height", height)):
        try:
            IMAGE_SIDE_PX.check(value, f"{where}: field '{key}'")
        except LimitError as exc:
            raise CameraModelError(str(exc)) from None
    for key, value in (("fx", fx), ("fy", fy)):
        if not math.isfinite(value) or value <= 0:
            raise CameraModelError(
                f"{where}: field '{key}' must be a positive focal length in pixels, got {value!r}"
            )
        try:
            FOCAL_PX.check(value, f"{where}: field '{key}'")
        except LimitError as exc:
            raise CameraModelError(str(exc)) from None
    if not (-0.5 <= cx <= width - 0.5):
        raise CameraModelError(
            f"{where}: field 'cx' = {cx!r} puts the principal point outside the {width}-pixel-wide image"
        )
    if not (-0.5 <= cy <= height - 0.5):
        raise CameraModelError(
            f"{where}: field 'cy' = {cy!r} puts the principal point outside the {height}-pixel-high image"
        )


def image_distance_mm(focal_length_mm: float, dioptres: float) -> float:
    """Lens-to-sensor distance (mm) of a thin lens of focal length f focused at 1/dioptres metres."""
    inverse = 1.0 / focal_length_mm - dioptres / 1000.0
    if inverse <= 0:
        raise CameraModelError(
            f"a {focal_length_mm:g} mm lens cannot focus at {dioptres:g} dioptres "
            "(closer than its focal length)"
        )
    return 1.0 / inverse


def format_crop(crop: Any) -> str:
    """A sensor rectangle as rpicam-hello prints it: ``(x, y)/WxH``."""
    try:
        x, y, w, h = (int(v) for v in crop)
    except (TypeError, ValueError):
        return repr(crop)
    return f"({x}, {y})/{w}x{h}"


def check_crop(
    crop: tuple[int, int, int, int], resolution: tuple[int, int] | None, where: str
) -> tuple[int, int, int, int]:
    """``crop`` (x, y, w, h) if it is a non-empty rectangle inside ``resolution`` (when known)."""
    x, y, w, h = crop
    if w <= 0 or h <= 0 or x < 0 or y < 0:
        raise CameraModelError(f"{where}: sensor crop {crop} needs x, y >= 0 and a positive size")
    if resolution is not None and (x + w > resolution[0] or y + h > resolution[1]):
        raise CameraModelError(
            f"{where}: sensor crop {format_crop(crop)} reaches outside the "
            f"{resolution[0]}x{resolution[1]} sensor"
        )
    return crop


def _whole_numbers(values: Any, count: int, key: str, where: str) -> tuple[int, ...]:
    """``values`` as a tuple of ``count`` whole numbers; CameraModelError naming ``key`` otherwise."""
    try:
        items = list(values)
    except TypeError:
        items = None
    if (
        items is None
        or len(items) != count
        or any(isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) for v in items)
        or any(not math.isfinite(v) or v != int(v) for v in items)
    ):
        raise CameraModelError(
            f"{where}: field '{key}' must be a list of {count} whole numbers, got {values!r}"
        )
    return tuple(int(v) for v in items)


def sensor_fields(values: dict[str, Any], where: str) -> dict[str, Any]:
    """The optional sensor fields (SENSOR_FIELDS) checked and coerced; None/"" stay unset.

    CameraModelError (prefixed with ``where``) names the field that is wrong."""
    out: dict[str, Any] = {}
    resolution = values.get("sensor_resolution")
    if resolution is not None:
        resolution = _whole_numbers(resolution, 2, "sensor_resolution", where)
        if min(resolution) <= 0:
            raise CameraModelError(f"{where}: field 'sensor_resolution' {resolution} must be positive")
        out["sensor_resolution"] = resolution
    crop = values.get("sensor_crop")
    if crop is not None:
        out["sensor_crop"] = check_crop(_whole_numbers(crop, 4, "sensor_crop", where), resolution, where)
    mode = values.get("sensor_mode")
    if mode not in (None, ""):
        if not isinstance(mode, str):
            raise CameraModelError(f"{where}: field 'sensor_mode' must be text, got {mode!r}")
        out["sensor_mode"] = mode
    for key in ("lens_position", "focal_length_mm"):
        value = values.get(key)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise CameraModelError(f"{where}: field '{key}' must be a number, got {value!r}")
        if value < 0 or (key == "focal_length_mm" and value == 0):
            raise CameraModelError(f"{where}: field '{key}' must be positive, got {value!r}")
        out[key] = float(value)
    return out


def _jsonable(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value
