"""OpenCV VideoCapture sources: a USB camera by index, or a video file (which may loop)."""

from __future__ import annotations

import os
import time
from pathlib import Path

import cv2

from qrfield.sources.base import EndOfStream, Frame, FrameSource, Pacer, SourceError

#: Consecutive failed grabs after which a USB camera counts as gone.
USB_MAX_FAILED_READS = 5


class UsbCameraSource(FrameSource):
    """A camera OpenCV can open by index (``usb:N``, /dev/videoN on Linux).

    Args:
        index: the device index.
        width, height: requested resolution in pixels (None = the camera's default); the camera
            may deliver another size, which the frames then have.
    """

    def __init__(self, index: int = 0, width: int | None = None, height: int | None = None) -> None:
        super().__init__()
        if index < 0:
            raise ValueError(f"USB camera index must be >= 0, got {index}")
        self.index = int(index)
        self.width, self.height = width, height
        self.name = f"usb:{self.index}"
        self._cap: cv2.VideoCapture | None = None

    @property
    def description(self) -> str:
        return f"USB camera {self.index} (OpenCV VideoCapture)"

    def _open_impl(self) -> None:
        cap = _quietly_open(self.index)
        if not cap.isOpened():
            cap.release()
            where = f" (/dev/video{self.index})" if os.name == "posix" else ""
            raise SourceError(f"cannot open USB camera {self.index}{where}: no such device or it is busy")
        if self.width and self.height:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.width)
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.height)
        self._cap = cap

    def _read_impl(self, index: int) -> Frame:
        assert self._cap is not None
        for _ in range(USB_MAX_FAILED_READS):
            ok, image = self._cap.read()
            if ok and image is not None:
                return Frame(image, time.monotonic(), index, label=self.name)
        raise SourceError(
            f"USB camera {self.index} stopped delivering frames ({USB_MAX_FAILED_READS} failed reads): "
            "unplugged or taken by another program?"
        )

    def _close_impl(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


def _quietly_open(index: int) -> cv2.VideoCapture:
    """cv2.VideoCapture(index) without OpenCV's console warnings when there is no such camera
    (the SourceError raised instead says so once, in words)."""
    logging = getattr(getattr(cv2, "utils", None), "logging", None)
    if logging is None:
        return cv2.VideoCapture(index)
    level = logging.getLogLevel()
    logging.setLogLevel(logging.LOG_LEVEL_ERROR)
    try:
        return cv2.VideoCapture(index)
    finally:
        logging.setLogLevel(level)


class VideoFileSource(FrameSource):
    """Frames of a video file, in order.

    Args:
        path: the video file.
        loop: start again from the first frame at the end instead of raising EndOfStream.
        pace: deliver frames at the file's own frame rate (live playback) instead of as fast as decoded.
    """

    name = "video"
    live = False  # a frame is decoded when read(): every frame in turn, none dropped

    def __init__(self, path: str | os.PathLike[str], loop: bool = False, pace: bool = False) -> None:
        super().__init__()
        self.path = Path(path)
        self.loop = loop
        self.pace = pace
        self._cap: cv2.VideoCapture | None = None
        self._pacer = Pacer(0.0)

    @property
    def description(self) -> str:
        return f"video file {self.path}" + (" (looping)" if self.loop else "")

    def _open_impl(self) -> None:
        if not self.path.is_file():
            raise SourceError(f"video file {self.path}: no such file")
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise SourceError(f"video file {self.path}: OpenCV cannot decode it (unknown format or codec)")
        file_fps = cap.get(cv2.CAP_PROP_FPS)
        self._pacer = Pacer(file_fps if self.pace and 0 < file_fps < 1000 else 0.0)
        self._cap = cap

    def _read_impl(self, index: int) -> Frame:
        assert self._cap is not None
        self._pacer.wait()
        ok, image = self._cap.read()
        if not ok and self.loop and index > 0:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, image = self._cap.read()
        if not ok or image is None:
            if index == 0:
                raise SourceError(f"video file {self.path}: no frame could be decoded")
            raise EndOfStream(f"video file {self.path}: end after {index} frames")
        return Frame(image, time.monotonic(), index, label=f"{self.path.name} #{index}")

    def _close_impl(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None
