"""The source registry: the kinds of ``--source`` values, and which sources are real cameras.

Kinds: ``auto``, ``virtual``, ``picamera2``, ``picamera2-sim`` (``picamera2-sim[:SENSOR]``, the
picamera2 stand-in: SIMULATED), ``usb`` (``usb:N``), ``folder`` (a folder of images) and ``video``
(any other path: a video file, or one image file, read as a folder of one image). Only a live camera
(``picamera2``, ``usb``) measures the world: a pose from any other source (the virtual bench's
rendering, a recording) is marked SIM on the serial link, never OK (docs/conventions.md), so a
gripper that acts only on OK never moves on it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: The kinds of source a ``--source`` value names (:func:`source_kind`).
AUTO, VIRTUAL, PICAMERA2, PICAMERA2_SIM, USB, FOLDER, VIDEO = (
    "auto",
    "virtual",
    "picamera2",
    "picamera2-sim",
    "usb",
    "folder",
    "video",
)
SOURCE_KINDS = (AUTO, VIRTUAL, PICAMERA2, PICAMERA2_SIM, USB, FOLDER, VIDEO)
#: Kinds whose frames come from a camera looking at the world now.
LIVE_CAMERA_KINDS = (PICAMERA2, USB)
#: What ``auto`` tries, in order (the virtual bench last, and only where allowed).
AUTO_CANDIDATES = ("picamera2", "usb:0", "virtual")
#: The sources offered in a chooser (files and folders are browsed for).
SOURCE_CHOICES = ("auto", "virtual", "picamera2", "usb:0", "usb:1")

SOURCE_HELP = (
    "camera source: auto (picamera2, then USB camera 0, then the virtual bench), virtual, picamera2, "
    "usb:N (OpenCV camera index N), a path to a video file, an image or a folder of images, or "
    "picamera2-sim[:imx219|imx708|imx477] (a SIMULATED Pi camera: the picamera2 stand-in)"
)


def source_kind(spec: str) -> str:
    """The kind (one of SOURCE_KINDS) of a ``--source`` value; a path that is a folder is
    ``folder``, any other path ``video``."""
    spec = spec.strip()
    if spec in (AUTO, VIRTUAL, PICAMERA2):
        return spec
    if spec == PICAMERA2_SIM or spec.startswith(PICAMERA2_SIM + ":"):
        return PICAMERA2_SIM
    if spec == USB or spec.startswith(USB + ":"):
        return USB
    return FOLDER if Path(spec).expanduser().is_dir() else VIDEO


def may_be_live_camera(spec: str) -> bool:
    """A ``--source`` value that may open a live camera: picamera2, usb:N, or auto (it tries them
    first). Checked before a source is opened (a calibration made from simulated frames is refused)."""
    return source_kind(spec) in (AUTO, *LIVE_CAMERA_KINDS)


def is_live_camera(source: Any) -> bool:
    """True when ``source`` (an opened FrameSource) is a camera looking at the world now: a live
    picamera2 or USB camera that is not a stand-in (a ``simulated`` attribute set true)."""
    name = str(getattr(source, "name", ""))
    return (
        bool(getattr(source, "live", False))
        and source_kind(name) in LIVE_CAMERA_KINDS
        and not getattr(source, "simulated", False)
    )
