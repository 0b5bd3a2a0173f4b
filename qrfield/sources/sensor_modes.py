"""Sensor modes of a Raspberry Pi camera and the one qrfield asks picamera2 for.

picamera2 picks the sensor mode that best matches the size it is asked for (it scores every mode
by ``sensor.output_size``, else ``raw.size``, else the main stream's size: Picamera2's
``_make_libcamera_config``). Asked for a main stream of 640x480 alone, an IMX219 gets its cropped
640x480 mode, which sees only the centre 1280x960 pixels of the sensor (picamera2 issue 1233). So by
default qrfield asks for the *full field of view* mode: among the modes whose crop holds the largest
field at the output's aspect ratio, the smallest (binned) one that still covers the output size.
Plain Python, no picamera2 import.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from qrfield.camera import format_crop

#: Sensor-mode policies (Picamera2Settings.sensor_mode); any other value is a mode's size WxH.
FULL_FIELD = "full"
PICAMERA2_CHOICE = "picamera2"
#: Two fields of view within this fraction count as the same (the IMX219's 1640x1232 and 3280x2464).
SAME_FIELD = 0.01


@dataclass(frozen=True)
class SensorMode:
    """One mode of the sensor, as ``Picamera2.sensor_modes`` reports it.

    Attributes:
        size: (width, height) the sensor outputs in this mode, pixels.
        bit_depth: bits per pixel.
        crop: (x, y, w, h), the part of the full-resolution pixel array the mode reads
            (``crop_limits``; binned modes read a larger area than their size).
        fps: the mode's highest frame rate.
        format: the raw format name, e.g. ``SRGGB10_CSI2P``.
    """

    size: tuple[int, int]
    bit_depth: int
    crop: tuple[int, int, int, int]
    fps: float = 0.0
    format: str = ""

    @classmethod
    def from_picamera2(cls, mode: dict[str, Any]) -> SensorMode:
        return cls(
            size=(int(mode["size"][0]), int(mode["size"][1])),
            bit_depth=int(mode.get("bit_depth", 0)),
            crop=tuple(int(v) for v in mode["crop_limits"]),  # type: ignore[arg-type]
            fps=float(mode.get("fps") or 0.0),
            format=str(mode.get("format", "")),
        )

    @property
    def label(self) -> str:
        """``1640x1232 10-bit``."""
        return f"{self.size[0]}x{self.size[1]} {self.bit_depth}-bit"

    def describe(self) -> str:
        """As rpicam-hello lists it: ``1640x1232 10-bit [41.85 fps - (0, 0)/3280x2464 crop]``."""
        return f"{self.label} [{self.fps:.2f} fps - {format_crop(self.crop)} crop]"


def bounded_to_aspect(size: tuple[int, int], aspect: tuple[int, int]) -> tuple[float, float]:
    """The largest (w, h) of ``aspect``'s shape that fits in ``size``."""
    width, height = size
    if width * aspect[1] > aspect[0] * height:
        return (height * aspect[0] / aspect[1], float(height))
    return (float(width), width * aspect[1] / aspect[0])


def field_area(mode: SensorMode, out_size: tuple[int, int]) -> float:
    """Full-resolution pixels of the field the mode shows at the output's aspect ratio."""
    w, h = bounded_to_aspect(mode.crop[2:], out_size)  # type: ignore[arg-type]
    return w * h


def full_field_mode(modes: list[SensorMode], out_size: tuple[int, int]) -> SensorMode:
    """The binned full-field-of-view mode for ``out_size``'s aspect ratio.

    Among the modes showing the largest field at that aspect ratio, the smallest whose own image
    (cropped to the aspect ratio) still covers ``out_size`` (binned: faster, no upscaling); if none
    does, the largest of them. Ties go to the deeper bit depth, then the faster mode.
    """
    if not modes:
        raise ValueError("the camera reports no sensor modes")
    best = max(field_area(m, out_size) for m in modes)
    widest = [m for m in modes if field_area(m, out_size) >= (1 - SAME_FIELD) * best]

    def covers(mode: SensorMode) -> bool:
        w, h = bounded_to_aspect(mode.size, out_size)
        return w >= out_size[0] - 0.5 and h >= out_size[1] - 0.5

    enough = [m for m in widest if covers(m)]
    if enough:
        return min(enough, key=lambda m: (m.size[0] * m.size[1], -m.bit_depth, -m.fps))
    return max(widest, key=lambda m: (m.size[0] * m.size[1], m.bit_depth, m.fps))


def check_policy(text: str) -> str:
    """``text`` if it is a valid sensor-mode setting (full, picamera2 or WxH); ValueError otherwise."""
    value = text.strip().lower()
    if value in (FULL_FIELD, PICAMERA2_CHOICE):
        return value
    parts = value.split("x")
    if len(parts) == 2 and all(p.isdigit() and int(p) > 0 for p in parts):
        return value
    raise ValueError(
        f"sensor mode {text!r}: give full (the full field of view, default), picamera2 (its own "
        "choice by size) or a mode's size WxH as qrfield camera list shows it"
    )


def choose_mode(
    modes: list[SensorMode], out_size: tuple[int, int], policy: str
) -> tuple[SensorMode | None, str]:
    """The mode to ask picamera2 for (None: let it choose) and why, for ``policy`` (see check_policy)."""
    policy = check_policy(policy)
    if policy == PICAMERA2_CHOICE:
        return None, "picamera2's own choice by the output size (sensor_mode picamera2)"
    if policy == FULL_FIELD:
        mode = full_field_mode(modes, out_size)
        w, h = out_size
        return mode, f"the binned full-field-of-view mode for {w}x{h} (sensor_mode full)"
    size = tuple(int(p) for p in policy.split("x"))
    matching = [m for m in modes if m.size == size]
    if not matching:
        sizes = ", ".join(sorted({f"{m.size[0]}x{m.size[1]}" for m in modes}))
        raise ValueError(f"sensor mode {policy}: the camera has no such mode; its modes are {sizes}")
    return max(matching, key=lambda m: m.bit_depth), f"sensor_mode {policy} as set"
