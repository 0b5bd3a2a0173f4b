"""The camera model: pinhole intrinsics plus OpenCV's five distortion coefficients (CameraModel).

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

import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.camera.distortion import check_distortion
from qrfield.camera.fields import (
    ASPECT_TOLERANCE,
    REQUIRED_FIELDS,
    SENSOR_FIELDS,
    CameraModelError,
    _jsonable,
    _validate,
    _whole_numbers,
    check_crop,
    format_crop,
    image_distance_mm,
    sensor_fields,
)
from qrfield.files import Fields, FileFormatError, describe_value, read_json
from qrfield.lens import has_distortion


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
