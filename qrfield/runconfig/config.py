"""RunConfig: everything a frame loop needs, resolved; what reopens the source or rebuilds the pipeline."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class RunConfig:
    """Everything a frame loop needs, resolved (a camera model, a tuple of methods).

    Attributes:
        source: the ``--source`` spec; camera: the camera model; side_mm: QR side, mm;
        methods: pose methods in order (the first gives the status); solver_settings: method ->
        its settings; detector_settings: DetectorSettings (its ``select_text`` picks the code);
        virtual, picamera, usb: those sources' settings (picamera None = sized from the camera
        model);
        loop, pace: for files and folders; retry_s: reopen a failed source after this long
        (0 = do not); allow_virtual: ``auto`` may fall back to the virtual bench;
        stream: qrfield.stream.StreamSettings (branch continuity, the filter; None = defaults).
    """

    source: str
    camera: Any
    side_mm: float
    methods: tuple[str, ...]
    solver_settings: dict[str, Any] = field(default_factory=dict)
    detector_settings: Any = None
    virtual: Any = None
    loop: bool = False
    picamera: Any = None
    usb: Any = None
    pace: bool = False
    retry_s: float = 0.0
    allow_virtual: bool = True
    stream: Any = None

    def source_key(self) -> tuple[Any, ...]:
        """What requires reopening the source when it changes."""
        from qrfield.sources.kinds import AUTO, PICAMERA2, PICAMERA2_SIM, USB, VIRTUAL, source_kind

        kind = source_kind(self.source)
        bench = (self.camera, self.side_mm) if kind in (VIRTUAL, AUTO) else ()
        usb = (self.camera.size, self.usb) if kind in (USB, AUTO) else ()
        # picamera2 derives the stream's model from the profile at open: a new profile reopens it.
        pi = (self.camera, self.picamera) if kind in (PICAMERA2, PICAMERA2_SIM, AUTO) else ()
        sim = (self.virtual, self.side_mm) if kind == PICAMERA2_SIM else ()
        return (self.source, self.loop, self.pace, self.allow_virtual, *bench, *usb, *pi, *sim)

    def pipeline_key(self) -> tuple[Any, ...]:
        """What requires a new pipeline when it changes."""
        return (
            self.camera,
            self.side_mm,
            self.methods,
            tuple(sorted(self.solver_settings.items())),
            self.detector_settings,
            self.stream,
        )

    def make_pipeline(self, camera: Any = None) -> Any:
        """A :class:`qrfield.pipeline.Pipeline` for these settings (ValueError if they do not fit);
        ``camera``: the stream's own model (a picamera2 stream's, through its crop) instead of
        the named one."""
        from qrfield.pipeline import Pipeline

        return Pipeline(
            camera if camera is not None else self.camera,
            self.side_mm,
            self.methods,
            solver_settings=self.solver_settings,
            detector_settings=self.detector_settings,
            stream=self.stream,
        )

    def open_source(self, opener: Callable[..., Any] | None = None) -> Any:
        """The source, opened (SourceError if it cannot be); ``opener`` replaces open_source."""
        from qrfield import sources

        kwargs: dict[str, Any] = dict(
            camera=self.camera,
            side_mm=self.side_mm,
            virtual=self.virtual,
            picamera=self.picamera,
            usb=self.usb,
            loop=self.loop,
            pace=self.pace,
        )
        if not self.allow_virtual:
            kwargs["allow_virtual"] = False
        return (opener or sources.open_source)(self.source, **kwargs)
