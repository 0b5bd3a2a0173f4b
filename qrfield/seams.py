"""The seams between the stages of a frame's path, as typed protocols (and no-op bases to build on).

docs/architecture.md ("The path of a frame"):

    FrameSource.read() -> Frame -> Tracker.update(image) -> [Detection] -> select -> PoseMethod
    (qrfield.solvers.registry) -> FrameResult -> every Sink.on_result(result, simulated)

and the frame loop's owner hears :class:`LoopEvents`. A sink and an events object implement every
method of their protocol (subclass :class:`BaseSink` / :class:`LoopEventsBase` and override what they
need), so the frame loop calls them directly: nothing is looked up by name at run time.
The source's own interface is :class:`qrfield.sources.base.FrameSource` (an ABC: its twins share code).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:  # types only: these modules are heavier than this one
    import numpy as np

    from qrfield.camera import CameraModel
    from qrfield.detect.detection import Detection
    from qrfield.pipeline import FrameResult
    from qrfield.sources.base import Frame


@runtime_checkable
class Detector(Protocol):
    """Finds QR codes in one image (qrfield.detect.Detector)."""

    def detect(self, image: np.ndarray) -> list[Detection]:
        """Every code in ``image`` (grey or BGR uint8): corners V1..V4 (4, 2) px, their covariance."""
        ...


@runtime_checkable
class Tracker(Protocol):
    """Follows codes from frame to frame (qrfield.detect.Tracker); what the pipeline calls."""

    def update(self, image: np.ndarray) -> list[Detection]:
        """The detections of the next frame of the stream; never raises on image content."""
        ...

    def reset(self) -> None:
        """Forget the stream: the next frame is searched whole."""
        ...

    def set_camera(self, camera: CameraModel | None) -> None:
        """The camera model of the frames to come (the fit goes through its lens)."""
        ...


@runtime_checkable
class Sink(Protocol):
    """Takes every result of a frame loop (the serial link, ``qrfield run``'s output, the app)."""

    def on_result(self, result: FrameResult, simulated: bool) -> Any:
        """One frame's result; ``simulated``: the frame is not from a live camera."""
        ...

    def on_source_down(self, reason: str) -> None:
        """No frames come (the source failed, ended or went quiet); ``reason`` says why."""
        ...

    def on_source_up(self) -> None:
        """Frames come again."""
        ...


class BaseSink:
    """A :class:`Sink` that ignores everything: subclass it and override what you need."""

    def on_result(self, result: FrameResult, simulated: bool) -> Any:
        return None

    def on_source_down(self, reason: str) -> None:
        return None

    def on_source_up(self) -> None:
        return None


@runtime_checkable
class LoopEvents(Protocol):
    """What the frame loop tells its owner, on the loop's thread (``source_down`` may also come from
    the opening timer's thread)."""

    def opened(self, description: str, again: bool) -> None:
        """The source opened (``again``: after a failure)."""
        ...

    def failed(self, message: str, ended: bool) -> None:
        """The source failed or could not be opened (``ended``: the loop ends)."""
        ...

    def note(self, message: str) -> None:
        """Something worth showing once (a source note, a pipeline or sink problem)."""
        ...

    def processed(self, frame: Frame, result: FrameResult, frames_behind: int) -> None:
        """One frame measured (``frames_behind``: frames a live camera delivered meanwhile)."""
        ...

    def source_down(self, reason: str) -> None:
        """As :meth:`Sink.on_source_down`, after the sinks heard it."""
        ...

    def source_up(self) -> None:
        """As :meth:`Sink.on_source_up`, after the sinks heard it."""
        ...


class LoopEventsBase:
    """:class:`LoopEvents` that ignore everything: subclass it and override what you need."""

    def opened(self, description: str, again: bool) -> None:
        return None

    def failed(self, message: str, ended: bool) -> None:
        return None

    def note(self, message: str) -> None:
        return None

    def processed(self, frame: Frame, result: FrameResult, frames_behind: int) -> None:
        return None

    def source_down(self, reason: str) -> None:
        return None

    def source_up(self) -> None:
        return None
