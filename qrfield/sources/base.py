"""The camera-source interface: every source (real or simulated) delivers :class:`Frame` objects.

A source is opened once, read frame by frame, and closed. ``read`` blocks until the next frame
(a real camera's exposure, or the virtual bench's frame pacing) and raises :class:`SourceError`
when the source fails or vanishes, or :class:`EndOfStream` when a finite source (a video file or
a folder that does not loop) is exhausted. Plain Python: no Qt here.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from qrfield.geometry import Pose

if TYPE_CHECKING:
    from qrfield.camera import CameraModel


#: Frames a camera runs on automatic exposure (and a USB camera on autofocus) before they are locked.
SETTLE_FRAMES = 15


class SourceError(RuntimeError):
    """A camera source cannot be opened or stopped delivering frames; the message says which and why."""


class EndOfStream(SourceError):
    """A finite source (video file, folder of images) has no more frames."""


@dataclass(frozen=True)
class Frame:
    """One captured image.

    Attributes:
        image: (H, W) uint8 grey or (H, W, 3) uint8 BGR, OpenCV pixel convention.
        t_capture: time.monotonic() seconds at which the frame was captured (or rendered).
        index: 0, 1, 2, ... in the order the source delivered them since it was opened.
        truth: the true pose (mm, degrees) for the virtual bench; None for real cameras.
        label: where the frame came from, for humans (file name, camera name); may be empty.
        t_media: the frame's time on its recording's own clock, s (a video file's timestamp, from
            its first frame), or None for a live source, whose clock is ``t_capture``. The stream's
            time (``FrameResult.t_ms``: the history's age, the filter's steps) follows it, so a file
            gives the same poses however fast it is decoded; ages and latencies stay on
            ``t_capture``.
    """

    image: np.ndarray
    t_capture: float
    index: int
    truth: Pose | None = None
    label: str = ""
    t_media: float | None = None

    def __post_init__(self) -> None:
        image = self.image
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
            raise ValueError(f"frame image must be a uint8 numpy array, got {type(image).__name__}")
        if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (3, 4))):
            raise ValueError(f"frame image must be (H, W) grey or (H, W, 3) BGR, got shape {image.shape}")

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return int(self.image.shape[1]), int(self.image.shape[0])


@dataclass
class Pacer:
    """Holds a frame loop to at most ``fps`` frames per second (0 = as fast as possible)."""

    fps: float = 0.0
    _next: float = field(default=0.0, repr=False)

    def wait(self) -> None:
        if self.fps <= 0:
            return
        now = time.monotonic()
        if self._next > now:
            time.sleep(self._next - now)
            now = self._next
        # The next slot counts from this frame, so a late frame never builds up a backlog.
        self._next = now + 1.0 / self.fps


class FrameSource(ABC):
    """One camera source. Use as ``with source: frame = source.read()`` or open()/read()/close().

    Attributes:
        name: short kind name (``virtual``, ``usb:0``, ``video``, ``folder``, ``picamera2``).
        description: one line for humans (what exactly is being read).
        notes: messages worth showing (why ``auto`` chose this source, files skipped, ...).
        live: frames come whether or not anyone reads them (a camera), so a reader must drain
            them; False when a frame is made on request (the virtual bench renders it in read()).
        simulated: the frames are made up (rendered), not captured by a camera: the virtual
            bench and the picamera2 stand-in (which is live, like the camera it imitates). A pose
            is a real measurement only from a source that is live and not simulated.
        camera: the camera model of the frames when the source knows it (a picamera2 stream's,
            derived from its sensor crop), else None: the model the user named applies.
    """

    name: str = "source"
    live: bool = True
    simulated: bool = False
    camera: CameraModel | None = None

    def __init__(self) -> None:
        self.notes: list[str] = []
        self._index = 0
        self._open = False

    @property
    def description(self) -> str:
        return self.name

    @property
    def is_open(self) -> bool:
        return self._open

    def open(self) -> None:
        """Acquire the device or file; raises SourceError saying why it cannot."""
        if self._open:
            return
        self._open_impl()
        self._open = True
        self._index = 0

    def read(self) -> Frame:
        """The next frame; SourceError if the source failed, EndOfStream when it is exhausted."""
        if not self._open:
            raise SourceError(f"{self.description}: read() before open()")
        frame = self._read_impl(self._index)
        self._index += 1
        return frame

    def close(self) -> None:
        """Release the device or file; safe to call twice or after a failure."""
        if self._open:
            self._open = False
            self._close_impl()

    def __enter__(self) -> FrameSource:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @abstractmethod
    def _open_impl(self) -> None: ...

    @abstractmethod
    def _read_impl(self, index: int) -> Frame: ...

    @abstractmethod
    def _close_impl(self) -> None: ...
