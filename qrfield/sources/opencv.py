"""OpenCV VideoCapture sources: a USB camera by index, or a video file (which may loop)."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from qrfield.camera import CameraModel
from qrfield.images import opencv_quiet
from qrfield.settings import setting, validated
from qrfield.sources.base import SETTLE_FRAMES, EndOfStream, Frame, FrameSource, Pacer, SourceError
from qrfield.texts import TextError, check_path_for_library

#: OpenCV's FFmpeg backend reads this once, at its first capture: -8 is AV_LOG_QUIET, so a damaged
#: video file's decoder lines ("[mjpeg @ 0x...] huffman table decode error") never reach the console;
#: the source says what went wrong in one line instead (cap_ffmpeg_impl.hpp: without the variable
#: OpenCV sets AV_LOG_ERROR). A value the user set is kept.
FFMPEG_LOG_LEVEL = ("OPENCV_FFMPEG_LOGLEVEL", "-8")

#: Consecutive failed grabs after which a USB camera counts as gone.
USB_MAX_FAILED_READS = 5
#: A video file whose container gives no usable frame rate is timed at this rate (frames/s).
VIDEO_FALLBACK_FPS = 30.0
#: A looping video's next pass starts this long after the last frame of the one before (s), more
#: than the stream's 0.5 s history and filter gap (docs/conventions.md, "The live stream"): the
#: card's pose jumps back to the first frame's, and that must not be read as motion.
VIDEO_LOOP_GAP_S = 1.0
#: FourCCs (as the container reports them, upper case) of MPEG-4 Part 2, OpenCV's ``mp4v``
#: writer's codec (FFmpeg reports it as FMP4): at its default quality it moves a small code's
#: corners several times more than their std says (docs/headless.md, "A video file's clock").
COARSE_VIDEO_CODECS = ("FMP4", "MP4V", "XVID", "DIVX", "DX50")


@dataclass(frozen=True)
class UsbCameraSettings:
    """Pixel format, focus and exposure of a USB camera (V4L2 through OpenCV VideoCapture)."""

    fourcc: str = setting(
        "auto",
        label="pixel format",
        choices=("auto", "MJPG", "YUYV", "driver"),
        help="auto: MJPG above 640x480 where the camera offers it (raw YUYV at 720p and up exceeds USB 2 "
        "at full frame rate), else the driver's default; driver: never change it",
    )
    autofocus_off: bool = setting(
        True, label="autofocus off", help="switch autofocus off where the driver offers it: focus held still"
    )
    focus: int = setting(
        -1,
        label="focus",
        minimum=-1,
        maximum=1023,
        help="fixed focus value (the driver's CAP_PROP_FOCUS units; -1 = where the autofocus left it)",
    )
    lock_exposure: bool = setting(
        True,
        label="lock exposure",
        help="freeze automatic exposure once settled, where offered",
    )
    settle_frames: int = setting(
        SETTLE_FRAMES,
        label="settle frames",
        minimum=0,
        maximum=300,
        help="frames before focus and exposure are locked",
    )


#: V4L2 exposure_auto menu values (OpenCV's V4L2 backend passes CAP_PROP_AUTO_EXPOSURE through).
V4L2_EXPOSURE_MANUAL, V4L2_EXPOSURE_APERTURE_PRIORITY = 1, 3
#: Frame sizes above this many pixels get MJPG (``fourcc`` auto).
MJPG_ABOVE_PIXELS = 640 * 480


def fourcc_text(value: float) -> str:
    """CAP_PROP_FOURCC's number as its four letters ('' when unknown)."""
    code = int(value) if value and value > 0 else 0
    text = "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4))
    return text if text.isprintable() and text.strip() else ""


class UsbCameraSource(FrameSource):
    """A camera OpenCV can open by index (``usb:N``, /dev/videoN on Linux).

    At open the source asks for the size (MJPG above 640x480 where offered), switches autofocus
    off (a fixed ``focus`` if set) where the driver offers it, and reads one frame: its size is the
    size delivered, which must be the camera model's (a mismatch is a SourceError, never a silent
    rescale: a webcam may crop for some sizes). After ``settle_frames`` the automatic exposure (and
    the focus the autofocus found) is locked where the driver offers it. ``notes`` say what the
    driver took.

    Args:
        index: the device index.
        width, height: requested resolution in pixels (None = the camera's default).
        camera: the camera model the frames must fit (None: no check).
        settings: pixel format, focus and exposure.
    """

    def __init__(
        self,
        index: int = 0,
        width: int | None = None,
        height: int | None = None,
        *,
        camera: CameraModel | None = None,
        settings: UsbCameraSettings | None = None,
    ) -> None:
        super().__init__()
        if index < 0:
            raise ValueError(f"USB camera index must be >= 0, got {index}")
        self.index = int(index)
        self.width, self.height = width, height
        self.profile = camera
        self.settings = validated(settings or UsbCameraSettings())
        self.name = f"usb:{self.index}"
        self.size: tuple[int, int] | None = None
        self.fourcc = ""
        self._cap: cv2.VideoCapture | None = None
        self._first: np.ndarray | None = None
        self._locked = False

    @property
    def description(self) -> str:
        text = f"USB camera {self.index} (OpenCV VideoCapture"
        if self.size:
            text += f", {self.size[0]}x{self.size[1]}" + (f" {self.fourcc}" if self.fourcc else "")
        return text + ")"

    def _open_impl(self) -> None:
        cap = quietly_open(self.index)
        if not cap.isOpened():
            cap.release()
            where = f" (/dev/video{self.index})" if os.name == "posix" else ""
            raise SourceError(f"cannot open USB camera {self.index}{where}: no such device or it is busy")
        self._cap = cap
        self._locked = False
        try:
            self._set_format(cap)
            self._set_focus(cap)
            image = self._grab()
            self.size = (int(image.shape[1]), int(image.shape[0]))
            self._check_size(self.size)
        except SourceError:
            self._close_impl()
            raise
        self._first = image

    def _set_format(self, cap: cv2.VideoCapture) -> None:
        s = self.settings
        big = bool(self.width and self.height and self.width * self.height > MJPG_ABOVE_PIXELS)
        wanted = {"auto": "MJPG" if big else "", "driver": ""}.get(s.fourcc, s.fourcc)
        if wanted:
            # The pixel format goes first: a driver offers some sizes only in some formats.
            cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*wanted))
        if self.width and self.height:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.width)
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.height)
        self.fourcc = fourcc_text(cap.get(cv2.CAP_PROP_FOURCC))
        if wanted and self.fourcc and self.fourcc != wanted:
            self.notes.append(f"the camera does not offer {wanted} here; it sends {self.fourcc}")

    def _set_focus(self, cap: cv2.VideoCapture) -> None:
        s = self.settings
        if not s.autofocus_off:
            return
        if not _set_and_check(cap, cv2.CAP_PROP_AUTOFOCUS, 0):
            self.notes.append("autofocus: the driver offers no autofocus switch (fixed-focus camera?)")
            return
        if s.focus >= 0:
            if _set_and_check(cap, cv2.CAP_PROP_FOCUS, s.focus):
                self.notes.append(f"autofocus off, focus fixed at {s.focus}")
            else:
                self.notes.append(f"autofocus off; the driver did not take focus {s.focus}")
        else:
            self.notes.append(f"autofocus off, focus held at {cap.get(cv2.CAP_PROP_FOCUS):g}")

    def _lock_exposure(self, cap: cv2.VideoCapture) -> None:
        """Switch automatic exposure to manual at the exposure it settled on, where offered."""
        self._locked = True
        if not self.settings.lock_exposure:
            return
        exposure = cap.get(cv2.CAP_PROP_EXPOSURE)
        if not _set_and_check(cap, cv2.CAP_PROP_AUTO_EXPOSURE, V4L2_EXPOSURE_MANUAL):
            self.notes.append("exposure: the driver offers no manual exposure; it stays automatic")
            return
        if exposure > 0:
            cap.set(cv2.CAP_PROP_EXPOSURE, exposure)
        self.notes.append(f"exposure locked at {cap.get(cv2.CAP_PROP_EXPOSURE):g} (driver units)")

    def _check_size(self, size: tuple[int, int]) -> None:
        camera = self.profile
        if camera is not None and size != camera.size:
            w, h = size
            asked = f" (asked for {self.width}x{self.height})" if self.width and self.height else ""
            raise SourceError(
                f"USB camera {self.index} delivers {w}x{h} frames{asked}, but the camera model "
                f"{camera.name!r} is for {camera.width}x{camera.height}: name a model of {w}x{h} "
                f"(calibrate at this size, or NAME@{w}x{h} if it is the same field of view)"
            )

    def _grab(self) -> np.ndarray:
        assert self._cap is not None
        for _ in range(USB_MAX_FAILED_READS):
            ok, image = self._cap.read()
            if ok and image is not None:
                return image
        raise SourceError(
            f"USB camera {self.index} stopped delivering frames ({USB_MAX_FAILED_READS} failed reads): "
            "unplugged or taken by another program?"
        )

    def _read_impl(self, index: int) -> Frame:
        assert self._cap is not None
        if self._first is not None:
            image, self._first = self._first, None
        else:
            image = self._grab()
        t = time.monotonic()
        size = (int(image.shape[1]), int(image.shape[0]))
        if size != self.size:
            raise SourceError(
                f"USB camera {self.index} changed its frame size from {self.size} to {size}: reopen it"
            )
        if not self._locked and index + 1 >= self.settings.settle_frames:
            self._lock_exposure(self._cap)
        return Frame(image, t, index, label=self.name)

    def _close_impl(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None
        self._first = None


def _set_and_check(cap: cv2.VideoCapture, prop: int, value: float) -> bool:
    """Set ``prop`` and read it back: VideoCapture.set's True only says the backend knows the
    property, not that the device took the value (OpenCV's VideoCapture::set documentation)."""
    if not cap.set(prop, value):
        return False
    return abs(cap.get(prop) - value) < 0.5


def quietly_open(index: int) -> cv2.VideoCapture:
    """cv2.VideoCapture(index) without OpenCV's console warnings when there is no such camera
    (the SourceError raised instead says so once, in words)."""
    with opencv_quiet():
        return cv2.VideoCapture(index)


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
        self._fps = VIDEO_FALLBACK_FPS
        self._pass_start_s = 0.0  # media time of this pass' first frame (loops add to it)
        self._last_s: float | None = None  # media time of the last frame delivered

    @property
    def description(self) -> str:
        return f"video file {self.path}" + (" (looping)" if self.loop else "")

    def _media_time(self, pass_start: bool) -> float:
        """The frame just read's time on the file's clock, s since its first frame: the container's
        timestamp (``CAP_PROP_POS_MSEC``, after ``read`` the frame just read's: cap_ffmpeg_impl.hpp's
        ``get_position``), or one frame period after the last where it gives none that moves
        forward (raw streams report 0); loops continue after :data:`VIDEO_LOOP_GAP_S`."""
        assert self._cap is not None
        if pass_start and self._last_s is not None:
            self._pass_start_s = self._last_s + VIDEO_LOOP_GAP_S
        pos_ms = self._cap.get(cv2.CAP_PROP_POS_MSEC)
        t = self._pass_start_s + pos_ms / 1000.0 if np.isfinite(pos_ms) and pos_ms >= 0 else None
        if self._last_s is not None and (t is None or t <= self._last_s):
            t = self._last_s + 1.0 / self._fps
        elif t is None:
            t = self._pass_start_s
        self._last_s = t
        return t

    def _open_impl(self) -> None:
        if not self.path.is_file():
            raise SourceError(f"video file {self.path}: no such file")
        try:
            name = check_path_for_library(self.path, f"video file {self.path}")
        except TextError as exc:
            raise SourceError(str(exc)) from None
        os.environ.setdefault(*FFMPEG_LOG_LEVEL)
        cap = cv2.VideoCapture(name)
        if not cap.isOpened():
            cap.release()
            raise SourceError(f"video file {self.path}: OpenCV cannot decode it (unknown format or codec)")
        file_fps = cap.get(cv2.CAP_PROP_FPS)
        usable_fps = bool(np.isfinite(file_fps) and 0 < file_fps < 1000)
        self._pacer = Pacer(file_fps if self.pace and usable_fps else 0.0)
        self._fps = float(file_fps) if usable_fps else VIDEO_FALLBACK_FPS
        self._pass_start_s, self._last_s = 0.0, None
        code = int(cap.get(cv2.CAP_PROP_FOURCC)) & 0xFFFFFFFF
        fourcc = code.to_bytes(4, "little").decode("latin-1").strip("\0 ").upper()
        if fourcc in COARSE_VIDEO_CODECS:
            self.notes.append(
                f"{self.path.name} is MPEG-4 Part 2 ({fourcc}): its coding moves small codes' corners "
                "more than their std says; for measurements record FFV1, MJPG or VP8/VP9"
            )
        self._cap = cap

    def _read_impl(self, index: int) -> Frame:
        assert self._cap is not None
        self._pacer.wait()
        ok, image = self._cap.read()
        looped = False
        if not ok and self.loop and index > 0:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, image = self._cap.read()
            looped = True
        if not ok or image is None:
            if index == 0:
                raise SourceError(f"video file {self.path}: no frame could be decoded")
            raise EndOfStream(f"video file {self.path}: end after {index} frames")
        t_media = self._media_time(looped)
        return Frame(image, time.monotonic(), index, label=f"{self.path.name} #{index}", t_media=t_media)

    def _close_impl(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None
