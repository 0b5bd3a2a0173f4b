"""The run section of app.json: source, camera model, QR side, pose methods, file playback, retry."""

from __future__ import annotations

from dataclasses import dataclass

from qrfield.camera import DEFAULT_CAMERA
from qrfield.limits import SIDE_MM
from qrfield.methods import BOTH, METHOD_CHOICES
from qrfield.settings import setting


@dataclass(frozen=True)
class RunSettings:
    """What to measure from and with: source, camera model, QR side, pose methods."""

    source: str = setting(
        "auto",
        label="source",
        help="auto (picamera2, then USB camera 0, then the virtual bench), virtual, picamera2, usb:N, "
        "or a video file / folder of images",
    )
    camera: str = setting(DEFAULT_CAMERA, label="camera model", help="preset NAME[@WxH] or PATH.json[@WxH]")
    side_mm: float = setting(
        50.0,
        label="QR side",
        unit="mm",
        minimum=SIDE_MM.minimum,
        maximum=SIDE_MM.maximum,
        decimals=1,
        help="side of the QR symbol without its quiet zone",
    )
    method: str = setting(
        BOTH,
        label="method",
        choices=METHOD_CHOICES,
        help="the thesis' numerical model, OpenCV IPPE, or both side by side (numerical gives the status)",
    )
    loop: bool = setting(False, label="loop files", help="a video file or folder starts again at its end")
    pace: bool = setting(
        False, label="pace files", help="play a video file at its own frame rate (a folder at 2 images/s)"
    )
    retry_s: float = setting(
        0.0,
        label="retry after",
        unit="s",
        minimum=0.0,
        maximum=3600.0,
        decimals=1,
        help="when the source fails, reopen it after this many seconds (0 = stop, or wait for Reopen)",
    )
