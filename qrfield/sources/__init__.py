"""Camera sources behind one interface (:class:`FrameSource`), and :func:`open_source` for ``--source``.

Sources: the virtual bench (``virtual``), a Raspberry Pi camera (``picamera2``), a USB camera
(``usb:N``), a video file or a folder of images (a path), and ``auto``, which tries picamera2,
then USB camera 0, then the virtual bench, and notes which it chose and why the others failed.
Plain Python, no Qt: the headless runner and the app's worker thread both use it.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from qrfield.camera import DEFAULT_CAMERA, CameraModel, resolve_camera
from qrfield.limits import MAX_USB_INDEX
from qrfield.sources.base import EndOfStream, Frame, FrameSource, Pacer, SourceError
from qrfield.sources.folder import ImageFolderSource, is_image_file
from qrfield.sources.kinds import (
    AUTO,
    AUTO_CANDIDATES,
    FOLDER,
    LIVE_CAMERA_KINDS,
    PICAMERA2,
    PICAMERA2_SIM,
    SOURCE_CHOICES,
    SOURCE_HELP,
    SOURCE_KINDS,
    USB,
    VIRTUAL,
    is_live_camera,
    may_be_live_camera,
    source_kind,
)
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
    "AUTO_CANDIDATES",
    "LIVE_CAMERA_KINDS",
    "PICAMERA2_MISSING",
    "SOURCE_CHOICES",
    "SOURCE_HELP",
    "SOURCE_KINDS",
    "EndOfStream",
    "Frame",
    "FrameSource",
    "ImageFolderSource",
    "LatestFrameReader",
    "Pacer",
    "Picamera2Settings",
    "Picamera2Source",
    "SourceError",
    "UsbCameraSource",
    "VideoFileSource",
    "VirtualBenchSettings",
    "VirtualBenchSource",
    "is_live_camera",
    "make_source",
    "may_be_live_camera",
    "open_source",
    "source_kind",
    "stream_camera",
]


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
            file, image file or folder).
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
    if not spec:  # Path("") is the current folder: never taken for a folder of images by accident
        raise SourceError(
            "source '': empty; give auto, virtual, picamera2, usb:N, or a path (. for the current folder)"
        )
    kind = source_kind(spec)
    if kind == VIRTUAL:
        return VirtualBenchSource(camera or resolve_camera(DEFAULT_CAMERA), side_mm, virtual)
    if kind in (PICAMERA2, PICAMERA2_SIM):
        if picamera is None and camera is not None:
            picamera = Picamera2Settings(width=camera.width, height=camera.height)
        if kind == PICAMERA2:
            return Picamera2Source(picamera, profile=camera)
        sensor = spec.partition(":")[2] or "imx219"
        scene = virtual or VirtualBenchSettings()
        return SimulatedPicamera2Source(picamera, profile=camera, sensor=sensor, scene=scene, side_mm=side_mm)
    if kind == USB:
        index_text = spec[4:] if spec.startswith("usb:") else "0"
        if not (index_text.isascii() and index_text.isdigit()):
            raise SourceError(f"source {spec!r}: the USB camera index must be a whole number, e.g. usb:0")
        if len(index_text) > 4 or int(index_text) > MAX_USB_INDEX:
            raise SourceError(
                f"source {spec!r}: USB camera index {index_text[:12]}{'...' if len(index_text) > 12 else ''} "
                f"is above the largest, {MAX_USB_INDEX} (/dev/video{MAX_USB_INDEX}); "
                "qrfield camera list shows the cameras present"
            )
        size = (camera.width, camera.height) if camera else (None, None)
        return UsbCameraSource(int(index_text), *size, camera=camera, settings=usb)
    if kind == AUTO:
        raise SourceError("source 'auto' is resolved by open_source(), not make_source()")
    path = Path(spec).expanduser()
    if kind == FOLDER:
        return ImageFolderSource(path, loop=loop, fps=2.0 if pace else 0.0)
    if is_image_file(path):  # one photo: the image reader's limits and reasons, not a video decoder's
        return ImageFolderSource(path, loop=loop, fps=2.0 if pace else 0.0)
    if path.is_file():
        return VideoFileSource(path, loop=loop, pace=pace)
    if os.path.lexists(path):  # a FIFO, a device, a broken link: there, but nothing to play
        what = "a broken symbolic link" if not path.exists() else f"{_file_kind(path)}, not a regular file"
        raise SourceError(
            f"source {spec!r}: {what}; give a video file, a folder of images, or one of auto, virtual, "
            "picamera2, usb:N"
        )
    raise SourceError(
        f"source {spec!r}: no such file or folder, and not one of auto, virtual, picamera2, usb:N"
    )


def _file_kind(path: Path) -> str:
    """``a FIFO``, ``a character device``... for a path that is no regular file or folder."""
    mode = path.stat().st_mode
    for test, name in (
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "a special file"


def open_source(spec: str, *, allow_virtual: bool = True, **kwargs: object) -> FrameSource:
    """Make and open the source named by ``spec`` (see :func:`make_source`; also ``auto``).

    For ``auto`` the chosen source's ``notes`` start with which source was chosen and why each
    one before it failed; without ``allow_virtual`` it never falls back to the virtual bench (a
    gripper must not be fed made-up poses because a camera is missing). Raises SourceError when
    the source cannot be opened.
    """
    if spec.strip() != "auto":
        source = make_source(spec, **kwargs)  # type: ignore[arg-type]
        source.open()
        return source
    failures: list[str] = []
    candidates = [c for c in AUTO_CANDIDATES if allow_virtual or source_kind(c) != "virtual"]
    for candidate in candidates:
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
    if not allow_virtual:
        raise SourceError(
            "auto found no camera (" + "; ".join(failures) + "); it does not fall back to the virtual "
            "bench here, whose poses are made up: connect a camera, name one with --source, or give "
            "--allow-virtual to stream the bench's poses (marked SIM)"
        )
    raise SourceError("auto: no source could be opened; " + "; ".join(failures))  # pragma: no cover


def stream_camera(source: FrameSource, camera: CameraModel) -> CameraModel:
    """The camera model to measure ``source``'s frames with: the source's own (a picamera2 stream's,
    derived from its sensor crop) when it has one, else ``camera`` (the model the user named)."""
    own = getattr(source, "camera", None)
    return own if isinstance(own, CameraModel) else camera
