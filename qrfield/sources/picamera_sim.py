"""A stand-in for picamera2's ``Picamera2`` class: a SIMULATED Raspberry Pi camera.

The tests (the contract test of sources) and ``--source picamera2-sim[:SENSOR]`` use it; it is never
a real camera: the source built on it says SIMULATED in its description, is ``simulated``, and its
frames carry their true pose. It renders the QR card with :func:`qrfield.render.render_view` through
the camera model of the stream it delivers, which it derives itself from the full-resolution
datasheet profile (``calib/picam-v2.json`` ...), the sensor mode and the ISP's crop: its truth is the
full-resolution profile, independent of :meth:`qrfield.camera.CameraModel.through_crop` (the code
under test).

Where each behaviour comes from (read, not guessed):

- P2 = raspberrypi/picamera2, ``picamera2/picamera2.py`` at 3e6dff0 (2026-05-12);
  PC = ``picamera2/controls.py``; LC = raspberrypi/libcamera: ``pipeline/rpi/common/pipeline_base.cpp``,
  ``pipeline/rpi/vc4/vc4.cpp``, ``pipeline/rpi/pisp/pisp.cpp``, ``libcamera/geometry.cpp``,
  ``ipa/rpi/controller/rpi/af.cpp``, ``ipa/rpi/pisp/data/imx708.json``.
- Sensor mode tables: IMX219 from raspberrypi/linux PR 5498 (``libcamera-hello --list-cameras``,
  10-bit and 8-bit modes with fps and crop); IMX708 from ``rpicam-hello --list-cameras`` output as
  published in several READMEs, with the 1536x864 crop (768, 432)/3072x1728 corrected by
  raspberrypi/linux PR 5312; IMX477 crops from raspberrypi/linux PR 6208, fps from rpicam-apps PR 312.
  picamera2 issue 683 shows the same IMX219 table as ``Picamera2.sensor_modes`` dicts.
- Camera number: ``Picamera2(n)`` indexes ``global_camera_info()`` (P2 ``__init__``): IndexError when
  there is no camera n.
- Native mode / ``sensor_resolution`` / ``sensor_format``: the largest mode, ties to the deeper bit
  depth (P2 ``_select_native_mode``).
- ``sensor_modes``: reconfigures the camera for each mode when first read (P2 ``sensor_modes``), so
  it fails while the camera runs ("Camera must be stopped before configuring", P2 ``configure_``).
- ``create_video_configuration``: its defaults (main XBGR8888 at 1280x720, raw of the main's size,
  FrameDurationLimits (33333, 33333)), the key check of ``_make_initial_stream_config``, even
  sizes (``align_stream``).
- ``configure``: the sensor keys allowed are bit_depth and output_size (P2 ``check_camera_config``);
  the mode is chosen by P2 ``_make_libcamera_config``: the size to match is ``sensor.output_size``,
  else ``raw.size``, else ``main.size``; each raw mode is scored by ``score_mode`` (copied below) and
  the lowest score wins (the first on ties, Python's ``min``). After configure,
  ``camera_configuration()['sensor']`` holds the chosen mode's bit_depth and output_size
  (P2 ``_update_camera_config``).
- The ISP's crop: the mode's image is cropped, centred, to the output's aspect ratio
  (LC vc4.cpp / pisp.cpp ``platformConfigure``: ``size = sensorSize.boundedToAspectRatio(output)``,
  ``crop = size.centeredTo(center)``), and reported in full-resolution pixels (LC ``scaleIspCrop``:
  scaled by analogCrop.size / outputSize, then moved by analogCrop's top-left; the mode's
  analogue crop is its ``crop_limits``), as ``ScalerCrop`` in every frame's metadata
  (LC ``fillRequestMetadata``) and as the default of ``camera_controls['ScalerCrop']``, whose
  maximum is the analogue crop (LC ``configure``). Integer arithmetic as LC geometry.cpp.
- Setting ``ScalerCrop`` (digital zoom): LC ``applyScalerCrop`` (minimum 32x32 ISP pixels, as pisp).
- Controls: a name not in ``camera_controls`` raises RuntimeError "Control X is not advertised by
  libcamera" (PC ``__setattr__``); ``controls.make_dict()`` lists what was set (PC ``make_dict``).
- Autofocus (IMX708 only): ``AfMode`` (0 Manual, 1 Auto, 2 Continuous; LC af_algorithm.h) and
  ``LensPosition`` in dioptres. The algorithm starts in Manual (af.cpp ``mode_``); ``LensPosition``
  moves the lens only in Manual mode and is clamped to the map's domain 0..15 (af.cpp
  ``setLensPosition``, ``getLensLimits``; imx708.json ``map`` [0.0, 445, 15.0, 925]); the default
  is 1.0 (imx708.json ranges.normal.default); the lens slews at most 1.5 dioptres per frame
  (imx708.json speeds.normal.max_slew); metadata reports ``LensPosition`` and ``AfState``.
- Metadata: ``SensorTimestamp`` in ns on the clock of ``time.monotonic_ns()`` (picamera2's
  examples/timestamp_capture.py compares the two), ``ExposureTime``, ``AnalogueGain``,
  ``FrameDuration``, ``ScalerCrop``. ``capture_request()`` returns a request with
  ``make_array(name)``, ``get_metadata()`` and ``release()``; ``capture_array`` and
  ``capture_metadata`` each take a new frame (P2 ``capture_metadata_`` pops a completed request).
- Frame rate: the frame duration is FrameDurationLimits' minimum, but never shorter than the
  mode allows (its fps).
- Optics of the simulation (physics, not picamera2): the focal length grows as the lens focuses
  closer (thin lens, v = 1 / (1/f - P/1000) mm), and the card blurs with the defocus (thin-lens
  blur circle (f^2 / N) * |P - 1000/z| / 1000 mm on the sensor; IMX708 f = 4.74 mm, f/1.8).

Not modelled: libcamera's stride and width alignment (sizes that are multiples of 64 are
unaffected), the preview and still configurations, YUV and raw streams, lores, brightness
following exposure, the sensor's flips.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from qrfield.camera import CameraModel, preset_dir
from qrfield.geometry import Pose
from qrfield.render import RenderError, render_view
from qrfield.sources.virtual import VirtualBenchSettings, pose_at

#: libcamera's AfMode values (af_algorithm.h): AfModeManual, AfModeAuto, AfModeContinuous.
AF_MANUAL, AF_AUTO, AF_CONTINUOUS = 0, 1, 2


@dataclass(frozen=True)
class SimMode:
    """One sensor mode, as ``Picamera2.sensor_modes`` lists it."""

    format: str
    bit_depth: int
    size: tuple[int, int]
    fps: float
    crop: tuple[int, int, int, int]  # crop_limits: the analogue crop, full-resolution pixels

    def as_picamera2(self) -> dict[str, Any]:
        return {
            "format": self.format,
            "unpacked": self.format.replace("_CSI2P", ""),
            "bit_depth": self.bit_depth,
            "size": self.size,
            "fps": self.fps,
            "crop_limits": self.crop,
            "exposure_limits": (75, 11766829, None),
        }


@dataclass(frozen=True)
class SimSensor:
    """A camera module: its sensor modes, its full-resolution profile and its lens."""

    model: str
    camera_id: str
    profile: str  # preset in calib/: the truth, at full resolution
    modes: tuple[SimMode, ...]
    f_number: float
    autofocus: bool = False
    lens_limits: tuple[float, float, float] = (0.0, 15.0, 1.0)  # min, max, default (af.cpp, imx708.json)
    max_slew: float = 1.5  # dioptres per frame (imx708.json speeds.normal.max_slew)


def _modes(
    fmt: str, depth: int, rows: list[tuple[int, int, float, tuple[int, int, int, int]]]
) -> list[SimMode]:
    return [SimMode(fmt, depth, (w, h), fps, crop) for w, h, fps, crop in rows]


_IMX219_CROPS = {
    (640, 480): (1000, 752, 1280, 960),
    (1640, 1232): (0, 0, 3280, 2464),
    (1920, 1080): (680, 692, 1920, 1080),
    (3280, 2464): (0, 0, 3280, 2464),
}
SENSORS: dict[str, SimSensor] = {
    # raspberrypi/linux PR 5498, libcamera-hello --list-cameras.
    "imx219": SimSensor(
        model="imx219",
        camera_id="/base/soc/i2c0mux/i2c@1/imx219@10",
        profile="picam-v2",
        modes=tuple(
            _modes(
                "SRGGB10_CSI2P",
                10,
                [
                    (640, 480, 206.65, _IMX219_CROPS[(640, 480)]),
                    (1640, 1232, 41.85, _IMX219_CROPS[(1640, 1232)]),
                    (1920, 1080, 47.57, _IMX219_CROPS[(1920, 1080)]),
                    (3280, 2464, 21.19, _IMX219_CROPS[(3280, 2464)]),
                ],
            )
            + _modes(
                "SRGGB8",
                8,
                [
                    (640, 480, 206.65, _IMX219_CROPS[(640, 480)]),
                    (1640, 1232, 83.70, _IMX219_CROPS[(1640, 1232)]),
                    (1920, 1080, 47.57, _IMX219_CROPS[(1920, 1080)]),
                    (3280, 2464, 21.19, _IMX219_CROPS[(3280, 2464)]),
                ],
            )
        ),
        f_number=2.0,
    ),
    # rpicam-hello --list-cameras; 1536x864 crop per raspberrypi/linux PR 5312.
    "imx708": SimSensor(
        model="imx708",
        camera_id="/base/axi/pcie@120000/rp1/i2c@88000/imx708@1a",
        profile="picam-v3",
        modes=tuple(
            _modes(
                "SRGGB10_CSI2P",
                10,
                [
                    (1536, 864, 120.13, (768, 432, 3072, 1728)),
                    (2304, 1296, 56.03, (0, 0, 4608, 2592)),
                    (4608, 2592, 14.35, (0, 0, 4608, 2592)),
                ],
            )
        ),
        f_number=1.8,
        autofocus=True,
    ),
    # raspberrypi/linux PR 6208 (crops), rpicam-apps PR 312 (fps).
    "imx477": SimSensor(
        model="imx477",
        camera_id="/base/soc/i2c0mux/i2c@1/imx477@1a",
        profile="picam-hq-6mm",
        modes=tuple(
            _modes("SRGGB10_CSI2P", 10, [(1332, 990, 120.0, (696, 528, 2664, 1980))])
            + _modes(
                "SRGGB12_CSI2P",
                12,
                [
                    (2028, 1080, 50.0, (0, 440, 4056, 2160)),
                    (2028, 1520, 40.0, (0, 0, 4056, 3040)),
                    (4056, 3040, 10.0, (0, 0, 4056, 3040)),
                ],
            )
        ),
        f_number=2.8,
    ),
}


# ---------------------------------------------------------------------- libcamera geometry (LC geometry.cpp)


def bounded_to_aspect_ratio(size: tuple[int, int], ratio: tuple[int, int]) -> tuple[int, int]:
    """libcamera ``Size::boundedToAspectRatio``: shrink ``size`` to the aspect ratio of ``ratio``."""
    r1, r2 = size[0] * ratio[1], ratio[0] * size[1]
    if r1 > r2:
        return (r2 // ratio[1], size[1])
    return (size[0], r1 // ratio[0])


def centered_to(size: tuple[int, int], center: tuple[int, int]) -> tuple[int, int, int, int]:
    """libcamera ``Size::centeredTo``."""
    return (center[0] - size[0] // 2, center[1] - size[1] // 2, size[0], size[1])


def rect_center(rect: tuple[int, int, int, int]) -> tuple[int, int]:
    """libcamera ``Rectangle::center``."""
    return (rect[0] + rect[2] // 2, rect[1] + rect[3] // 2)


def scaled_by(rect: tuple[int, int, int, int], num: tuple[int, int], den: tuple[int, int]) -> tuple[int, ...]:
    """libcamera ``Rectangle::scaledBy`` (integer division, as its int64 arithmetic)."""
    x, y, w, h = rect
    return (x * num[0] // den[0], y * num[1] // den[1], w * num[0] // den[0], h * num[1] // den[1])


def score_mode(mode: SimMode, bit_depth: int, output_size: tuple[int, int]) -> float:
    """picamera2's ``score_mode`` (inside P2 ``_make_libcamera_config``), unchanged."""
    mode_bit_depth = mode.bit_depth
    mode_output_size = mode.size
    ar = output_size[0] / output_size[1]
    mode_ar = mode_output_size[0] / mode_output_size[1]

    def score_format(desired: float, actual: float) -> float:
        score = desired - actual
        return -score / 4 if score < 0 else score * 2

    score = score_format(output_size[0], mode_output_size[0])
    score += score_format(output_size[1], mode_output_size[1])
    score += 1500 * score_format(ar, mode_ar)
    score += 500 * abs(bit_depth - mode_bit_depth)
    return score


def isp_scaler_crop(mode: SimMode, out_size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The ScalerCrop (full-resolution pixels) of an output of ``out_size`` from ``mode`` (LC)."""
    size = bounded_to_aspect_ratio(mode.size, out_size)
    isp_crop = centered_to(size, rect_center((0, 0, *mode.size)))
    native = scaled_by(isp_crop, mode.crop[2:], mode.size)
    return (native[0] + mode.crop[0], native[1] + mode.crop[1], native[2], native[3])


# ---------------------------------------------------------------------- the stream's truth


def stream_truth(
    full: CameraModel, crop: tuple[int, int, int, int], out_size: tuple[int, int]
) -> CameraModel:
    """The model of the stream, from the full-resolution ``full`` by the ISP's resampling.

    The ISP scales the crop's area onto the output's area, pixel edge to pixel edge: output pixel
    i samples the sensor at x = crop_x + (i + 0.5) * crop_w / out_w - 0.5. Inverted, a sensor
    coordinate x shows at i = s x + (0.5 - crop_x) s - 0.5 with s = out_w / crop_w; as a matrix A
    acting on homogeneous pixels, K_stream = A K_full.
    """
    sx, sy = out_size[0] / crop[2], out_size[1] / crop[3]
    A = np.array([[sx, 0.0, (0.5 - crop[0]) * sx - 0.5], [0.0, sy, (0.5 - crop[1]) * sy - 0.5], [0, 0, 1]])
    K = A @ full.K
    return CameraModel(
        fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], width=out_size[0], height=out_size[1], dist=full.dist
    )


def thin_lens_image_distance(focal_mm: float, dioptres: float) -> float:
    """Lens-to-sensor distance (mm) focused at 1/dioptres m: 1 / (1/f - P/1000)."""
    return 1.0 / (1.0 / focal_mm - dioptres / 1000.0)


# ---------------------------------------------------------------------- the stand-in


class SimControls:
    """picamera2's ``Controls`` (PC): set_controls checks the names; make_dict lists what was set."""

    def __init__(self, camera: SimPicamera2) -> None:
        self._camera = camera
        self._values: dict[str, Any] = {}

    def set_controls(self, controls: dict[str, Any]) -> None:
        advertised = self._camera.camera_controls
        for name in controls:
            if name not in advertised:
                raise RuntimeError(f"Control {name} is not advertised by libcamera")
        self._values.update(controls)

    def make_dict(self) -> dict[str, Any]:
        return dict(self._values)


class SimRequest:
    """A completed request (picamera2's ``CompletedRequest``): arrays, metadata, release()."""

    def __init__(self, camera: SimPicamera2, image: np.ndarray, metadata: dict[str, Any]) -> None:
        self._camera = camera
        self._image = image
        self._metadata = metadata
        self.released = False

    def make_array(self, name: str = "main") -> np.ndarray:
        if name != "main":
            raise RuntimeError(f"Stream {name!r} is not defined")
        return self._image.copy()

    def get_metadata(self) -> dict[str, Any]:
        return dict(self._metadata)

    def release(self) -> None:
        if not self.released:
            self.released = True
            self._camera._held -= 1


class SimPicamera2:
    """Stands in for ``picamera2.Picamera2`` (see the module docstring for each behaviour's source).

    Use :func:`picamera2_class` to get a class bound to a sensor and a scene.
    """

    SENSOR: ClassVar[SimSensor] = SENSORS["imx219"]
    SCENE: ClassVar[VirtualBenchSettings] = VirtualBenchSettings(fps=0.0)
    SIDE_MM: ClassVar[float] = 50.0
    #: added to SensorTimestamp (a clock other than CLOCK_MONOTONIC, e.g. CLOCK_BOOTTIME after a suspend)
    CLOCK_OFFSET_NS: ClassVar[int] = 0
    #: every instance made, newest last (tests look at what the source asked of the camera)
    instances: ClassVar[list[SimPicamera2]] = []

    @classmethod
    def global_camera_info(cls) -> list[dict[str, Any]]:
        return [
            {"Model": cls.SENSOR.model, "Location": 2, "Rotation": 0, "Id": cls.SENSOR.camera_id, "Num": 0}
        ]

    def __init__(self, camera_num: int = 0, tuning: Any = None) -> None:
        _ = self.global_camera_info()[camera_num]  # IndexError when there is no such camera, as picamera2
        sensor = self.SENSOR
        self.camera_num = camera_num
        self._raw_modes = list(sensor.modes)
        native = self._raw_modes[0]
        for mode in self._raw_modes[1:]:  # P2 _select_native_mode
            area, best = mode.size[0] * mode.size[1], native.size[0] * native.size[1]
            if area > best or (area == best and mode.bit_depth > native.bit_depth):
                native = mode
        self._native = native
        self.sensor_resolution = native.size
        self.sensor_format = native.format
        self.camera_properties = {
            "Model": sensor.model,
            "ColorFilterArrangement": 0,
            "Location": 2,
            "Rotation": 0,
        }
        self.full_profile = CameraModel.load(preset_dir() / f"{sensor.profile}.json")
        if self.full_profile.size != native.size:
            raise RuntimeError(f"stand-in: {sensor.profile} is not the {native.size} full-resolution profile")
        self.controls = SimControls(self)
        self.camera_config: dict[str, Any] | None = None
        self.mode: SimMode = native
        self.scaler_crop = native.crop
        self.started = False
        self.closed = False
        self._modes_read = False
        self._held = 0
        self._frame_index = 0
        self._t0 = 0.0
        self._next_ns = 0
        self._lens = sensor.lens_limits[2]
        self._lock = threading.Lock()
        type(self).instances.append(self)

    # ---------------------------------------------------------------- properties
    @property
    def camera_controls(self) -> dict[str, tuple[Any, Any, Any]]:
        mode = self.mode
        controls: dict[str, tuple[Any, Any, Any]] = {
            "AeEnable": (False, True, None),
            "ExposureTime": (75, 11766829, None),
            "AnalogueGain": (1.0, 10.666667, None),
            "FrameDurationLimits": (int(1e6 / mode.fps), 120000000, None),
            "NoiseReductionMode": (0, 4, 0),
            "ScalerCrop": ((0, 0, 32, 32), mode.crop, self.scaler_crop),
        }
        if self.SENSOR.autofocus:
            lo, hi, default = self.SENSOR.lens_limits
            controls.update(
                AfMode=(AF_MANUAL, AF_CONTINUOUS, AF_MANUAL),
                AfTrigger=(0, 1, 0),
                AfRange=(0, 2, 0),
                AfSpeed=(0, 1, 0),
                LensPosition=(lo, hi, default),
            )
        return controls

    @property
    def sensor_modes(self) -> list[dict[str, Any]]:
        if not self._modes_read:
            if self.started:
                raise RuntimeError("Camera must be stopped before configuring")
            self._modes_read = True  # picamera2 configures the camera once per mode here
        return [mode.as_picamera2() for mode in self._raw_modes]

    # ---------------------------------------------------------------- configuration
    def create_video_configuration(
        self,
        main: dict[str, Any] | None = None,
        lores: dict[str, Any] | None = None,
        raw: dict[str, Any] | None = None,
        controls: dict[str, Any] | None = None,
        sensor: dict[str, Any] | None = None,
        buffer_count: int = 6,
        **kwargs: Any,
    ) -> dict[str, Any]:
        return self._make_config(main, raw, controls, sensor, buffer_count, kwargs)

    def _make_config(
        self,
        main: dict[str, Any] | None,
        raw: dict[str, Any] | None,
        controls: dict[str, Any] | None,
        sensor: dict[str, Any] | None,
        buffer_count: int,
        extra: dict[str, Any],
    ) -> dict[str, Any]:
        default_size, durations, use_case = (1280, 720), (33333, 33333), "video"
        unknown = set(extra) - {"transform", "colour_space", "display", "encode", "queue", "use_case"}
        if unknown:
            raise TypeError(f"unexpected keyword argument(s) {sorted(unknown)}")
        stream = {"format": "XBGR8888", "size": default_size, "preserve_ar": True}
        for key, value in (main or {}).items():
            if key not in ("format", "size", "stride", "preserve_ar"):
                raise ValueError(
                    f"Bad key {key!r}: valid stream configuration keys are "
                    "('format', 'size', 'stride', 'preserve_ar')"
                )
            stream[key] = value
        width, height = stream["size"]
        stream["size"] = (width - width % 2, height - height % 2)  # align_stream(optimal=False)
        raw_stream = {"format": self.sensor_format, "size": stream["size"], **(raw or {})}
        return {
            "use_case": use_case,
            "buffer_count": buffer_count,
            "main": stream,
            "lores": None,
            "raw": raw_stream,
            "controls": {"NoiseReductionMode": 1, "FrameDurationLimits": durations} | dict(controls or {}),
            "sensor": dict(sensor) if sensor is not None else {},
        }

    def configure(self, camera_config: dict[str, Any]) -> None:
        if self.started:
            raise RuntimeError("Camera must be stopped before configuring")
        config = {key: (dict(v) if isinstance(v, dict) else v) for key, v in camera_config.items()}
        sensor = config.get("sensor") or {}
        bad = set(sensor) - {"bit_depth", "output_size"}
        if bad:
            raise RuntimeError(f"Unexpected keys {bad} in sensor configuration")
        main = config["main"]
        if main.get("format") not in ("RGB888", "BGR888", "XRGB8888", "XBGR8888"):
            raise RuntimeError(f"stand-in: format {main.get('format')!r} is not modelled")
        size = main["size"]
        if not (isinstance(size, tuple) and len(size) == 2):
            raise RuntimeError("size in main stream should be (width, height)")
        if size[0] % 2 or size[1] % 2:
            raise RuntimeError("width and height should be even")
        raw = config.get("raw")
        if sensor.get("bit_depth") is not None:
            bit_depth = int(sensor["bit_depth"])
        else:
            fmt = raw["format"] if raw is not None and "format" in raw else self.sensor_format
            bit_depth = next(m.bit_depth for m in self._raw_modes if m.format == fmt)
        if sensor.get("output_size") is not None:
            output_size = tuple(sensor["output_size"])
        elif raw is not None and "size" in raw:
            output_size = tuple(raw["size"])
        else:
            output_size = tuple(size)
        mode = min(self._raw_modes, key=lambda m: score_mode(m, bit_depth, output_size))  # type: ignore[arg-type]
        config["sensor"] = {"bit_depth": mode.bit_depth, "output_size": mode.size}
        self.controls = SimControls(self)
        self.mode = mode
        self.scaler_crop = isp_scaler_crop(mode, size)
        self.camera_config = config
        self.controls.set_controls(config.get("controls") or {})

    def camera_configuration(self) -> dict[str, Any]:
        return self.camera_config or {}

    def set_controls(self, controls: dict[str, Any]) -> None:
        self.controls.set_controls(controls)
        crop = controls.get("ScalerCrop")
        if crop is not None:
            self._apply_scaler_crop(tuple(int(v) for v in crop))

    def _apply_scaler_crop(self, native: tuple[int, ...]) -> None:
        """LC ``applyScalerCrop``: into mode pixels, at least 32x32, same centre, inside the mode."""
        mode = self.mode
        if native[2] <= 0 or native[3] <= 0:
            native = (0, 0, 1, 1)
        moved = (native[0] - mode.crop[0], native[1] - mode.crop[1], native[2], native[3])
        isp = scaled_by(moved, mode.size, mode.crop[2:])  # type: ignore[arg-type]
        w, h = max(isp[2], 32), max(isp[3], 32)
        x, y, w, h = centered_to((w, h), rect_center(isp))  # type: ignore[arg-type]
        w, h = min(w, mode.size[0]), min(h, mode.size[1])
        x = min(max(x, 0), mode.size[0] - w)
        y = min(max(y, 0), mode.size[1] - h)
        back = scaled_by((x, y, w, h), mode.crop[2:], mode.size)  # type: ignore[arg-type]
        self.scaler_crop = (back[0] + mode.crop[0], back[1] + mode.crop[1], back[2], back[3])

    # ---------------------------------------------------------------- running
    def start(self, config: dict[str, Any] | None = None, show_preview: bool = False) -> None:
        if config is not None:
            self.configure(config)
        if self.camera_config is None:
            raise RuntimeError(
                "stand-in: configure() before start() (the preview configuration is not modelled)"
            )
        self.started = True
        self._t0 = time.monotonic()
        self._next_ns = time.monotonic_ns()

    def stop(self) -> None:
        self.started = False

    def close(self) -> None:
        self.started = False
        self.closed = True

    def capture_request(self, wait: Any = None, flush: Any = None) -> SimRequest:
        with self._lock:
            if not self.started:
                raise RuntimeError("Camera is not running")
            config = self.camera_config
            assert config is not None
            if self._held >= config["buffer_count"] - 1:
                # picamera2 would stall once every buffer is held; a test should hear of it.
                raise RuntimeError("stand-in: every buffer is held; release() the requests")
            image, metadata = self._next_frame()
            self._held += 1
            return SimRequest(self, image, metadata)

    def capture_metadata(self, wait: Any = None) -> dict[str, Any]:
        request = self.capture_request()
        request.release()
        return request.get_metadata()

    def capture_array(self, name: str = "main", wait: Any = None) -> np.ndarray:
        request = self.capture_request()
        request.release()
        return request.make_array(name)

    # ---------------------------------------------------------------- one frame
    def _frame_duration_us(self) -> int:
        limits = self.controls.make_dict().get("FrameDurationLimits", (33333, 33333))
        return max(int(limits[0]), int(1e6 / self.mode.fps))

    def _next_frame(self) -> tuple[np.ndarray, dict[str, Any]]:
        period_ns = self._frame_duration_us() * 1000
        now = time.monotonic_ns()
        if self._next_ns < now - period_ns:  # a slow reader: frames went by unread
            self._next_ns += ((now - self._next_ns) // period_ns) * period_ns
        if self._next_ns > now:
            time.sleep((self._next_ns - now) / 1e9)
        timestamp = self._next_ns  # the end of the frame's readout
        self._next_ns += period_ns
        values = self.controls.make_dict()
        if (
            self.SENSOR.autofocus
            and values.get("AfMode", AF_MANUAL) == AF_MANUAL
            and "LensPosition" in values
        ):
            lo, hi, _ = self.SENSOR.lens_limits
            target = min(max(float(values["LensPosition"]), lo), hi)
            step = self.SENSOR.max_slew
            self._lens = min(max(target, self._lens - step), self._lens + step)
        t = (timestamp / 1e9) - self._t0
        pose = pose_at(self.SCENE, t)
        image = self._render(pose, self._frame_index)
        auto = values.get("AeEnable", True) is not False
        metadata: dict[str, Any] = {
            "SensorTimestamp": timestamp + self.CLOCK_OFFSET_NS,
            "ScalerCrop": self.scaler_crop,
            "ExposureTime": 10000 if auto or "ExposureTime" not in values else int(values["ExposureTime"]),
            "AnalogueGain": 2.0 if auto or "AnalogueGain" not in values else float(values["AnalogueGain"]),
            "FrameDuration": period_ns // 1000,
            "SimTruePose": pose,  # not picamera2's: the stand-in's truth, for the source to pass on
        }
        if self.SENSOR.autofocus:
            metadata.update(LensPosition=self._lens, AfState=0)
        self._frame_index += 1
        return image, metadata

    def stream_truth(self) -> CameraModel:
        """The model the current frames are rendered through (the stand-in's own truth)."""
        config = self.camera_config
        assert config is not None
        full = self.full_profile
        if self.SENSOR.autofocus and full.focal_length_mm:
            scale = thin_lens_image_distance(full.focal_length_mm, self._lens) / full.focal_length_mm
            K = full.K
            full = CameraModel(
                fx=K[0, 0] * scale,
                fy=K[1, 1] * scale,
                cx=K[0, 2],
                cy=K[1, 2],
                width=full.width,
                height=full.height,
                dist=full.dist,
            )
        return stream_truth(full, self.scaler_crop, config["main"]["size"])

    def _render(self, pose: Pose, index: int) -> np.ndarray:
        config = self.camera_config
        assert config is not None
        camera = self.stream_truth()
        s = self.SCENE
        blur = s.blur_px
        if self.SENSOR.autofocus and self.full_profile.focal_length_mm:
            f = self.full_profile.focal_length_mm
            defocus = abs(self._lens - 1000.0 / max(float(pose.position_mm[2]), 1.0))
            circle_mm = (f * f / self.SENSOR.f_number) * defocus / 1000.0
            pitch_mm = f / self.full_profile.fx  # full-resolution pixel pitch
            circle_px = circle_mm / pitch_mm * camera.width / self.scaler_crop[2]
            blur = math.hypot(blur, circle_px / 4)  # a disc of diameter d: sigma d/4 along each axis
        kwargs = dict(text=s.text, noise_sigma=s.noise_sigma, blur_px=blur, seed=s.seed + index, color=True)
        try:
            image = render_view(camera, self.SIDE_MM, pose, **kwargs).image
        except RenderError:
            try:  # a card partly out of view is still a picture
                image = render_view(camera, self.SIDE_MM, pose, allow_partial=True, **kwargs).image
            except RenderError:
                image = np.full((camera.height, camera.width, 3), 110, np.uint8)
        fmt = config["main"]["format"]
        if fmt.startswith("X"):  # 4 bytes per pixel
            image = np.concatenate([image, np.full((*image.shape[:2], 1), 255, np.uint8)], axis=2)
        return image


def picamera2_class(
    sensor: str = "imx219", scene: VirtualBenchSettings | None = None, side_mm: float = 50.0
) -> type[SimPicamera2]:
    """A ``Picamera2`` stand-in class for ``sensor`` (imx219, imx708, imx477) showing ``scene``."""
    if sensor not in SENSORS:
        raise ValueError(f"no simulated sensor {sensor!r}; known: {', '.join(SENSORS)}")
    attrs: dict[str, Any] = {
        "SENSOR": SENSORS[sensor],
        "SCENE": scene or VirtualBenchSettings(fps=0.0),
        "SIDE_MM": float(side_mm),
        "instances": [],
    }
    return type(f"SimPicamera2_{sensor}", (SimPicamera2,), attrs)
