"""The Raspberry Pi camera through picamera2 (imported only when this source is opened).

picamera2 ships with Raspberry Pi OS (apt package ``python3-picamera2``), not from PyPI; see
DEVELOPERS.md. What this source does about the things that move under a camera model:

- **Sensor mode.** picamera2 would pick a cropped mode for some sizes (640x480 on an IMX219 sees
  only the centre 1280x960 sensor pixels; picamera2 issue 1233). By default the source asks for the
  binned full-field-of-view mode for the output's aspect ratio (``sensor={'output_size': ...}``;
  :mod:`qrfield.sources.sensor_modes`); ``sensor_mode`` chooses another.
- **Crop.** After ``configure()`` it reads the chosen mode back and takes the ``ScalerCrop`` (the
  ISP's crop of the mode's field to the output's aspect ratio, in full-resolution pixels) from the
  first frame's metadata; the stream's camera model (:attr:`Picamera2Source.camera`) is the
  full-resolution profile mapped through that crop (docs/conventions.md, "Camera models follow
  the stream"). A profile that does not say which part of the sensor it describes is refused.
  A frame whose ScalerCrop differs (a digital zoom) stops the source with a clear error.
- **Focus.** On a camera with ``AfMode`` in its controls (Camera Module 3) the focus is manual at
  ``lens_position`` dioptres; a lens position other than the profile's is a warning in ``notes``.
- **Exposure.** Fixed, or locked at the automatic exposure's values after ``settle_frames``.
- **Time.** A frame's time is its own ``SensorTimestamp`` (ns, on the monotonic clock) when given.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from qrfield.camera import CameraModel, CameraModelError, format_crop
from qrfield.geometry import Pose
from qrfield.settings import setting, validated
from qrfield.sources.base import SETTLE_FRAMES, Frame, FrameSource, SourceError
from qrfield.sources.sensor_modes import PICAMERA2_CHOICE, SensorMode, check_policy, choose_mode

PICAMERA2_MISSING = (
    "picamera2 is not installed: on Raspberry Pi OS run sudo apt install python3-picamera2 and make the "
    "venv with --system-site-packages (./run.sh does this)"
)
#: Focus when neither the setting nor the camera model gives one: 3 dioptres = 33 cm, a bench distance.
DEFAULT_LENS_POSITION = 3.0
#: libcamera's AfModeManual (af_algorithm.h: AfModeManual = 0, AfModeAuto, AfModeContinuous).
AF_MODE_MANUAL = 0
#: A SensorTimestamp further than this from time.monotonic() is not on that clock (s).
TIMESTAMP_TOLERANCE_S = 5.0
#: The lens counts as settled within this many dioptres of its target...
LENS_SETTLED = 0.05
#: ... and the source drops at most this many frames at open waiting for it (1 s at 30 fps).
LENS_SETTLE_FRAMES = 30
#: The preset for each sensor picamera2 names (camera_properties['Model']); the HQ camera's lens
#: is interchangeable: picam-hq-6mm is for the 6 mm lens only.
SENSOR_PRESETS = {"imx219": "picam-v2", "imx708": "picam-v3", "imx477": "picam-hq-6mm", "ov5647": "picam-v1"}


@dataclass(frozen=True)
class Picamera2Settings:
    """Resolution, sensor mode, focus and exposure of the Raspberry Pi camera."""

    width: int = setting(640, label="width", unit="px", minimum=64, maximum=4656)
    height: int = setting(480, label="height", unit="px", minimum=64, maximum=3496)
    exposure_us: int = setting(
        0,
        label="exposure",
        unit="us",
        minimum=0,
        maximum=10_000_000,
        help="fixed exposure time (0 = automatic)",
    )
    gain: float = setting(
        0.0, label="analogue gain", minimum=0.0, maximum=64.0, decimals=2, help="fixed gain (0 = automatic)"
    )
    lock_exposure: bool = setting(
        True,
        label="lock exposure",
        help="freeze automatic exposure and gain once settled, for steady brightness",
    )
    settle_frames: int = setting(
        SETTLE_FRAMES, label="settle frames", minimum=0, maximum=300, help="frames before the lock"
    )
    camera_num: int = setting(0, label="camera number", minimum=0, maximum=7)
    sensor_mode: str = setting(
        "full",
        label="sensor mode",
        help="full: the binned full-field-of-view mode for the output's aspect ratio; picamera2: "
        "picamera2's own choice by size (may be a cropped mode); or a mode's size WxH (qrfield camera list)",
    )
    lens_position: float = setting(
        -1.0,
        label="lens position",
        unit="dioptres",
        minimum=-1.0,
        maximum=32.0,
        decimals=2,
        help="manual focus of an autofocus camera: 1 / focus distance in m (0 = infinity); "
        f"-1 = the camera model's lens_position, else {DEFAULT_LENS_POSITION:g} (33 cm)",
    )


def import_picamera2() -> Any:
    """The ``Picamera2`` class; SourceError with the install hint where picamera2 is missing."""
    try:
        from picamera2 import Picamera2  # type: ignore[import-not-found]
    except ImportError as exc:
        raise SourceError(PICAMERA2_MISSING) from exc
    except Exception as exc:
        # Installed but broken, e.g. the OS's picamera2 (its simplejpeg built for numpy 1.x) under a
        # numpy 2 in the venv raises ValueError "numpy.dtype size changed": a source that cannot
        # open, so that auto moves on to the next camera instead of stopping the app.
        raise SourceError(
            f"picamera2 is installed but fails to import ({type(exc).__name__}: {exc}); "
            "if it mentions numpy, the OS's picamera2 needs numpy 1.x in the venv: pip install 'numpy<2'"
        ) from exc
    return Picamera2


@dataclass
class StreamInfo:
    """What the camera was asked for and what it delivers, with where each number came from."""

    sensor: str = ""
    sensor_resolution: tuple[int, int] | None = None
    modes: list[SensorMode] = field(default_factory=list)
    requested_mode: SensorMode | None = None
    why: str = ""
    mode: SensorMode | None = None
    out_size: tuple[int, int] = (0, 0)
    scaler_crop: tuple[int, int, int, int] | None = None
    crop_source: str = ""
    autofocus: bool = False
    lens_position: float | None = None
    lens_source: str = ""
    profile: CameraModel | None = None
    camera: CameraModel | None = None
    model_notes: list[str] = field(default_factory=list)
    clock: str = ""

    def lines(self) -> list[str]:
        """The report of ``qrfield camera check`` and the app's Camera tab, one fact per line."""
        out = [
            f"sensor: {self.sensor or 'unknown'}"
            + (
                f", full resolution {self.sensor_resolution[0]}x{self.sensor_resolution[1]} "
                "(picamera2 sensor_resolution)"
                if self.sensor_resolution
                else ""
            )
        ]
        if self.modes:
            out.append("sensor modes (picamera2 sensor_modes: size, fps, crop_limits):")
            out += [f"  {m.describe()}" for m in self.modes]
        asked = self.requested_mode.label if self.requested_mode else "none (picamera2 chooses)"
        out.append(f"mode asked for: {asked}: {self.why}")
        if self.mode is not None:
            out.append(f"mode chosen: {self.mode.describe()} (picamera2 camera_configuration()['sensor'])")
        w, h = self.out_size
        out.append(f"output: {w}x{h} (camera_configuration()['main']['size'])")
        if self.scaler_crop is not None:
            out.append(f"ScalerCrop: {format_crop(self.scaler_crop)} ({self.crop_source})")
        if self.autofocus:
            out.append(f"focus: manual (AfMode 0) at {self.lens_position:g} dioptres ({self.lens_source})")
        if self.profile is not None:
            p = self.profile
            where = f"sensor crop {format_crop(p.sensor_crop)}" if p.sensor_crop else "no sensor crop"
            out.append(f"profile: {p.name}, {p.width}x{p.height}, {where}")
        if self.camera is not None:
            out.append(f"camera model of the stream: {self.camera.summary()}")
            out += self.formula_lines()
        else:
            out.append("camera model of the stream: none (no camera model named)")
        if self.clock:
            out.append(f"frame time: {self.clock}")
        out += [f"note: {n}" for n in self.model_notes]
        return out

    def formula_lines(self) -> list[str]:
        """The docs/conventions.md formula with this stream's numbers (full-resolution f and c)."""
        p, cam, crop = self.profile, self.camera, self.scaler_crop
        if p is None or cam is None or crop is None or p.sensor_crop is None:
            return []
        # f and c in full-resolution pixels: the profile's, after any focus change.
        full_fx, full_fy = cam.fx * crop[2] / cam.width, cam.fy * crop[3] / cam.height
        full_cx = (cam.cx + 0.5) * crop[2] / cam.width - 0.5 + crop[0]
        full_cy = (cam.cy + 0.5) * crop[3] / cam.height - 0.5 + crop[1]
        own_fx = p.fx * p.sensor_crop[2] / p.width  # the profile's own, in full-resolution pixels
        focus = full_fx / own_fx
        lines = [
            f"  fx = f * out_w / crop_w = {full_fx:.3f} * {cam.width} / {crop[2]} = {cam.fx:.3f}",
            f"  fy = f * out_h / crop_h = {full_fy:.3f} * {cam.height} / {crop[3]} = {cam.fy:.3f}",
            f"  cx = (c - crop_x + 0.5) * out_w / crop_w - 0.5 = ({full_cx:.3f} - {crop[0]} + 0.5) * "
            f"{cam.width} / {crop[2]} - 0.5 = {cam.cx:.3f}",
            f"  cy = ({full_cy:.3f} - {crop[1]} + 0.5) * {cam.height} / {crop[3]} - 0.5 = {cam.cy:.3f}",
            f"  (f, c: the profile {p.name} in full-resolution pixels"
            + (f"; f = {own_fx:.3f} x {focus:.5f} for the focus" if abs(focus - 1) > 1e-9 else "")
            + '; docs/conventions.md, "Camera models follow the stream")',
        ]
        return lines


class Picamera2Source(FrameSource):
    """Frames from a Raspberry Pi camera module (BGR, as OpenCV expects).

    Args:
        settings: size, sensor mode, focus and exposure.
        profile: the camera model to map through the stream's sensor crop (a full-resolution
            profile such as picam-v2, or one that states its ``sensor_crop``); None = no model
            (:attr:`camera` stays None).

    Attributes:
        camera: after open, the camera model of the delivered frames (or None without a profile).
        stream: after open, what was asked and what is delivered (:class:`StreamInfo`).
    """

    name = "picamera2"

    def __init__(
        self, settings: Picamera2Settings | None = None, *, profile: CameraModel | None = None
    ) -> None:
        super().__init__()
        self.settings = validated(settings or Picamera2Settings())
        try:
            check_policy(self.settings.sensor_mode)
        except ValueError as exc:
            raise SourceError(str(exc)) from None
        self.profile = profile
        self.camera: CameraModel | None = None
        self.stream = StreamInfo()
        self._camera: Any = None
        self._locked = False
        self._first: tuple[np.ndarray, dict[str, Any]] | None = None
        self._clock_noted = False

    @property
    def description(self) -> str:
        s, info = self.settings, self.stream
        text = f"Raspberry Pi camera {s.camera_num} (picamera2, {s.width}x{s.height})"
        if info.mode is not None:
            sensor = f"{info.sensor} " if info.sensor else ""
            w, h = info.out_size
            text = (
                f"Raspberry Pi camera {s.camera_num} {sensor}(picamera2, {w}x{h} "
                f"from sensor mode {info.mode.label}"
                + (f", ScalerCrop {format_crop(info.scaler_crop)}" if info.scaler_crop else "")
                + ")"
            )
        return text

    def _picamera2_class(self) -> Any:
        return import_picamera2()

    # ---------------------------------------------------------------- open
    def _open_impl(self) -> None:
        Picamera2 = self._picamera2_class()
        s = self.settings
        try:
            camera = Picamera2(s.camera_num)
        except Exception as exc:  # picamera2 raises IndexError/RuntimeError when no camera is attached
            raise SourceError(f"picamera2: no camera {s.camera_num} ({exc})") from exc
        self._camera = camera
        try:
            self.stream = self._configure(camera)
            self._start(camera)
        except SourceError:
            self._close_impl()
            raise
        except Exception as exc:
            self._close_impl()
            raise SourceError(
                f"picamera2: cannot start camera {s.camera_num} at {s.width}x{s.height} ({exc})"
            ) from exc

    def _configure(self, camera: Any) -> StreamInfo:
        """Choose the sensor mode, configure, and set focus and exposure (before start)."""
        s = self.settings
        info = StreamInfo(sensor=str(camera.camera_properties.get("Model", "")), profile=self.profile)
        resolution = getattr(camera, "sensor_resolution", None)
        info.sensor_resolution = tuple(resolution) if resolution else None  # type: ignore[assignment]
        # sensor_modes configures the camera once per mode: read it before our own configure().
        info.modes = [SensorMode.from_picamera2(m) for m in camera.sensor_modes if "crop_limits" in m]
        out = (s.width, s.height)
        sensor: dict[str, Any] = {}
        if info.modes:
            try:
                info.requested_mode, info.why = choose_mode(info.modes, out, s.sensor_mode)
            except ValueError as exc:
                raise SourceError(f"picamera2: {exc}") from None
            if info.requested_mode is not None:
                mode = info.requested_mode
                sensor = {"output_size": mode.size, "bit_depth": mode.bit_depth}
        else:
            info.why = "the camera lists no raw sensor modes (not a Raspberry Pi camera?)"
        # picamera2's "RGB888" is B, G, R in memory: the order OpenCV uses.
        kwargs: dict[str, Any] = {"main": {"size": out, "format": "RGB888"}}
        if sensor:
            kwargs["sensor"] = sensor
        camera.configure(camera.create_video_configuration(**kwargs))
        config = camera.camera_configuration()
        info.out_size = tuple(int(v) for v in config["main"]["size"])  # type: ignore[assignment]
        chosen = config.get("sensor") or {}
        if chosen.get("output_size") is not None:
            size = tuple(int(v) for v in chosen["output_size"])
            depth = chosen.get("bit_depth")
            info.mode = next(
                (m for m in info.modes if m.size == size and (depth is None or m.bit_depth == depth)), None
            )
        if s.sensor_mode != PICAMERA2_CHOICE and info.requested_mode and info.mode != info.requested_mode:
            raise SourceError(
                f"picamera2 configured sensor mode {info.mode.label if info.mode else '?'} instead of "
                f"{info.requested_mode.label}"
            )
        controls: dict[str, Any] = {}
        if s.exposure_us > 0:
            controls.update(AeEnable=False, ExposureTime=int(s.exposure_us))
        if s.gain > 0:
            controls.update(AeEnable=False, AnalogueGain=float(s.gain))
        self._locked = bool(controls) or not s.lock_exposure
        if "AfMode" in camera.camera_controls:
            info.autofocus = True
            info.lens_position, info.lens_source = self._lens_position()
            limits = camera.camera_controls.get("LensPosition")
            if limits and not limits[0] <= info.lens_position <= limits[1]:
                raise SourceError(
                    f"picamera2: lens position {info.lens_position:g} dioptres ({info.lens_source}) is "
                    f"outside this camera's {limits[0]:g}..{limits[1]:g} dioptres"
                )
            controls.update(AfMode=AF_MODE_MANUAL, LensPosition=float(info.lens_position))
        if controls:
            camera.set_controls(controls)
        return info

    def _lens_position(self) -> tuple[float, str]:
        s, profile = self.settings, self.profile
        if s.lens_position >= 0:
            return s.lens_position, "lens_position setting"
        if profile is not None and profile.lens_position is not None:
            return profile.lens_position, f"the lens_position camera model {profile.name} was calibrated at"
        return DEFAULT_LENS_POSITION, "default: 33 cm; the camera model states no lens position"

    def _start(self, camera: Any) -> None:
        """Start, take the first frame (once the lens has settled), and derive the stream's model."""
        camera.start()
        image, metadata = self._capture()
        if self.stream.autofocus:
            image, metadata = self._settle_lens(image, metadata)
        self._first = (image, metadata)
        info = self.stream
        crop = metadata.get("ScalerCrop")
        if crop is not None:
            info.scaler_crop, info.crop_source = tuple(int(v) for v in crop), "the first frame's metadata"
        else:
            default = camera.camera_controls.get("ScalerCrop")
            if default is not None and default[2] is not None:
                info.scaler_crop = tuple(int(v) for v in default[2])
                info.crop_source = "camera_controls['ScalerCrop'] default (no ScalerCrop in the metadata)"
        height, width = image.shape[:2]
        if (width, height) != info.out_size:
            raise SourceError(
                f"picamera2 delivers {width}x{height} frames, configured for "
                f"{info.out_size[0]}x{info.out_size[1]}"
            )
        self.use_profile(self.profile)

    def use_profile(self, profile: CameraModel | None) -> CameraModel | None:
        """Derive :attr:`camera` from ``profile`` for the open stream (its mode, crop and focus);
        the model and how it was made go to ``notes``. SourceError when it cannot be mapped."""
        info = self.stream
        self.profile, info.profile, info.model_notes = profile, profile, []
        self.camera = info.camera = self._stream_camera(info)
        if self.camera is not None:
            self.notes.append(f"camera model: {self.camera.summary()} ({self.camera.notes.split('. ')[0]})")
        self.notes.extend(info.model_notes)
        return self.camera

    def _stream_camera(self, info: StreamInfo) -> CameraModel | None:
        """The profile mapped to this stream (mode, crop, lens); SourceError when it cannot be."""
        profile = self.profile
        if profile is None:
            return None
        if (
            profile.sensor_resolution is not None
            and info.sensor_resolution is not None
            and tuple(profile.sensor_resolution) != tuple(info.sensor_resolution)
        ):
            preset = SENSOR_PRESETS.get(info.sensor, "")
            raise SourceError(
                f"camera model {profile.name!r} describes a {profile.sensor_resolution[0]}x"
                f"{profile.sensor_resolution[1]} sensor, but camera {self.settings.camera_num}'s sensor, "
                f"the {info.sensor}, is {info.sensor_resolution[0]}x{info.sensor_resolution[1]}"
                + (f": name its profile ({preset})" if preset else "")
            )
        model = profile
        if info.autofocus and info.lens_position is not None:
            try:
                model, text = model.at_lens_position(info.lens_position)
            except CameraModelError as exc:
                raise SourceError(str(exc)) from None
            unknown = profile.lens_position is None and not profile.focal_length_mm
            differs = profile.lens_position is not None and profile.lens_position != info.lens_position
            info.model_notes.append(f"warning: {text}" if unknown or differs else text)
        if info.scaler_crop is None:
            if model.size == info.out_size and model.sensor_crop is None:
                info.model_notes.append(
                    f"the camera reports no ScalerCrop: {model.name} used as it is (it has the frames' size)"
                )
                return model
            raise SourceError(
                f"the camera reports no ScalerCrop, so camera model {model.name!r} "
                f"({model.width}x{model.height}) cannot be mapped to its {info.out_size[0]}x"
                f"{info.out_size[1]} frames: name a model of exactly this stream"
            )
        try:
            return model.through_crop(
                info.scaler_crop, info.out_size, sensor_mode=info.mode.label if info.mode else ""
            )
        except CameraModelError as exc:
            raise SourceError(f"picamera2: {exc}") from None

    def _settle_lens(self, image: np.ndarray, metadata: dict[str, Any]) -> tuple[np.ndarray, dict[str, Any]]:
        """Drop frames until the lens reports its position (it moves a step per frame), at most
        LENS_SETTLE_FRAMES: frames taken while it moves have another focal length."""
        target = self.stream.lens_position
        for dropped in range(LENS_SETTLE_FRAMES + 1):
            reported = metadata.get("LensPosition")
            if reported is None or target is None:
                return image, metadata
            if abs(float(reported) - target) <= LENS_SETTLED:
                self.notes.append(
                    f"focus: manual, lens at {float(reported):.2f} dioptres"
                    + (f" ({dropped} frame(s) dropped while it moved)" if dropped else "")
                )
                return image, metadata
            if dropped < LENS_SETTLE_FRAMES:
                image, metadata = self._capture()
        self.notes.append(
            f"warning: the lens reports {float(metadata['LensPosition']):.2f} dioptres after "
            f"{LENS_SETTLE_FRAMES} frames, not the {target:g} set"
        )
        return image, metadata

    # ---------------------------------------------------------------- frames
    def _capture(self) -> tuple[np.ndarray, dict[str, Any]]:
        """One frame and its own metadata (one request, released at once)."""
        request = self._camera.capture_request()
        try:
            image = request.make_array("main")
            metadata = request.get_metadata()
        finally:
            request.release()
        return image, metadata

    def _read_impl(self, index: int) -> Frame:
        try:
            if self._first is not None:
                (image, metadata), self._first = self._first, None
            else:
                image, metadata = self._capture()
        except Exception as exc:
            raise SourceError(f"picamera2: capture failed ({exc})") from exc
        crop = metadata.get("ScalerCrop")
        known = self.stream.scaler_crop
        if crop is not None and known is not None and tuple(crop) != known:
            raise SourceError(
                f"picamera2: the ScalerCrop changed from {format_crop(known)} to "
                f"{format_crop(crop)} (a digital zoom?): the camera model no longer fits the frames; reopen"
            )
        t = self._frame_time(metadata)
        image = np.ascontiguousarray(image[..., :3]) if image.ndim == 3 else image
        if not self._locked and index + 1 >= self.settings.settle_frames:
            self._lock_exposure(metadata)
        return Frame(
            image.astype(np.uint8, copy=False),
            t,
            index,
            truth=self._truth(metadata),
            label=f"{self.name} #{index}",
        )

    def _truth(self, metadata: dict[str, Any]) -> Pose | None:
        """A real camera knows no true pose."""
        return None

    def _frame_time(self, metadata: dict[str, Any]) -> float:
        """The frame's SensorTimestamp (end of readout, ns, CLOCK_MONOTONIC) in s; now if absent."""
        now = time.monotonic()
        stamp = metadata.get("SensorTimestamp")
        if isinstance(stamp, (int, float)) and stamp > 0:
            t = float(stamp) / 1e9
            if -0.05 <= now - t <= TIMESTAMP_TOLERANCE_S:
                self.stream.clock = "the frame's SensorTimestamp (end of readout, CLOCK_MONOTONIC)"
                return t
            if not self._clock_noted:
                self._clock_noted = True
                self.notes.append(
                    f"SensorTimestamp is {now - t:+.1f} s from the monotonic clock: frame times are "
                    "delivery times instead"
                )
        self.stream.clock = "delivery time (time.monotonic; no usable SensorTimestamp)"
        return now

    def _lock_exposure(self, metadata: dict[str, Any]) -> None:
        """Fix exposure time and gain at the automatic exposure's values of this frame."""
        self._locked = True
        try:
            exposure, gain = metadata["ExposureTime"], metadata["AnalogueGain"]
            self._camera.set_controls(
                {"AeEnable": False, "ExposureTime": int(exposure), "AnalogueGain": float(gain)}
            )
            self.notes.append(f"exposure locked at {int(exposure)} us, gain {float(gain):.2f}")
        except Exception as exc:  # a failed lock is worth a note, not a stopped camera
            self.notes.append(f"could not lock exposure ({exc})")

    def _close_impl(self) -> None:
        _close_quietly(self._camera)
        self._camera = None
        self._first = None


class SimulatedPicamera2Source(Picamera2Source):
    """The picamera2 source on the stand-in (:mod:`qrfield.sources.picamera_sim`): SIMULATED frames.

    Everything above runs unchanged; only the ``Picamera2`` class is the stand-in's, which renders
    the card at ``scene``'s pose through the sensor mode and crop it was configured with.
    """

    simulated = True

    def __init__(
        self,
        settings: Picamera2Settings | None = None,
        *,
        profile: CameraModel | None = None,
        sensor: str = "imx219",
        scene: Any = None,
        side_mm: float = 50.0,
    ) -> None:
        super().__init__(settings, profile=profile)
        from qrfield.sources.picamera_sim import SENSORS, picamera2_class

        if sensor not in SENSORS:
            raise SourceError(f"picamera2-sim: no simulated sensor {sensor!r}; known: {', '.join(SENSORS)}")
        self.sensor = sensor
        self.name = f"picamera2-sim:{sensor}"
        self.backend = picamera2_class(sensor, scene, side_mm)

    @property
    def description(self) -> str:
        return f"SIMULATED {super().description} [picamera2 stand-in, {self.sensor}]"

    def _picamera2_class(self) -> Any:
        return self.backend

    def _truth(self, metadata: dict[str, Any]) -> Pose | None:
        truth = metadata.get("SimTruePose")  # the stand-in's own key: the pose it rendered
        return truth if isinstance(truth, Pose) else None


def _close_quietly(camera: Any) -> None:
    if camera is None:
        return
    for method in ("stop", "close"):
        with contextlib.suppress(Exception):  # closing a failed camera must not hide the first error
            getattr(camera, method)()
