"""Physical limits of every number qrfield takes from a user or a file, declared once.

Each limit is far wider than any real bench (so no real measurement is refused) and narrow enough
that nonsense is stopped before it is used: a QR side of 1e-300 mm, a focal length of 1e308 px, a
corner a million pixels outside the image, a lens model that cannot be inverted over its image.
Command options, camera profiles, session files and the app all check against these; a refusal
is one line naming the option or file, the field, the value and the limit (:class:`LimitError`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


class LimitError(ValueError):
    """A number outside its physical limits, or not a finite number; the message names it."""


#: Longest number text read (characters): a float has 17 significant digits and an exponent, so
#: this is far beyond any real value, and short enough that int() and float() stay instant.
MAX_NUMBER_CHARS = 64


def as_number(value: Any, where: str, label: str = "value") -> float:
    """The one reader of a number from a user or a file: ``value`` (an int, a float, or a number's
    text) as a finite float, else LimitError naming ``where`` (the option, or the file and key).

    Refused: true/false, what is not a number, a text longer than :data:`MAX_NUMBER_CHARS`, an
    integer too large for a float (a 400-digit integer in a JSON file: float() would raise
    OverflowError), and infinities and NaN (``1e400`` in a file reads as infinity).
    """
    if isinstance(value, bool):
        raise LimitError(f"{where}: {label} must be a number, got {value!r}")
    if isinstance(value, str):
        text = value.strip()
        if len(text) > MAX_NUMBER_CHARS:
            raise LimitError(
                f"{where}: {label} must be a number, got a text of {len(text)} characters "
                f"(more than {MAX_NUMBER_CHARS})"
            )
        value = text
    elif isinstance(value, int) and value.bit_length() > 1024:  # beyond the largest float
        digits = math.floor(math.log10(abs(value))) + 1  # not len(str()): it refuses over 4300 digits
        digits -= 10 ** (digits - 1) > abs(value)  # log10 rounds 99...9 up to the next power
        raise LimitError(f"{where}: {label} is an integer of {digits} digits, too large for a number")
    try:
        number = float(value)
    except OverflowError:  # an integer just under 2**1024 but above the largest float
        raise LimitError(f"{where}: {label} is an integer too large for a number") from None
    except (TypeError, ValueError):
        shown = repr(value) if len(repr(value)) <= 40 else repr(value)[:40] + "..."
        raise LimitError(f"{where}: {label} must be a number, got {shown}") from None
    if not math.isfinite(number):
        raise LimitError(f"{where}: {label} must be a finite number, got {value!r}")
    return number


@dataclass(frozen=True)
class Limit:
    """A closed range ``minimum..maximum`` of a quantity in ``unit``, with why it is what it is."""

    label: str
    unit: str
    minimum: float
    maximum: float
    why: str = ""

    def describe(self) -> str:
        """``0.1..10000 mm``."""
        return f"{self.minimum:g}..{self.maximum:g} {self.unit}".rstrip()

    def check(self, value: Any, where: str) -> float:
        """``value`` as a float inside the limits, else LimitError: ``WHERE: LABEL V UNIT is ...``."""
        unit = f" {self.unit}" if self.unit else ""
        number = as_number(value, where, self.label)
        if number < self.minimum:
            raise LimitError(
                f"{where}: {self.label} {number:g}{unit} is below the smallest accepted, "
                f"{self.minimum:g}{unit} (limits {self.describe()})"
            )
        if number > self.maximum:
            raise LimitError(
                f"{where}: {self.label} {number:g}{unit} is above the largest accepted, "
                f"{self.maximum:g}{unit} (limits {self.describe()})"
            )
        return number


#: The QR symbol's side L (quiet zone excluded): a 0.1 mm code is 4 um per module of a version 1
#: code, far below any printer; 10 m is a building's wall.
SIDE_MM = Limit("QR side", "mm", 0.1, 10_000.0, "a printable code to a wall-sized one")
#: Focal length in pixels: 10 px is a fish-eye of a few pixels; 100,000 px a telescope on a
#: 100 MP sensor.
FOCAL_PX = Limit("focal length", "px", 10.0, 100_000.0, "any lens on any sensor qrfield can read")
#: Width or height of a camera's image (pixels).
IMAGE_SIDE_PX = Limit("image size", "px", 8.0, 65_535.0, "OpenCV's image dimensions")
#: Corners given by hand (``solve --corners``) may lie this fraction of the image's width or height
#: outside it (a code cut by the image border, its hidden vertex extrapolated), no farther.
CORNER_MARGIN_FRACTION = 0.25
#: A lens model is usable when undistorting every border pixel of its image (the solvers' own
#: iteration, :data:`qrfield.lens.UNDISTORT_CRITERIA`) and distorting it back lands within
#: this many pixels of where it started, and the radial part grows monotonically up to there.
DISTORTION_ROUND_TRIP_PX = 0.01
#: How much a lens model may stretch or shrink the image's edge (distorted radius / undistorted
#: radius, on the ellipse inscribed in the image): a strong real barrel lens is about 0.6, a strong
#: pincushion 1.5; k1 = 1e6 is 24, which no lens the 5-coefficient model describes can be.
DISTORTION_SCALE = Limit("distortion scale at the image's edge", "", 1.0 / 3.0, 3.0)
#: A position given by hand (``--pose``, mm in the camera frame): a kilometre each way; 1e308 mm
#: overflowed the visibility test's norm into numpy warnings and a wrong "faces away".
POSITION_MM = Limit("position", "mm", -1_000_000.0, 1_000_000.0, "a kilometre from the camera")
#: An angle given by hand (degrees): one turn each way.
ANGLE_DEG = Limit("angle", "deg", -360.0, 360.0, "one turn each way")
#: How long a command runs when told to stop after S seconds: a week, far beyond any bench run,
#: and finite (``serial-demo --seconds 1e308`` ran forever).
DURATION_S = Limit("duration", "s", 0.0, 7 * 24 * 3600.0, "a week")
#: Frames, poses or lines per second a command produces or paces itself at.
RATE_HZ = Limit("rate", "Hz", 0.0, 1000.0, "faster than any camera or serial line qrfield drives")
#: Largest count of frames, lines, rows or samples a command is asked for: a week at 1000 per
#: second is 6e8.
MAX_COUNT = 1_000_000_000
#: Largest count of poses, views or rounds a benchmark is asked for (each figure takes seconds to
#: minutes at the defaults, a few hundred to 100,000).
MAX_BENCHMARK_COUNT = 10_000_000
#: Largest noise seed (numpy's generators take any non-negative integer; a 64-bit one is plenty).
MAX_SEED = 2**63 - 1
#: Largest USB camera index (``usb:N``): Linux numbers video devices 0..255
#: (``/dev/video255``); usb:99999999999999999999 gave seven lines of OpenCV's overload errors.
MAX_USB_INDEX = 255
#: Most worker processes a command starts.
MAX_WORKERS = 1024
#: Default pixel limit of an image to decode (megapixels): a 50 MP grey image is 50 MB, a colour
#: one 150 MB, which a Raspberry Pi can hold; 32000 x 24000 (768 MP, 2.3 GB) it cannot.
DEFAULT_MAX_MEGAPIXELS = 50.0


def check_corners_in_view(corners: Any, width: int, height: int, where: str = "--corners") -> None:
    """LimitError naming the vertex when a corner lies beyond the margin around a W x H image.

    ``corners``: (4, 2) pixels V1..V4 (OpenCV convention: the top-left pixel's centre is 0, 0).
    """
    mx, my = CORNER_MARGIN_FRACTION * width, CORNER_MARGIN_FRACTION * height
    lo_u, hi_u = -0.5 - mx, width - 0.5 + mx
    lo_v, hi_v = -0.5 - my, height - 0.5 + my
    for i, (u, v) in enumerate(corners, start=1):
        if not (math.isfinite(u) and math.isfinite(v)):
            raise LimitError(f"{where}: V{i} ({u}, {v}) is not a finite pixel")
        if not (lo_u <= u <= hi_u and lo_v <= v <= hi_v):
            raise LimitError(
                f"{where}: V{i} ({u:g}, {v:g}) px lies outside the {width}x{height} image by more than "
                f"{CORNER_MARGIN_FRACTION:.0%} of its size (u {lo_u:g}..{hi_u:g}, v {lo_v:g}..{hi_v:g})"
            )


#: A robot's tool position (pairs.csv, ``$QRC,TOOL``) in mm: 100 m is beyond any arm or gantry.
TOOL_POSITION_MM = Limit("tool position", "mm", -100_000.0, 100_000.0, "any robot's reach")
#: A robot's own pose uncertainty, 1 sigma (``handeye --tool-std-mm/--tool-std-deg``, the hand-eye
#: bench's noise): 100 mm and 10 degrees are far beyond any arm's repeatability.
TOOL_STD_MM = Limit("tool std mm", "mm", 0.0, 100.0, "far beyond any robot's repeatability")
TOOL_STD_DEG = Limit("tool std deg", "deg", 0.0, 10.0, "far beyond any robot's repeatability")
