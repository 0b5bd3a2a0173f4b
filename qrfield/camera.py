"""Camera models: pinhole intrinsics plus OpenCV's five distortion coefficients.

Conventions (docs/conventions.md): pixels follow OpenCV, the centre of the top-left pixel is (0, 0), so the
centre of a W x H image is ((W-1)/2, (H-1)/2). fx, fy, cx, cy are in pixels; the distortion
coefficients (k1, k2, p1, p2, k3) act on normalised image coordinates and are unitless.

A camera is named on the command line as one of
  - ``NAME[@WxH]``: a profile ``NAME.json`` looked up in ``$QRFIELD_CALIB_DIR``, then the user's
    profile folder (``~/.config/qrfield/calib``, where calibrations are saved), then the presets
    shipped in ``calib/``. A profile of the user's with a preset's name is the user's choice and
    wins, and :func:`camera_origin` says so; a ``./calib`` folder in the current folder is *not*
    searched by name (it would silently replace a preset wherever one happens to be): give its
    path, ``--camera calib/NAME.json``;
  - ``PATH[@WxH]``: a JSON file (relative paths from the current folder);
  - ``--focal-px F --size WxH``: the thesis' minimal model (principal point at the image centre).
``@WxH`` rescales the profile to another resolution of the same sensor mode (same aspect ratio).
Every number is checked against :mod:`qrfield.limits`: focal lengths, image size, and a lens
model that OpenCV can invert over the whole image (:func:`check_distortion`).

Camera models follow the stream (docs/conventions.md): a profile may state which rectangle of the
sensor's full-resolution pixel array its image covers (``sensor_crop``, with ``sensor_resolution``);
:meth:`CameraModel.through_crop` then gives the model of any stream that delivers a crop, or a scaled
crop, of that array (a sensor mode, the ISP's crop to the output's aspect ratio: picamera2's
``ScalerCrop``). An autofocus lens moves: ``lens_position`` (dioptres) is where the profile's
intrinsics hold, and :meth:`CameraModel.at_lens_position` follows a focus change where the lens's
focal length in mm is known (thin lens).
"""

from __future__ import annotations

import functools
import json
import math
import os
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from qrfield import paths
from qrfield.files import Fields, FileFormatError, describe_value, read_json
from qrfield.lens import has_distortion, undistort_points
from qrfield.limits import DISTORTION_ROUND_TRIP_PX, DISTORTION_SCALE, FOCAL_PX, IMAGE_SIDE_PX, LimitError

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
        sensor_resolution: (W, H) of the sensor's full-resolution pixel array, or None if unknown.
        sensor_crop: (x, y, w, h), the rectangle of the full-resolution pixel array (in its pixels)
            that this model's image covers (picamera2's ``ScalerCrop``), or None if unknown; the
            image is that rectangle scaled to width x height.
        sensor_mode: the sensor mode the image came from, for the record (e.g. ``1640x1232 10-bit``).
        lens_position: the lens position (dioptres, 1 / focus distance in m) at which the
            intrinsics hold, for autofocus cameras; None if not stated.
        focal_length_mm: the lens's focal length in mm (datasheet), or None; a model with it and
            no lens_position is taken to be focused at infinity (a datasheet model).
        path: the profile file it was read from ("" when built otherwise); not part of equality
            (nor of :meth:`to_dict`), so a profile is the same model wherever it was read from.
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
    sensor_resolution: tuple[int, int] | None = None
    sensor_crop: tuple[int, int, int, int] | None = None
    sensor_mode: str = ""
    lens_position: float | None = None
    focal_length_mm: float | None = None
    path: str = field(default="", compare=False)

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
        checked = sensor_fields({key: getattr(self, key) for key in SENSOR_FIELDS}, f"camera {self.name!r}")
        for key, value in checked.items():
            object.__setattr__(self, key, value)
        check_distortion(self, f"camera {self.name!r}")

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
            raise CameraModelError(f"{where}: expected a JSON object, got {describe_value(data)}")
        for key in REQUIRED_FIELDS:
            if key not in data:
                raise CameraModelError(f"{where}: missing field '{key}'")
        values: dict[str, Any] = {}
        fields = Fields(data, where)
        try:
            for key in REQUIRED_FIELDS:
                values[key] = fields.number(key)
            name = fields.text("name", "custom", max_chars=200)
            notes = fields.text("notes", "")
        except FileFormatError as exc:
            raise CameraModelError(str(exc)) from None
        for key in ("width", "height"):
            if values[key] != int(values[key]) or values[key] <= 0:
                raise CameraModelError(
                    f"{where}: field '{key}' must be a positive whole number of pixels, got {values[key]!r}"
                )
        dist = data.get("dist", [0.0] * 5)
        if not isinstance(dist, list) or not all(
            isinstance(d, (int, float)) and not isinstance(d, bool) for d in dist
        ):
            raise CameraModelError(
                f"{where}: field 'dist' must be a list of numbers k1, k2, p1, p2, k3, "
                f"got {describe_value(dist)}"
            )
        if len(dist) > 14:  # OpenCV's longest model
            raise CameraModelError(
                f"{where}: field 'dist' has {len(dist)} terms; OpenCV's models have at most 14"
            )
        dist_arr = np.asarray(dist, dtype=float).reshape(-1)
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
        try:
            return cls(
                fx=values["fx"],
                fy=values["fy"],
                cx=values["cx"],
                cy=values["cy"],
                width=int(values["width"]),
                height=int(values["height"]),
                dist=dist_arr,
                name=name,
                notes=notes,
                **sensor_fields({key: data.get(key) for key in SENSOR_FIELDS}, where),
            )
        except CameraModelError as exc:  # the distortion check: name the file, not the model
            raise CameraModelError(str(exc).replace(f"camera {name!r}", where, 1)) from None

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> CameraModel:
        """Load a camera JSON file; one clear CameraModelError naming the file and field."""
        path = Path(path)
        try:
            data = read_json(path, "camera file", max_bytes=1024 * 1024)
        except FileFormatError as exc:
            raise CameraModelError(str(exc)) from None
        if isinstance(data, dict) and "name" not in data:
            data = {**data, "name": path.stem}
        return replace(cls.from_dict(data, where=f"camera file {path}"), path=str(path))

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
        } | {
            key: _jsonable(getattr(self, key))
            for key in SENSOR_FIELDS
            if getattr(self, key) not in (None, "")
        }

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = True) -> None:
        """Write the model as JSON (UTF-8, indented), all or nothing: a crash or power cut while
        overwriting a calibrated profile leaves the old file, never a truncated one. The folder must
        exist; ``overwrite=False``: FileExistsError if ``path`` exists."""
        from qrfield.files import atomic_write

        atomic_write(path, json.dumps(self.to_dict(), indent=2) + "\n", overwrite=overwrite)

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
        """True when any distortion coefficient is non-zero (qrfield.lens.has_distortion)."""
        return has_distortion(self)

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
                f"{self.width / self.height:.3f}): a crop of the sensor is another field of view. With "
                "picamera2 name the full-sensor profile (e.g. picam-v3): the stream's model is derived "
                "from its sensor crop (docs/cameras.md); otherwise calibrate at this size"
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

    def through_crop(
        self, crop_xywh: Any, out_size: tuple[int, int], *, sensor_mode: str = ""
    ) -> CameraModel:
        """The model of a stream that delivers the sensor rectangle ``crop_xywh`` scaled to ``out_size``.

        docs/conventions.md, "Camera models follow the stream": with f, c in full-resolution pixels,
        f_out = f * out_w / crop_w and c_out = (c - crop_x + 0.5) * out_w / crop_w - 0.5 (the same
        for y with out_h, crop_h). This model's own image covers ``sensor_crop`` (scaled to its
        width x height), so it is first taken back to full-resolution pixels by the inverse mapping.
        Distortion acts on normalised coordinates and is unchanged.

        Args:
            crop_xywh: (x, y, w, h) in full-resolution sensor pixels (picamera2's ``ScalerCrop``).
            out_size: (width, height) of the stream's images, pixels.
            sensor_mode: the sensor mode, recorded in the result (e.g. ``1640x1232 10-bit``).

        Raises:
            CameraModelError: this model does not state its ``sensor_crop`` (so which part of the
                sensor it describes is unknown), or the crop lies outside its sensor_resolution.
        """
        where = f"camera {self.name!r}"
        if self.sensor_crop is None:
            raise CameraModelError(
                f"{where} does not say which part of the sensor it describes (no 'sensor_crop'), so it "
                f"cannot be mapped to a stream that shows the sensor crop {format_crop(crop_xywh)}: use a "
                'preset, add "sensor_crop": [x, y, w, h] (full-resolution pixels of the area the profile '
                'was calibrated on) and "sensor_resolution": [W, H] to its JSON, or calibrate again '
                "(qrfield calibrate records them); see docs/cameras.md"
            )
        crop = check_crop(_whole_numbers(crop_xywh, 4, "crop", where), self.sensor_resolution, where)
        out_w, out_h = _whole_numbers(out_size, 2, "output size", where)
        if out_w <= 0 or out_h <= 0:
            raise CameraModelError(f"{where}: output size {out_w}x{out_h} must be positive")
        own_x, own_y, own_w, own_h = self.sensor_crop
        # This model's pixels -> full-resolution pixels (the inverse of the formula above).
        fx_full, fy_full = self.fx * own_w / self.width, self.fy * own_h / self.height
        cx_full = (self.cx + 0.5) * own_w / self.width - 0.5 + own_x
        cy_full = (self.cy + 0.5) * own_h / self.height - 0.5 + own_y
        x, y, w, h = crop
        base = self.name.split("@")[0]
        outside = (
            not (own_x <= x and own_y <= y and x + w <= own_x + own_w and y + h <= own_y + own_h)
            and self.has_distortion
        )
        how = (
            f"{base} mapped through sensor crop {format_crop(crop)} to {out_w}x{out_h}"
            + (f" (sensor mode {sensor_mode})" if sensor_mode else "")
            + (
                f"; the crop reaches outside the calibrated area {format_crop(self.sensor_crop)}, where "
                "the distortion is extrapolated"
                if outside
                else ""
            )
        )
        return replace(
            self,
            fx=fx_full * out_w / w,
            fy=fy_full * out_h / h,
            cx=(cx_full - x + 0.5) * out_w / w - 0.5,
            cy=(cy_full - y + 0.5) * out_h / h - 0.5,
            width=out_w,
            height=out_h,
            name=f"{base}@{out_w}x{out_h}",
            notes=f"{how}. {self.notes}".strip(),
            sensor_crop=crop,
            sensor_mode=sensor_mode or self.sensor_mode,
        )

    def at_lens_position(self, dioptres: float) -> tuple[CameraModel, str]:
        """The model with the lens focused at ``dioptres`` (1 / focus distance in m), and how it was made.

        Focusing closer moves the lens away from the sensor: by the thin-lens equation the image
        distance is v(P) = 1 / (1/f - P/1000) mm, and the focal lengths in pixels scale with it.
        That needs the lens's focal length (``focal_length_mm``); the model's own lens position is
        its ``lens_position``, or infinity (0) for a datasheet model without one. Without
        ``focal_length_mm`` the intrinsics are kept and the text says they may be off.
        """
        if not math.isfinite(dioptres) or dioptres < 0:
            raise CameraModelError(f"lens position must be >= 0 dioptres, got {dioptres!r}")
        own = self.lens_position
        focal = self.focal_length_mm
        if own is None and not focal:
            return replace(self, lens_position=float(dioptres)), (
                f"camera model {self.name!r} does not state the lens position it holds at; focus fixed at "
                f"{dioptres:g} dioptres, intrinsics used as they are (calibrate at this lens position)"
            )
        if own == dioptres:
            return replace(self, lens_position=float(dioptres)), (
                f"focus fixed at {dioptres:g} dioptres, the lens position camera model {self.name!r} holds at"
            )
        if not focal:
            return replace(self, lens_position=float(dioptres)), (
                f"lens position {dioptres:g} dioptres differs from the {own:g} dioptres camera model "
                f"{self.name!r} was calibrated at: the focal length moves with the lens, so distances may be "
                "off by a few per cent (calibrate at this lens position, or set it back)"
            )
        scale = image_distance_mm(focal, dioptres) / image_distance_mm(focal, own or 0.0)
        how = f"focal lengths scaled by {scale:.5f} (thin lens, f = {focal:g} mm)"
        if own is None:
            text = (
                f"{self.name!r} is a datasheet model (focused at infinity): {how} for the lens at "
                f"{dioptres:g} dioptres"
            )
        else:
            text = (
                f"lens position {dioptres:g} dioptres differs from the {own:g} dioptres camera model "
                f"{self.name!r} was calibrated at: {how}; calibrate at this lens position for best accuracy"
            )
        return (
            replace(
                self,
                fx=self.fx * scale,
                fy=self.fy * scale,
                lens_position=float(dioptres),
                notes=f"{text}. {self.notes}".strip(),
            ),
            text,
        )

    def summary(self) -> str:
        """One line: size, intrinsics, and the sensor crop when known."""
        text = (
            f"{self.width}x{self.height} px, fx {self.fx:.1f}, fy {self.fy:.1f}, "
            f"cx {self.cx:.1f}, cy {self.cy:.1f}"
        )
        if self.sensor_crop is not None:
            text += f", sensor crop {format_crop(self.sensor_crop)}"
        if self.lens_position is not None:
            text += f", lens {self.lens_position:g} dioptres"
        return text

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CameraModel):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_dict(), sort_keys=True))


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


def check_distortion(camera: CameraModel, where: str) -> None:
    """CameraModelError naming ``where`` and 'dist' when the lens model cannot be inverted over the image.

    Usable means (qrfield.limits.DISTORTION_ROUND_TRIP_PX): every point of the ellipse inscribed in
    the image (through the middles of its four edges), undistorted by the solvers' own iteration and
    distorted back by cv2.projectPoints, lands within that many pixels of itself, and the radial
    factor r (1 + k1 r^2 + k2 r^4 + k3 r^6) keeps growing out to there (the model does not fold back
    inside it). k1 = 1e6 fails the first (OpenCV's iteration oscillates); k1 = -1 on a wide lens both.
    The image's corners beyond the ellipse are not required: a real calibration with k3 often folds
    there, where its chessboard views never reached (:func:`distortion_note` says so).
    """
    if not camera.has_distortion:
        return
    problem = _distortion_problem(*_distortion_key(camera), corners=False)
    if problem:
        coefficients = ", ".join(f"{d:g}" for d in camera.dist)
        raise CameraModelError(f"{where}: field 'dist' ({coefficients}) {problem}")


def distortion_note(camera: CameraModel) -> str:
    """ "" when the lens model can be inverted over the whole image, corners included; else one line
    saying that poses from codes in the corners are unreliable (for calibrate's advice)."""
    if not camera.has_distortion:
        return ""
    problem = _distortion_problem(*_distortion_key(camera), corners=True)
    if not problem:
        return ""
    return (
        f"the lens model {problem.replace('over the', 'in the corners of the')}: poses from codes "
        "near the corners are unreliable; take views that reach the corners, or calibrate with --fix-k3"
    )


def _distortion_key(camera: CameraModel) -> tuple[Any, ...]:
    return (
        camera.fx,
        camera.fy,
        camera.cx,
        camera.cy,
        camera.width,
        camera.height,
        tuple(camera.dist.tolist()),
    )


@functools.lru_cache(maxsize=64)
def _distortion_problem(
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    width: int,
    height: int,
    dist: tuple[float, ...],
    corners: bool,
) -> str:
    """Why the model cannot be inverted over the inscribed ellipse (or, ``corners``, the whole
    image's border at its pixel edges), or ""."""
    import cv2

    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    D = np.asarray(dist, dtype=float)
    if corners:
        n = 64  # points per side of the border (pixel edges), corners included
        u = np.linspace(-0.5, width - 0.5, n + 1)
        v = np.linspace(-0.5, height - 0.5, n + 1)
        outline = np.concatenate(
            [
                np.column_stack([u, np.full_like(u, -0.5)]),
                np.column_stack([u, np.full_like(u, height - 0.5)]),
                np.column_stack([np.full_like(v, -0.5), v]),
                np.column_stack([np.full_like(v, width - 0.5), v]),
            ]
        )
    else:
        t = np.linspace(0.0, 2.0 * np.pi, 256, endpoint=False)
        outline = np.column_stack(
            [(width - 1) / 2.0 + width / 2.0 * np.cos(t), (height - 1) / 2.0 + height / 2.0 * np.sin(t)]
        )
    pts = outline.reshape(-1, 1, 2)
    with np.errstate(all="ignore"):
        # The solvers' iteration (qrfield.lens) is what must work.
        ideal = undistort_points(pts, K, D).reshape(-1, 2)
        if not np.all(np.isfinite(ideal)):
            return f"cannot be inverted over the {width}x{height} image (OpenCV's undistortion diverges)"
        rays = np.column_stack([ideal, np.ones(len(ideal))])
        back, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, D)
        miss = float(np.nanmax(np.abs(back.reshape(-1, 2) - outline)))
    if not math.isfinite(miss) or miss > DISTORTION_ROUND_TRIP_PX:
        return (
            f"cannot be inverted over the {width}x{height} image: undistorting points of the image and "
            f"distorting them back misses by {miss:.3g} px (at most {DISTORTION_ROUND_TRIP_PX:g} px)"
        )
    distorted = np.column_stack([(outline[:, 0] - cx) / fx, (outline[:, 1] - cy) / fy])
    with np.errstate(all="ignore"):
        scale = np.hypot(distorted[:, 0], distorted[:, 1]) / np.hypot(ideal[:, 0], ideal[:, 1])
    scale = scale[np.isfinite(scale)]
    for extreme in (float(scale.min()), float(scale.max())) if scale.size else ():
        if not DISTORTION_SCALE.minimum <= extreme <= DISTORTION_SCALE.maximum:
            return (
                f"{'stretches' if extreme > 1 else 'shrinks'} the {width}x{height} image's edge "
                f"{extreme:.3g} times (a real lens: {DISTORTION_SCALE.minimum:.2g}.."
                f"{DISTORTION_SCALE.maximum:g}); is it a calibration of this camera?"
            )
    k1, k2, k3 = D[0], D[1] if D.size > 1 else 0.0, D[4] if D.size > 4 else 0.0
    r = np.linspace(0.0, float(np.hypot(ideal[:, 0], ideal[:, 1]).max()), 2001)
    growth = 1.0 + 3.0 * k1 * r**2 + 5.0 * k2 * r**4 + 7.0 * k3 * r**6  # d/dr of r * radial factor
    if np.any(growth <= 0.0):
        fold = float(r[np.argmax(growth <= 0.0)])
        return (
            f"folds back over the {width}x{height} image: its radial distortion stops growing "
            f"{math.degrees(math.atan(fold)):.1f} degrees off the axis, inside the field of view"
        )
    return ""


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


# ---------------------------------------------------------------------- lookup by name


def preset_dir() -> Path:
    """Folder of the presets shipped with qrfield (the repository's ``calib/``)."""
    try:
        return Path(str(resources.files("qrfield_calib")))
    except ModuleNotFoundError:  # running from a source tree that is not installed
        return Path(__file__).resolve().parent.parent / "calib"


def user_profile_dirs() -> list[Path]:
    """Folders searched for ``NAME.json`` before the shipped presets, in order.

    ``$QRFIELD_CALIB_DIR`` (if set), then the user's profile folder. The current folder's
    ``./calib`` is not searched by name: see the module docstring.
    """
    dirs = []
    env = os.environ.get("QRFIELD_CALIB_DIR", "").strip()
    if env:
        dirs.append(Path(env).expanduser())
    dirs.append(paths.user_calib_dir())
    return dirs


def camera_origin(camera: CameraModel) -> str:
    """Where a camera model came from, with the file's path, for the line every command prints."""
    if not camera.path:
        return camera.notes.split(";")[0] if camera.notes else "built in"
    file = Path(camera.path)
    try:
        preset = file.resolve().parent == preset_dir().resolve()
    except OSError:
        preset = False
    if preset:
        return f"shipped preset {file}"
    shadowed = (preset_dir() / file.name).is_file() and any(file.parent == d for d in user_profile_dirs())
    note = " (it replaces the shipped preset of that name)" if shadowed else ""
    return f"profile {file}{note}"


def say_camera(camera: CameraModel, command: str) -> None:
    """One line on stderr naming the camera model and the file it came from (docs/cli.md)."""
    import sys

    print(f"qrfield {command}: camera {camera.name} from {camera_origin(camera)}", file=sys.stderr)


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
    try:
        for value in (width, height):
            IMAGE_SIDE_PX.check(value, f"image size {text!r}")
    except LimitError as exc:
        raise CameraModelError(str(exc)) from None
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
        if base in (".", "..") or "/" in base:  # a name, never a path outside the folders searched
            raise CameraModelError(f"no camera profile named {base!r}")
        candidates = [d / f"{base}.json" for d in user_profile_dirs()] + [preset_dir() / f"{base}.json"]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            local = Path("calib") / f"{base}.json"
            hint = (
                f"; ./{local} is not searched by name: give its path, --camera {local}"
                if local.is_file()
                else ""
            )
            raise CameraModelError(
                f"no camera profile named {base!r}; presets: {', '.join(preset_names())} "
                f"(or give a path to a JSON file, or --focal-px F --size WxH){hint}"
            )
        camera = CameraModel.load(found)
    return camera.scaled(*size) if size else camera


def add_camera_arguments(parser: Any, default: str | None = None, focal_only: bool = False) -> None:
    """Add ``--camera``, ``--focal-px`` and ``--size`` to an argparse parser.

    ``focal_only``: the command takes images, whose own size serves when ``--size`` is left out
    (see :func:`camera_from_args`).
    """
    parser.add_argument(
        "--camera",
        default=default,
        metavar="CAM",
        help="camera profile NAME[@WxH] (your profiles in ~/.config/qrfield/calib, then the presets "
        "picam-v1, picam-v2, picam-v3, picam-hq-6mm, webcam-60) or PATH.json[@WxH]; the file used is printed",
    )
    from qrfield.arguments import limited

    parser.add_argument(
        "--focal-px",
        type=limited(FOCAL_PX, "--focal-px"),
        metavar="F",
        help=f"focal length in pixels ({FOCAL_PX.describe()}), with --size"
        + (
            " (with IMAGE files, --size may be left out: each image's own size is taken)"
            if focal_only
            else ""
        ),
    )
    parser.add_argument("--size", metavar="WxH", help="image size for --focal-px, e.g. 640x480")
    # Remembered so that camera_from_args can tell a default --camera from one the user typed.
    parser.set_defaults(_camera_default=default)


def camera_from_args(args: Any, focal_only: bool = False) -> CameraModel | None:
    """The camera named by ``--camera`` or ``--focal-px``/``--size``.

    ``--focal-px``/``--size`` win over a default ``--camera``; CameraModelError if neither is
    given, or if both a typed ``--camera`` and ``--focal-px``/``--size`` are (which one was meant?).
    ``focal_only``: ``--focal-px`` without ``--size`` is accepted and gives None: the caller makes
    :meth:`CameraModel.from_focal` at each image's own size (``args.focal_px``).
    """
    focal, size = getattr(args, "focal_px", None), getattr(args, "size", None)
    if focal is not None or size is not None:
        camera = getattr(args, "camera", None)
        if camera and camera != getattr(args, "_camera_default", None):
            raise CameraModelError(f"give either --camera ({camera}) or --focal-px/--size, not both")
        if focal is not None and size is None and focal_only:
            _checked_focal(focal)
            return None
        if focal is None or size is None:
            raise CameraModelError("--focal-px and --size go together, e.g. --focal-px 620 --size 640x480")
        width, height = parse_size(size)
        return CameraModel.from_focal(_checked_focal(focal), width, height)
    if not getattr(args, "camera", None):
        raise CameraModelError("name a camera: --camera NAME[@WxH] or --focal-px F --size WxH")
    return resolve_camera(args.camera)


def _checked_focal(focal: Any) -> float:
    try:
        return FOCAL_PX.check(focal, "--focal-px")
    except LimitError as exc:
        raise CameraModelError(str(exc)) from None
