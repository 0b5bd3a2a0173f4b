"""The per-frame measurement pipeline: detect the code, select it, solve its pose, time it.

One :class:`Pipeline` serves one stream (the headless runner and the app's worker thread each
own one). :meth:`Pipeline.process` never raises for a frame: whatever goes wrong becomes the
result's ``status`` and ``reason``, so a frame loop keeps running.

Statuses (:class:`qrfield.status.ResultStatus`):
    OK      the first chosen method converged: a pose is given;
    NOQR    no code found (or none with the selected text);
    NOCONV  a code was found but the first chosen method did not converge (its reason says why), or
            its corners are not fit for a pose (not refined: the backend's own, possibly several
            px off; ``Detection.untrusted`` says why): then no method is run and no pose is given;
    ERROR   anything else (the camera model does not fit the frame, a solver raised): see reason.
Reported to other programs (``qrfield run`` output, the app), OK becomes AMBIG or SIM by the one rule
of :func:`qrfield.status.reported_status` (:meth:`FrameResult.reported_status`), as on the serial link.

A tracked code whose pose does not fit its corners (chi-square above RECHECK_CHI2) is detected
again from scratch in the same frame, and the fresh detection kept when it fits better.

After the solve, the stream stage (:class:`qrfield.stream.StreamStage`, docs/conventions.md "The
live stream") resolves an ambiguous frame's flip from the stream's recent history and, with
``filter_s`` > 0, filters the pose: ``FrameResult.poses`` holds what is reported (``ambiguous``: the
flag after history), ``FrameResult.frame_poses`` the frame's own solve, ``FrameResult.stream`` what
the stage did (``resolved_by``, ``filtered``).

Timing: ``t_ms`` is the frame's capture time in ms since the stream started (the first frame
processed, or the ``t0`` given); for a recording (a frame with ``t_media``, e.g. a video file) it
follows the recording's own clock from the frame where it began, so the stream stage sees the
recorded times however fast the file is decoded; ``latency_ms`` runs from capture to the finished
result.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from qrfield.camera import CameraModel, CameraModelError
from qrfield.geometry import Pose
from qrfield.methods import METHODS, NUMERICAL
from qrfield.solvers.result import POSE_JSON_KEYS
from qrfield.sources.base import Frame
from qrfield.status import Reported, ResultStatus, reported_status, usable_pose

# The result statuses under their old names (other modules and programs import them from here).
OK, NOQR, NOCONV, ERROR = ResultStatus.OK, ResultStatus.NOQR, ResultStatus.NOCONV, ResultStatus.ERROR
SIM = Reported.SIM
#: The statuses of a FrameResult (qrfield.status.ResultStatus).
RESULT_STATUSES = tuple(ResultStatus)
#: A tracked code whose first method's pose fits its corners worse than this chi-square (the
#: 0.9999 quantile of chi-square with 2 degrees of freedom: 1 in 10^4 of frames whose corners are
#: as their covariance says) is detected again from scratch in the same frame, and the fresh
#: detection kept when it fits better (:meth:`Pipeline._recheck`). Tracked fits can settle wrong
#: in a fast swing: ``qrfield benchmark stream``, "fast swing far 1.4 px", seed 172, frame 10:
#: V3 and V4 3 px off with a std of 0.3 px, chi-square 21, where a fresh detection puts every
#: corner within 0.04 px. Above FIT_CHI2 (9.21, qrfield.solvers.uncertainty) rather than at it:
#: a detection from scratch costs several tracked frames, and 1 % of right fits lie above 9.21.
RECHECK_CHI2 = 18.42


@dataclass
class FrameResult:
    """What the pipeline made of one frame.

    Attributes:
        index: the frame's index in its stream.
        t_ms: capture time in ms since the stream started.
        status: one of RESULT_STATUSES; reason: why, when not OK ("" when OK).
        detection: the selected code (qrfield.detect.Detection: corners_px (4, 2) V1..V4, text, ...)
            or None.
        detections: every code found in the frame.
        poses: method name -> qrfield.solvers.PoseResult, in the order the methods were asked.
        truth: the true pose for the virtual bench, else None.
        latency_ms: capture to finished result; detect_ms, solve_ms: time spent in each step.
        label: the frame's label (file name, ...).
        camera: the camera model used for this frame (scaled to the frame's size).
        t_capture: time.monotonic() s of the frame's capture (the serial line's age_ms counts from it).
        stream: method name -> qrfield.stream.StreamMark (``resolved_by``, ``filtered``) for each
            method with a usable pose; frame_poses: the frame's own solver results before the
            stream stage (``poses`` holds what is reported).
    """

    index: int
    t_ms: int
    status: str
    reason: str = ""
    detection: Any = None
    detections: list[Any] = field(default_factory=list)
    poses: dict[str, Any] = field(default_factory=dict)
    truth: Pose | None = None
    latency_ms: float = math.nan
    detect_ms: float = 0.0
    solve_ms: float = 0.0
    label: str = ""
    camera: CameraModel | None = None
    t_capture: float = math.nan
    stream: dict[str, Any] = field(default_factory=dict)
    frame_poses: dict[str, Any] = field(default_factory=dict)

    @property
    def primary(self) -> Any:
        """The first method's PoseResult, or None."""
        return next(iter(self.poses.values()), None)

    @property
    def ambiguous(self) -> bool:
        """The first method's pose is usable and its flip (mirror) ambiguity is unresolved after the
        stream's history (the stream stage sets the reported pose's ``ambiguous`` to that)."""
        primary = self.primary
        return usable_pose(primary) and bool(getattr(primary, "ambiguous", False))

    def _mark(self) -> Any:
        """The stream stage's mark of the first method (None without a usable pose)."""
        return self.stream.get(next(iter(self.poses), ""))

    @property
    def resolved_by(self) -> str | None:
        """How the first method's flip was decided: "frame" or "history" (None without a pose)."""
        mark = self._mark()
        if mark is not None:
            return mark.resolved_by
        return "frame" if usable_pose(self.primary) else None

    @property
    def filtered(self) -> bool:
        """The first method's pose is the stream filter's (earlier frames were used)."""
        mark = self._mark()
        return bool(mark is not None and mark.filtered)

    def converged_pose(self, method: str) -> Pose | None:
        """The converged pose of ``method`` as a Pose (mm, degrees), else None."""
        result = self.poses.get(method)
        if not usable_pose(result):
            return None
        return Pose(result.position_mm, result.angles_deg)

    def reported_status(self, simulated: bool = False) -> Reported:
        """The status as reported to other programs (:func:`qrfield.status.reported_status`): SIM
        instead of OK when the frame did not come from a live camera (``simulated``: the virtual
        bench, a video, a folder), AMBIG for a live camera's ambiguous pose, so a program that acts
        only on OK never acts on a made-up or ambiguous pose."""
        return reported_status(self.status, live=not simulated, ambiguous=self.ambiguous)

    def to_json_dict(self, simulated: bool = False) -> dict[str, Any]:
        """One JSON line of ``qrfield run --json-lines``: the keys of ``qrfield solve --json``
        (of the first method; null when there is no pose) plus t_ms, status (SIM for a converged
        pose from a source that is not a live camera, see :meth:`reported_status`), simulated,
        reason, frame, text, latency_ms, resolved_by ("frame" or "history", null without a pose)
        and filtered (docs/conventions.md, "The live stream"); ``methods`` (every method's result,
        each with its own resolved_by and filtered) when more than one ran; ``truth`` on the
        virtual bench. ``ambiguous`` is the flag after the stream's history."""
        primary = self.primary
        out: dict[str, Any] = dict.fromkeys(POSE_JSON_KEYS)
        if primary is not None:
            out.update(primary.to_json_dict())
        elif self.detection is not None:
            out["corners"] = [[float(u), float(v)] for u, v in self.detection.corners_px]
        out.update(
            t_ms=self.t_ms,
            status=str(self.reported_status(simulated)),
            simulated=bool(simulated),
            reason=self.reason,
            frame=self.index,
            text=None if self.detection is None else self.detection.text,
            latency_ms=None if not math.isfinite(self.latency_ms) else round(self.latency_ms, 3),
            resolved_by=self.resolved_by,
            filtered=self.filtered,
        )
        if len(self.poses) > 1:
            out["methods"] = {name: self._method_json(name, result) for name, result in self.poses.items()}
        if self.truth is not None:
            out["truth"] = {
                "position_mm": [float(v) for v in self.truth.position_mm],
                "angles_deg": [float(v) for v in self.truth.angles_deg],
            }
        if self.label:
            out["label"] = self.label
        return out

    def _method_json(self, name: str, result: Any) -> dict[str, Any]:
        mark = self.stream.get(name)
        out = result.to_json_dict()
        out["resolved_by"] = (
            mark.resolved_by if mark is not None else ("frame" if usable_pose(result) else None)
        )
        out["filtered"] = bool(mark is not None and mark.filtered)
        return out

    def summary(self, simulated: bool = False) -> str:
        """One compact human line: frame, time, status (:meth:`reported_status`), each method's pose
        and what the live stream did (``[flip from history]``, ``[filtered]``)."""
        line = f"#{self.index:<5d} t={self.t_ms / 1000:8.3f}s {self.reported_status(simulated):<6s}"
        for k, (name, pose) in enumerate(self.poses.items()):
            if not np.all(np.isfinite(pose.position_mm)):
                line += f"{' |' if k else ''} {name}: no pose"
                continue
            x, y, z = pose.position_mm
            a, b, g = pose.angles_deg
            prefix = "" if len(self.poses) == 1 else f"{' |' if k else ''} {name}:"
            line += (
                f"{prefix} x={x:7.1f} y={y:7.1f} z={z:7.1f} mm a={a:7.2f} b={b:7.2f} g={g:7.2f} deg"
                f" n={pose.iterations} rep={pose.reprojection_px:.2f}px"
            )
        if self.reason:
            line += f"  ({self.reason})"
        if self.resolved_by == "history":
            line += "  [flip from history]"
        if self.filtered:
            line += "  [filtered]"
        return line + f"  lat={self.latency_ms:.1f}ms"


class Pipeline:
    """Detect, select and solve, frame after frame, for one stream.

    Args:
        camera: the camera model (rescaled automatically when frames come at another resolution
            of the same aspect ratio).
        side_mm: the QR symbol's side L, mm.
        methods: pose methods to run, a subset of METHODS in order; the first gives the status.
        solver_settings: method -> its settings dataclass (NumericalSettings, IppeSettings).
        detector_settings: qrfield.detect.DetectorSettings (None = defaults); its ``select_text``
            chooses the code (only one with this payload counts, "" = any; see
            qrfield.detect.select_code).
        t0: stream start, time.monotonic() s (None = the first frame's capture time).
        stream: qrfield.stream.StreamSettings for the stream stage after the solve (None = the
            defaults: branch continuity on, no filter).
        tracker, solve, select: replace qrfield.detect.Tracker(settings), qrfield.solvers.solve
            (called with the ``corners_cov`` keyword: the detection's ``pose_cov``) and
            qrfield.detect.select_code (tests, other detectors).
    """

    def __init__(
        self,
        camera: CameraModel,
        side_mm: float,
        methods: Sequence[str] = (NUMERICAL,),
        *,
        solver_settings: dict[str, Any] | None = None,
        detector_settings: Any = None,
        t0: float | None = None,
        stream: Any = None,
        tracker: Any = None,
        solve: Callable[..., Any] | None = None,
        select: Callable[..., Any] | None = None,
    ) -> None:
        if not isinstance(camera, CameraModel):
            raise TypeError(f"camera must be a CameraModel, got {type(camera).__name__}")
        if not math.isfinite(side_mm) or side_mm <= 0:
            raise ValueError(f"QR side must be a positive length in mm, got {side_mm!r}")
        methods = tuple(methods)
        if not methods or any(m not in METHODS for m in methods) or len(set(methods)) != len(methods):
            raise ValueError(f"methods must be distinct names from {', '.join(METHODS)}, got {methods!r}")
        self.camera = camera
        self.side_mm = float(side_mm)
        self.methods = methods
        self.solver_settings = dict(solver_settings or {})
        self.select_text = str(getattr(detector_settings, "select_text", "") or "")
        self.t0 = t0
        self._media_anchor: tuple[float, float] | None = None  # (t_ms, t_media s) where a recording began
        self._last_media = -math.inf
        self._last_t_ms = -math.inf
        self._own_tracker = tracker is None
        if tracker is None or select is None:
            from qrfield import detect

            tracker = (
                tracker
                if tracker is not None
                else detect.Tracker(detector_settings or detect.DetectorSettings())
            )
            select = select or detect.select_code
        # The default solves every method in one call (what they share is done once).
        self._solve_methods = None
        if solve is None:
            from qrfield.solvers import solve, solve_methods

            self._solve_methods = solve_methods
        self._tracker = tracker
        self._detector_settings = detector_settings
        self._solve = solve
        self._select = select
        self._scaled: dict[tuple[int, int], CameraModel | str] = {}
        from qrfield.stream import StreamStage

        self.stream = StreamStage(stream)

    def camera_for(self, size: tuple[int, int]) -> CameraModel:
        """The camera model at ``size`` (width, height); CameraModelError if the aspect differs."""
        if size == self.camera.size:
            return self.camera
        cached = self._scaled.get(size)
        if cached is None:
            try:
                cached = self.camera.scaled(*size)
            except CameraModelError as exc:
                cached = str(exc)
            self._scaled[size] = cached
        if isinstance(cached, str):
            raise CameraModelError(cached)
        return cached

    def process(self, frame: Frame) -> FrameResult:
        """Detect, select and solve one frame; never raises (problems become status and reason)."""
        t_ms = self._stream_ms(frame)
        result = FrameResult(
            frame.index, t_ms, NOQR, truth=frame.truth, label=frame.label, t_capture=frame.t_capture
        )
        try:
            self._process(frame, result)
        except Exception as exc:  # never raise per frame: a broken frame is a status, not a crash
            result.status, result.reason = ERROR, f"{type(exc).__name__}: {exc}"
        result.latency_ms = (time.monotonic() - frame.t_capture) * 1000.0
        return result

    def _stream_ms(self, frame: Frame) -> int:
        """The frame's ``t_ms``: ms since the stream started, on the capture clock, or for a
        recording (``frame.t_media`` set) on its own clock from the frame where it began; a recording
        whose clock steps back (it started again) begins anew a second after the last frame."""
        if self.t0 is None:
            self.t0 = frame.t_capture
        wall_ms = (frame.t_capture - self.t0) * 1000.0
        media = frame.t_media
        if media is None or not math.isfinite(media):
            self._media_anchor = None
            t_ms = wall_ms
        else:
            anchor = self._media_anchor
            if anchor is None or media < self._last_media:
                start = max(wall_ms, self._last_t_ms + 1000.0)  # -inf: the stream's first frame
                anchor = self._media_anchor = (start, media)
            self._last_media = media
            t_ms = anchor[0] + (media - anchor[1]) * 1000.0
        self._last_t_ms = max(self._last_t_ms, t_ms)
        return max(0, round(t_ms))

    def _process(self, frame: Frame, result: FrameResult) -> None:
        try:
            camera = self.camera_for(frame.size)
        except CameraModelError as exc:
            result.status, result.reason = ERROR, f"camera model does not fit the frame: {exc}"
            return
        result.camera = camera
        set_camera = getattr(self._tracker, "set_camera", None)
        if set_camera is not None:  # the detector fits the symbol through this camera's lens
            set_camera(camera)
        t = time.perf_counter()
        result.detections = list(self._tracker.update(frame.image))
        result.detection = self._select(result.detections, self.select_text)
        result.detect_ms = (time.perf_counter() - t) * 1000.0
        if result.detection is None:
            found = len(result.detections)
            result.reason = (
                "no QR code found"
                if not found
                else f"{found} code(s) found, none with the text {self.select_text!r}"
            )
            return
        t = time.perf_counter()
        if not self._solved(result, camera):
            return
        if self._misfit_tracked(result):  # the tracked corners are not the code's: look again
            self._recheck(frame, result, camera)
        self.stream.apply(
            result, self.side_mm, self._corners_cov(result)
        )  # the flip from history, the filter
        result.solve_ms = (time.perf_counter() - t) * 1000.0

    @staticmethod
    def _corners_cov(result: FrameResult) -> Any:
        """The fit's covariance, or the one assumed for corners without (Detection.pose_cov)."""
        return getattr(result.detection, "pose_cov", getattr(result.detection, "corners_cov", None))

    def _solved(self, result: FrameResult, camera: CameraModel) -> bool:
        """Solve ``result.detection`` with every method into ``result.poses`` and set the status;
        False when the detection is untrusted (status NOCONV, nothing solved)."""
        untrusted = getattr(result.detection, "untrusted", "")
        if untrusted:
            result.status, result.reason = NOCONV, untrusted
            return False
        cov = self._corners_cov(result)
        errors = []
        result.poses = {}
        if self._solve_methods is not None:
            try:
                result.poses = self._solve_methods(
                    result.detection.corners_px, camera, self.side_mm, self.methods, self.solver_settings, cov
                )
            except Exception:  # then method by method, to say which one failed
                result.poses = {}
        for method in self.methods if not result.poses else ():
            try:
                result.poses[method] = self._solve(
                    result.detection.corners_px,
                    camera,
                    self.side_mm,
                    method=method,
                    settings=self.solver_settings.get(method),
                    corners_cov=cov,
                )
            except Exception as exc:  # one method failing must not hide the other's answer
                errors.append(f"{method}: {type(exc).__name__}: {exc}")
        primary = result.poses.get(self.methods[0])
        if primary is None:
            result.status, result.reason = ERROR, "; ".join(errors)
        elif primary.converged:
            result.status, result.reason = OK, "; ".join(errors)
        else:
            result.status, result.reason = NOCONV, primary.reason or f"{primary.method} did not converge"
        return True

    def _misfit_tracked(self, result: FrameResult) -> bool:
        """The selected code was followed by the tracker (backend "track") and the first method's
        pose fits its corners worse than RECHECK_CHI2."""
        primary = result.poses.get(self.methods[0])
        chi2 = float(getattr(primary, "chi2", math.nan))
        tracked = getattr(result.detection, "backend", "") == "track"
        return tracked and math.isfinite(chi2) and chi2 > RECHECK_CHI2

    def _recheck(self, frame: Frame, result: FrameResult, camera: CameraModel) -> None:
        """Detect ``frame`` again from scratch (the tracker's ``recheck``, when it has one) and keep
        that detection and its poses when its first method fits it better than the tracked one's;
        else the tracked result stands (the stream stage widens its std by its misfit)."""
        recheck = getattr(self._tracker, "recheck", None)
        if recheck is None:
            return
        detections = list(recheck(frame.image))
        chosen = self._select(detections, self.select_text)
        if chosen is None:
            return
        trial = replace(result, detections=detections, detection=chosen, poses={})
        if not self._solved(trial, camera):
            return
        before = result.poses.get(self.methods[0])
        after = trial.poses.get(self.methods[0])
        if after is None or not after.converged or not float(after.chi2) < float(before.chi2):
            return
        result.detections, result.detection, result.poses = trial.detections, chosen, trial.poses
        result.status, result.reason = trial.status, trial.reason

    def reset(self, t0: float | None = None) -> None:
        """Start a new stream: the clock restarts, the tracker forgets the last code and the stream
        stage its history and filter."""
        self.t0 = t0
        self._media_anchor = None
        if t0 is None:
            self._last_t_ms = -math.inf
        self.stream.reset()
        reset = getattr(self._tracker, "reset", None)
        if callable(reset):
            reset()
        elif self._own_tracker:
            from qrfield import detect

            self._tracker = detect.Tracker(self._detector_settings or detect.DetectorSettings())
