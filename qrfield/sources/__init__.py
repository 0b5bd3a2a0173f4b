"""Camera sources behind one interface (:class:`FrameSource`), and :func:`open_source` for ``--source``.

Sources: the virtual bench (``virtual``), a Raspberry Pi camera (``picamera2``), a SIMULATED
Raspberry Pi camera (``picamera2-sim[:SENSOR]``: the picamera2 stand-in, never chosen by ``auto``), a
USB camera (``usb:N``), a video file or a folder of images (a path), and ``auto``, which tries
picamera2, then USB camera 0, then the virtual bench, and notes which it chose and why the others
failed. Plain Python, no Qt: the headless runner and the app's worker thread both use it.

A source that knows the camera model of its frames (picamera2: the profile mapped through the
stream's sensor crop) sets ``source.camera``; :func:`stream_camera` gives the model to measure with.
"""

from __future__ import annotations

import os
from pathlib import Path

from qrfield.camera import CameraModel, resolve_camera
from qrfield.sources.base import EndOfStream, Frame, FrameSource, Pacer, SourceError
from qrfield.sources.folder import ImageFolderSource
from qrfield.sources.latest import LatestFrameReader
from qrfield.sources.opencv import UsbCameraSettings, UsbCameraSource, VideoFileSource
from qrfield.sources.picamera import (
    PICAMERA2_MISSING,
    Picamera2Settings,
    Picamera2Source,
    SimulatedPicamera2Source,
)
from qrfield.sources.virtual import VirtualBenchSettings, VirtualBenchSource

__all__ = [
    "PICAMERA2_MISSING",
    "SOURCE_HELP",
    "EndOfStream",
    "Frame",
    "FrameSource",
    "ImageFolderSource",
    "LatestFrameReader",
    "Pacer",
    "Picamera2Settings",
    "Picamera2Source",
    "SimulatedPicamera2Source",
    "SourceError",
    "UsbCameraSettings",
    "UsbCameraSource",
    "VideoFileSource",
    "VirtualBenchSettings",
    "VirtualBenchSource",
    "make_source",
    "open_source",
    "stream_camera",
]

#: Camera used by the virtual bench when none is named.
DEFAULT_VIRTUAL_CAMERA = "picam-v2@640x480"

#: The simulated picamera2 spelling: picamera2-sim or picamera2-sim:SENSOR.
SIM_PICAMERA2 = "picamera2-sim"

SOURCE_HELP = (
    "camera source: auto (picamera2, then USB camera 0, then the virtual bench), virtual, picamera2, "
    "usb:N (OpenCV camera index N), a path to a video file or a folder of images, or "
    "picamera2-sim[:imx219|imx708|imx477] (a SIMULATED Pi camera: the picamera2 stand-in)"
)


def make_source(
    spec: str,
    *,
    camera: CameraModel | None = None,
    side_mm: float = 50.0,
    virtual: VirtualBenchSettings | None = None,
    picamera: Picamera2Settings | None = None,
    usb: UsbCameraSettings | None = None,
    loop: bool = False,
    pace: bool = False,
) -> FrameSource:
    """The (unopened) source named by ``spec`` (any ``--source`` value but ``auto``).

    Args:
        spec: ``virtual``, ``picamera2``, ``picamera2-sim[:SENSOR]``, ``usb:N`` or a path (video
            file or folder).
        camera: the virtual bench's camera model (default picam-v2@640x480); for real cameras,
            its size is the resolution requested; picamera2 maps it through the stream's sensor
            crop, a USB camera's frames must have its size.
        side_mm: the virtual bench's (and the picamera2 stand-in's) QR side, mm.
        virtual, picamera, usb: settings of those sources (``virtual`` also sets the stand-in's scene).
        loop: a video file or folder starts again at its end.
        pace: a video file plays at its own frame rate, a folder at 2 images per second.

    Raises:
        SourceError: the spec names nothing usable (the message lists the valid forms).
    """
    spec = spec.strip()
    if spec == "virtual":
        return VirtualBenchSource(camera or resolve_camera(DEFAULT_VIRTUAL_CAMERA), side_mm, virtual)
    if spec == "picamera2" or spec == SIM_PICAMERA2 or spec.startswith(SIM_PICAMERA2 + ":"):
        if picamera is None and camera is not None:
            picamera = Picamera2Settings(width=camera.width, height=camera.height)
        if spec == "picamera2":
            return Picamera2Source(picamera, profile=camera)
        sensor = spec.partition(":")[2] or "imx219"
        scene = virtual or VirtualBenchSettings()
        return SimulatedPicamera2Source(picamera, profile=camera, sensor=sensor, scene=scene, side_mm=side_mm)
    if spec.startswith("usb:") or spec == "usb":
        index_text = spec[4:] if spec.startswith("usb:") else "0"
        if not index_text.isdigit():
            raise SourceError(f"source {spec!r}: the USB camera index must be a whole number, e.g. usb:0")
        size = (camera.width, camera.height) if camera else (None, None)
        return UsbCameraSource(int(index_text), *size, camera=camera, settings=usb)
    if spec == "auto":
        raise SourceError("source 'auto' is resolved by open_source(), not make_source()")
    path = Path(spec).expanduser()
    if path.is_dir():
        return ImageFolderSource(path, loop=loop, fps=2.0 if pace else 0.0)
    if path.is_file():
        return VideoFileSource(path, loop=loop, pace=pace)
    raise SourceError(
        f"source {spec!r}: no such file or folder, and not one of auto, virtual, picamera2, usb:N"
    )


def open_source(spec: str, **kwargs: object) -> FrameSource:
    """Make and open the source named by ``spec`` (see :func:`make_source`; also ``auto``).

    For ``auto`` the chosen source's ``notes`` start with which source was chosen and why each
    one before it failed. Raises SourceError when the source cannot be opened.
    """
    if spec.strip() != "auto":
        source = make_source(spec, **kwargs)  # type: ignore[arg-type]
        source.open()
        return source
    failures: list[str] = []
    for candidate in ("picamera2", "usb:0", "virtual"):
        source = make_source(candidate, **kwargs)  # type: ignore[arg-type]
        try:
            source.open()
        except SourceError as exc:
            failures.append(f"{candidate}: {exc}")
            continue
        note = f"auto chose {source.description}"
        if failures:
            note += "; tried " + "; ".join(failures)
        source.notes.insert(0, note)
        return source
    raise SourceError("auto: no source could be opened; " + "; ".join(failures))  # pragma: no cover


def stream_camera(source: FrameSource, camera: CameraModel) -> CameraModel:
    """The camera model to measure ``source``'s frames with: the source's own (a picamera2 stream's,
    derived from its sensor crop) when it has one, else ``camera`` (the model the user named)."""
    own = getattr(source, "camera", None)
    return own if isinstance(own, CameraModel) else camera


def describe_spec(spec: str) -> str:
    """A short human name for a ``--source`` value (for window titles and logs)."""
    if spec in ("auto", "virtual", "picamera2") or spec.startswith(("usb", SIM_PICAMERA2)):
        return spec
    return os.path.basename(os.path.normpath(spec)) or spec
