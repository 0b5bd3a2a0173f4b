"""The Raspberry Pi camera through picamera2 (imported only when this source is opened).

picamera2 ships with Raspberry Pi OS (apt package ``python3-picamera2``), not from PyPI; see
DEVELOPERS.md. Exposure and gain can be fixed, or locked at the values the camera's automatic
exposure settled on after ``settle_frames`` frames, so that brightness stays put during a measurement.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.settings import setting, validated
from qrfield.sources.base import Frame, FrameSource, SourceError

PICAMERA2_MISSING = (
    "picamera2 is not installed: on Raspberry Pi OS run sudo apt install python3-picamera2 and make the "
    "venv with --system-site-packages (./run.sh does this)"
)


@dataclass(frozen=True)
class Picamera2Settings:
    """Resolution and exposure of the Raspberry Pi camera."""

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
        15, label="settle frames", minimum=0, maximum=300, help="frames before the lock"
    )
    camera_num: int = setting(0, label="camera number", minimum=0, maximum=7)


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


class Picamera2Source(FrameSource):
    """Frames from a Raspberry Pi camera module (BGR, as OpenCV expects)."""

    name = "picamera2"

    def __init__(self, settings: Picamera2Settings | None = None) -> None:
        super().__init__()
        self.settings = validated(settings or Picamera2Settings())
        self._camera: Any = None
        self._locked = False

    @property
    def description(self) -> str:
        s = self.settings
        return f"Raspberry Pi camera {s.camera_num} (picamera2, {s.width}x{s.height})"

    def _open_impl(self) -> None:
        Picamera2 = import_picamera2()
        s = self.settings
        try:
            camera = Picamera2(s.camera_num)
        except Exception as exc:  # picamera2 raises IndexError/RuntimeError when no camera is attached
            raise SourceError(f"picamera2: no camera {s.camera_num} ({exc})") from exc
        try:
            # picamera2's "RGB888" is B, G, R in memory: the order OpenCV uses.
            config = camera.create_video_configuration(main={"size": (s.width, s.height), "format": "RGB888"})
            camera.configure(config)
            controls: dict[str, Any] = {}
            if s.exposure_us > 0:
                controls.update(AeEnable=False, ExposureTime=int(s.exposure_us))
            if s.gain > 0:
                controls.update(AeEnable=False, AnalogueGain=float(s.gain))
            if controls:
                camera.set_controls(controls)
            camera.start()
        except Exception as exc:
            _close_quietly(camera)
            raise SourceError(
                f"picamera2: cannot start camera {s.camera_num} at {s.width}x{s.height} ({exc})"
            ) from exc
        self._camera = camera
        self._locked = bool(controls) or not s.lock_exposure

    def _read_impl(self, index: int) -> Frame:
        try:
            image = self._camera.capture_array("main")
        except Exception as exc:
            raise SourceError(f"picamera2: capture failed ({exc})") from exc
        t = time.monotonic()
        image = np.ascontiguousarray(image[..., :3]) if image.ndim == 3 else image
        if not self._locked and index + 1 >= self.settings.settle_frames:
            self._lock_exposure()
        return Frame(image.astype(np.uint8, copy=False), t, index, label=f"picamera2 #{index}")

    def _lock_exposure(self) -> None:
        """Fix exposure time and gain at the automatic exposure's current values."""
        self._locked = True
        try:
            metadata = self._camera.capture_metadata()
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


def _close_quietly(camera: Any) -> None:
    if camera is None:
        return
    for method in ("stop", "close"):
        with contextlib.suppress(Exception):  # closing a failed camera must not hide the first error
            getattr(camera, method)()
