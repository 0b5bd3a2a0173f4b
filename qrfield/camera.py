"""Camera models: pinhole intrinsics plus OpenCV's five distortion coefficients.

Conventions (docs/conventions.md): pixels follow OpenCV, the centre of the top-left pixel is (0, 0), so the
centre of a W x H image is ((W-1)/2, (H-1)/2). fx, fy, cx, cy are in pixels; the distortion
coefficients (k1, k2, p1, p2, k3) act on normalised image coordinates and are unitless.

A camera is named on the command line as one of
  - ``NAME[@WxH]``: a profile ``NAME.json`` looked up in ``./calib``, the user's profile folder
    (``$QRFIELD_CALIB_DIR`` or ``~/.config/qrfield/calib``), then the presets shipped in ``calib/``;
  - ``PATH[@WxH]``: a JSON file;
  - ``--focal-px F --size WxH``: the thesis' minimal model (principal point at the image centre).
``@WxH`` rescales the profile to another resolution of the same sensor mode (same aspect ratio).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from qrfield import paths

#: Fields every camera JSON file must have.
REQUIRED_FIELDS = ("width", "height", "fx", "fy", "cx", "cy")
#: Largest relative aspect-ratio mismatch accepted when rescaling to another resolution.
ASPECT_TOLERANCE = 0.01
#: The camera model used when none is named (the virtual bench renders through it, too).
DEFAULT_CAMERA = "picam-v2@640x480"


class CameraModelError(ValueError):
    """A camera model, file or name that cannot be used; the message names file and field."""


@dataclass(frozen=True)
class CameraModel:
    """Pinhole camera with OpenCV distortion.

    Attributes:
        fx, fy: focal lengths in pixels (> 0).
        cx, cy: principal point in pixels, OpenCV convention (top-left pixel centre = (0, 0)).
        width, height: image size in pixels.
        dist: (5,) OpenCV distortion coefficients k1, k2, p1, p2, k3 (zeros = ideal pinhole).
        name: a label for humans (preset name or file stem).
        notes: free text: where the numbers come from.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    name: str = "custom"
    notes: str = ""

    def __post_init__(self) -> None:
        dist = np.asarray(self.dist, dtype=float).reshape(-1)
        if dist.size > 5:
            # Only the 5-term model is used; extra zero terms (rational model) are tolerated.
            if np.any(dist[5:] != 0):
                raise CameraModelError(
                    f"camera {self.name!r}: field 'dist' has {dist.size} non-zero terms; "
                    "only k1, k2, p1, p2, k3 are supported"
                )
            dist = dist[:5]
        dist = np.pad(dist, (0, 5 - dist.size))
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        for key in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, key, float(getattr(self, key)))
        _validate(self.fx, self.fy, self.cx, self.cy, self.width, self.height, f"camera {self.name!r}")

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_focal(cls, focal_px: float, width: int, height: int, name: str = "focal-only") -> CameraModel:
        """The thesis' minimal model: one focal length (px), principal point at the image centre."""
        return cls(
            fx=focal_px,
            fy=focal_px,
            cx=(width - 1) / 2.0,
            cy=(height - 1) / 2.0,
            width=width,
            height=height,
            name=name,
            notes="focal length only; principal point at the image centre; no distortion",
        )

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "camera") -> CameraModel:
        """Build from a JSON-like dict; raises CameraModelError naming ``where`` and the field."""
        if not isinstance(data, dict):
            raise CameraModelError(f"{where}: expected a JSON object, got {type(data).__name__}")
        for key in REQUIRED_FIELDS:
            if key not in data:
                raise CameraModelError(f"{where}: missing field '{key}'")
        values: dict[str, Any] = {}
        for key in REQUIRED_FIELDS:
            value = data[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise CameraModelError(f"{where}: field '{key}' must be a number, got {value!r}")
            if not math.isfinite(value):
                raise CameraModelError(f"{where}: field '{key}' must be finite, got {value!r}")
            values[key] = value
        for key in ("width", "height"):
            if values[key] != int(values[key]) or values[key] <= 0:
                raise CameraModelError(
                    f"{where}: field '{key}' must be a positive whole number of pixels, got {values[key]!r}"
                )
        dist = data.get("dist", [0.0] * 5)
        try:
            dist_arr = np.asarray(dist, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise CameraModelError(f"{where}: field 'dist' must be a list of numbers, got {dist!r}") from None
        if not np.all(np.isfinite(dist_arr)):
            raise CameraModelError(f"{where}: field 'dist' has a non-finite value: {dist!r}")
        _validate(
            values["fx"],
            values["fy"],
            values["cx"],
            values["cy"],
            int(values["width"]),
            int(values["height"]),
            where,
        )
        return cls(
            fx=values["fx"],
            fy=values["fy"],
            cx=values["cx"],
            cy=values["cy"],
            width=int(values["width"]),
            height=int(values["height"]),
            dist=dist_arr,
            name=str(data.get("name", "custom")),
            notes=str(data.get("notes", "")),
        )

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> CameraModel:
        """Load a camera JSON file; one clear CameraModelError naming the file and field."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise CameraModelError(f"camera file {path}: no such file") from None
        except OSError as exc:
            raise CameraModelError(f"camera file {path}: cannot read ({exc.strerror})") from None
        except UnicodeDecodeError:
            raise CameraModelError(f"camera file {path}: not JSON (not UTF-8 text)") from None
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise CameraModelError(f"camera file {path}: not JSON ({exc.msg} at line {exc.lineno})") from None
        if isinstance(data, dict) and "name" not in data:
            data = {**data, "name": path.stem}
        return cls.from_dict(data, where=f"camera file {path}")

    # ------------------------------------------------------------------ output
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the same fields :meth:`from_dict` reads)."""
        return {
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "dist": [float(d) for d in self.dist],
            "notes": self.notes,
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model as JSON (UTF-8, indented), all or nothing: a crash or power cut while
        overwriting a calibrated profile leaves the old file, never a truncated one."""
        from qrfield.sessions.files import atomic_write  # lazily: sessions imports this module

        atomic_write(path, (json.dumps(self.to_dict(), indent=2) + "\n").encode("utf-8"))

    # ------------------------------------------------------------------ derived
    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return (self.width, self.height)

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0.0))

    @property
    def fov_deg(self) -> tuple[float, float]:
        """Horizontal and vertical field of view in degrees (pinhole, ignoring distortion)."""
        return (
            math.degrees(2 * math.atan(self.width / (2 * self.fx))),
            math.degrees(2 * math.atan(self.height / (2 * self.fy))),
        )

    def scaled(self, width: int, height: int) -> CameraModel:
        """The same sensor mode at another resolution (same aspect ratio within 1 %).

        Focal lengths scale with the size; the principal point scales about the pixel edge, so
        pixel centres stay consistent: c' = (c + 0.5) * s - 0.5. Distortion is unchanged (it acts
        on normalised coordinates).
        """
        if width <= 0 or height <= 0:
            raise CameraModelError(f"camera {self.name!r}: size {width}x{height} must be positive")
        sx, sy = width / self.width, height / self.height
        if abs(sx / sy - 1.0) > ASPECT_TOLERANCE:
            raise CameraModelError(
                f"camera {self.name!r}: {width}x{height} has another aspect ratio than its "
                f"{self.width}x{self.height} profile ({width / height:.3f} vs "
                f"{self.width / self.height:.3f}); a cropped sensor mode needs its own profile "
                "(calibrate it, or give --focal-px and --size)"
            )
        if (width, height) == (self.width, self.height):
            return self
        return replace(
            self,
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
            width=width,
            height=height,
            name=f"{self.name.split('@')[0]}@{width}x{height}",
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CameraModel):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_dict(), sort_keys=True))


def _validate(fx: float, fy: float, cx: float, cy: float, width: int, height: int, where: str) -> None:
    """Raise CameraModelError (prefixed with ``where``) for unusable intrinsics."""
    if width <= 0 or height <= 0:
        raise CameraModelError(f"{where}: image size {width}x{height} must be positive")
    for key, value in (("fx", fx), ("fy", fy)):
        if not math.isfinite(value) or value <= 0:
            raise CameraModelError(
                f"{where}: field '{key}' must be a positive focal length in pixels, got {value!r}"
            )
    if not (-0.5 <= cx <= width - 0.5):
        raise CameraModelError(
            f"{where}: field 'cx' = {cx!r} puts the principal point outside the {width}-pixel-wide image"
        )
    if not (-0.5 <= cy <= height - 0.5):
        raise CameraModelError(
            f"{where}: field 'cy' = {cy!r} puts the principal point outside the {height}-pixel-high image"
        )


# ---------------------------------------------------------------------- lookup by name


def preset_dir() -> Path:
    """Folder of the presets shipped with qrfield (the repository's ``calib/``)."""
    try:
        return Path(str(resources.files("qrfield_calib")))
    except ModuleNotFoundError:  # running from a source tree that is not installed
        return Path(__file__).resolve().parent.parent / "calib"


def user_profile_dirs() -> list[Path]:
    """Folders searched for ``NAME.json`` before the shipped presets, in order."""
    dirs = [Path.cwd() / "calib"]
    env = os.environ.get("QRFIELD_CALIB_DIR")
    if env:
        dirs.append(Path(env))
    dirs.append(paths.user_calib_dir())
    return dirs


def preset_names() -> list[str]:
    """Names of the shipped presets (e.g. ``picam-v2``)."""
    return sorted(p.stem for p in preset_dir().glob("*.json"))


def parse_size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` (e.g. ``640x480``) into (width, height); CameraModelError if malformed."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise CameraModelError(f"image size {text!r} is not of the form WxH, e.g. 640x480")
    width, height = int(parts[0]), int(parts[1])
    if width <= 0 or height <= 0:
        raise CameraModelError(f"image size {text!r} must be positive")
    return width, height


def resolve_camera(spec: str) -> CameraModel:
    """A camera from ``NAME[@WxH]`` or ``PATH[@WxH]`` (see the module docstring)."""
    spec = spec.strip()
    if not spec:
        raise CameraModelError("empty camera name; give a preset such as picam-v2@640x480")
    # A file that exists is taken whole, so that a path may contain '@' (/home/me@lab/cam.json).
    whole_file = Path(spec).expanduser().is_file()
    base, _, size_text = spec.rpartition("@") if "@" in spec and not whole_file else (spec, "", "")
    size = parse_size(size_text) if size_text else None
    path = Path(base).expanduser()
    if base.endswith(".json") or os.sep in base or path.is_file():
        camera = CameraModel.load(path)
    else:
        candidates = [d / f"{base}.json" for d in user_profile_dirs()] + [preset_dir() / f"{base}.json"]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            raise CameraModelError(
                f"no camera profile named {base!r}; presets: {', '.join(preset_names())} "
                "(or give a path to a JSON file, or --focal-px F --size WxH)"
            )
        camera = CameraModel.load(found)
    return camera.scaled(*size) if size else camera


def add_camera_arguments(parser: Any, default: str | None = None) -> None:
    """Add ``--camera``, ``--focal-px`` and ``--size`` to an argparse parser."""
    parser.add_argument(
        "--camera",
        default=default,
        metavar="CAM",
        help="camera profile NAME[@WxH] (presets: picam-v1, picam-v2, picam-v3, picam-hq-6mm, "
        "webcam-60) or PATH.json[@WxH]",
    )
    parser.add_argument("--focal-px", type=float, metavar="F", help="focal length in pixels (with --size)")
    parser.add_argument("--size", metavar="WxH", help="image size for --focal-px, e.g. 640x480")
    # Remembered so that camera_from_args can tell a default --camera from one the user typed.
    parser.set_defaults(_camera_default=default)


def camera_from_args(args: Any) -> CameraModel:
    """The camera named by ``--camera`` or ``--focal-px``/``--size``.

    ``--focal-px``/``--size`` win over a default ``--camera``; CameraModelError if neither is
    given, or if both a typed ``--camera`` and ``--focal-px``/``--size`` are (which one was meant?).
    """
    focal, size = getattr(args, "focal_px", None), getattr(args, "size", None)
    if focal is not None or size is not None:
        camera = getattr(args, "camera", None)
        if camera and camera != getattr(args, "_camera_default", None):
            raise CameraModelError(f"give either --camera ({camera}) or --focal-px/--size, not both")
        if focal is None or size is None:
            raise CameraModelError("--focal-px and --size go together, e.g. --focal-px 620 --size 640x480")
        if not math.isfinite(focal) or focal <= 0:
            raise CameraModelError(f"--focal-px must be a positive number of pixels, got {focal}")
        width, height = parse_size(size)
        return CameraModel.from_focal(focal, width, height)
    if not getattr(args, "camera", None):
        raise CameraModelError("name a camera: --camera NAME[@WxH] or --focal-px F --size WxH")
    return resolve_camera(args.camera)
