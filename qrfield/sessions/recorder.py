"""The one row recorder: session rows collected from a frame loop (the app, ``session log``, the guide).

:class:`RowRecorder` is a sink of the core's frame loop (:class:`qrfield.seams.BaseSink`): the loop
hands it every processed frame on the loop's thread (``on_result``), so a row averages the frames
the loop measured, not the ones a window happened to draw. Its owner (the app's Session tab, the
``session log`` command, the guide of a planned experiment) asks for one row at a time:

- :meth:`RowRecorder.arm`: the row's ground truth, frames wanted, solver, criteria, note, and
  whether the truth is the virtual bench's mean true pose over the row's frames (``follow_bench``:
  :func:`bench_mean_truth`). Only frames captured after the call count
  (``FrameResult.t_capture``, ``time.monotonic()`` s), collected by a
  :class:`~qrfield.sessions.FrameCollector` for the row's solver;
- once the N frames are in, they are averaged and judged with the row's criteria
  (:meth:`FrameCollector.measurement`, on the loop's thread) and the finished row, a
  :class:`RecordedRow`, waits in :meth:`RowRecorder.take` / :meth:`RowRecorder.wait` for the owner,
  which logs it with :meth:`qrfield.sessions.Session.log` on its own thread;
- a row is given up, nothing measured, when the owner cancels it (:meth:`cancel`) or gives it up
  (:meth:`give_up`, e.g. the source failed), when no frame came for the row's ``frame_timeout_s``
  (:meth:`expire`, which the owner calls from its timer), or, for a row without a frame timeout,
  as soon as the loop says the source is down (``on_source_down``).

:meth:`RowRecorder.measure` does all of it for a terminal (arm, wait, return the measurement).
:func:`session_run_config` is the run configuration a session's rows are measured with.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.mailbox import Handoff
from qrfield.methods import NUMERICAL
from qrfield.runconfig import RunConfig
from qrfield.seams import BaseSink
from qrfield.sessions.averaging import FrameCollector, Measurement, circular_mean_deg
from qrfield.sessions.criteria import AcceptanceCriteria
from qrfield.sessions.groundtruth import GroundTruth
from qrfield.sessions.store import SessionInfo

#: Why a row following the bench has no truth (its frames carry no true pose).
NO_BENCH_TRUTH = "the frames carry no true pose: following the bench needs the virtual bench as the source"


def session_run_config(base: RunConfig, info: SessionInfo) -> RunConfig:
    """``base`` (source, detector, source settings from the run configuration) measuring with the
    session's own camera model, QR side, solver and solver settings (what its rows claim)."""
    import dataclasses

    from qrfield.settings import from_dict
    from qrfield.solvers import settings_class

    settings = from_dict(settings_class(info.solver), info.solver_settings, strict=False)
    return dataclasses.replace(
        base,
        camera=info.camera,
        side_mm=info.side_mm,
        methods=(info.solver,),
        solver_settings={info.solver: settings},
    )


def bench_mean_truth(frames: list[Any], combo: str, method: str) -> GroundTruth | None:
    """The mean true pose of the virtual bench (FrameResult.truth: mm and degrees; angles by circular
    mean) over the collected frames that the row's mean is made of (those where ``method``
    converged; all of them if none did), so that a wobbling bench is compared with where it was
    while the row was measured. None if a frame has no truth (not the virtual bench)."""
    if not frames or any(getattr(f, "truth", None) is None for f in frames):
        return None
    averaged = [f for f in frames if _converged(f.poses.get(method))]
    truths = [f.truth for f in averaged or frames]
    position = np.mean([t.position_mm for t in truths], axis=0)
    angles = np.array([t.angles_deg for t in truths], dtype=float)
    alpha, beta, gamma = (circular_mean_deg(angles[:, k]) for k in range(3))
    return GroundTruth(*(float(v) for v in position), alpha, beta, gamma, combo)


def _converged(pose: Any) -> bool:
    """The test average_frames applies: converged with a finite position and angles."""
    return (
        pose is not None
        and bool(pose.converged)
        and bool(np.all(np.isfinite(pose.position_mm)) and np.all(np.isfinite(pose.angles_deg)))
    )


@dataclass(frozen=True)
class RowRequest:
    """What one row is asked for (see :meth:`RowRecorder.arm`).

    ``truth``: the ground truth (mm, degrees), or the fallback when ``follow_bench`` finds no true
    pose (None: then the row is refused with :data:`NO_BENCH_TRUTH`); ``combo``: the combination of a
    followed truth when ``truth`` is None; ``frame_timeout_s``: no frame for this long gives the row
    up (None: the source going down does); ``tag``: the owner's (the guide's target);
    ``captured_after``: ``time.monotonic()`` s before which frames do not count.
    """

    truth: GroundTruth | None
    frames: int
    method: str
    criteria: AcceptanceCriteria
    note: str = ""
    follow_bench: bool = False
    combo: str = ""
    frame_timeout_s: float | None = None
    tag: Any = None
    captured_after: float = -math.inf


@dataclass(frozen=True)
class RecordedRow:
    """A row that ended: its measurement, or why there is none (``problem``). ``stopped``: it was
    given up because frames stopped or it was cancelled (rather than refused: no bench truth)."""

    request: RowRequest
    measurement: Measurement | None
    frames_in: int
    problem: str = ""
    stopped: bool = False

    @property
    def frames_wanted(self) -> int:
        return self.request.frames


class RowRecorder(BaseSink):
    """See the module docstring. A :class:`qrfield.seams.Sink` of the frame loop; thread-safe
    (frames come on the loop's thread, the owner calls the rest from its own).

    ``info``: the session whose solver, criteria and frames per row a row gets unless
    :meth:`arm` says otherwise (None: ``method`` "numerical", default criteria, 10 frames).
    """

    def __init__(self, info: SessionInfo | None = None) -> None:
        self.info = info
        self._lock = threading.Lock()
        self._ended: Handoff[RecordedRow] = Handoff()  # rows that ended by themselves
        self._request: RowRequest | None = None
        self._collector: FrameCollector | None = None
        self._t_armed = 0.0
        self._last_frame_at = 0.0  # monotonic time of the last frame seen (any frame)
        self.frames_seen = 0
        self.last_problem = ""  # why the last measure() gave no row ("" when it gave one)

    # ---------------------------------------------------------------- the owner's thread
    def arm(
        self,
        truth: GroundTruth | None,
        frames: int | None = None,
        *,
        method: str | None = None,
        criteria: AcceptanceCriteria | None = None,
        note: str = "",
        follow_bench: bool = False,
        combo: str = "",
        frame_timeout_s: float | None = None,
        tag: Any = None,
        captured_after: float | None = None,
    ) -> bool:
        """Collect a row from the next frames captured after now (or ``captured_after``); False
        while another row is being collected. Unset values come from the recorder's session."""
        info = self.info
        frames = int(frames or (info.frames_per_row if info is not None else 10))
        if frames < 1:
            raise ValueError(f"frames per row must be at least 1, got {frames}")
        if truth is None and not follow_bench:
            raise ValueError("a row needs a ground truth, or follow_bench")
        if frame_timeout_s is not None and not frame_timeout_s > 0:
            raise ValueError(f"frame_timeout_s must be > 0 s, got {frame_timeout_s!r}")
        now = time.monotonic()
        request = RowRequest(
            truth=truth,
            frames=frames,
            method=method or (info.solver if info is not None else NUMERICAL),
            criteria=criteria or (info.criteria if info is not None else AcceptanceCriteria()),
            note=note,
            follow_bench=follow_bench,
            combo=combo,
            frame_timeout_s=frame_timeout_s,
            tag=tag,
            captured_after=now if captured_after is None else float(captured_after),
        )
        with self._lock:
            if self._request is not None:
                return False
            self._request = request
            self._collector = FrameCollector(frames, method=request.method)
            self._t_armed = now
            return True

    def cancel(self) -> bool:
        """Give up the row being collected, nothing measured and nothing queued; True if there was one."""
        with self._lock:
            return self._end(None, "cancelled") is not None

    def give_up(self, why: str) -> RecordedRow | None:
        """End the row being collected because of ``why`` (the owner's reason, e.g. the source
        failed); the ended row (not queued), None if none was collected."""
        with self._lock:
            return self._end(None, why)

    def expire(self, now: float | None = None) -> RecordedRow | None:
        """Give up the row when no frame came for its ``frame_timeout_s`` (counted from the arm or
        the last frame, whichever is later); the ended row (not queued), else None."""
        now = time.monotonic() if now is None else now
        with self._lock:
            request = self._request
            if request is None or request.frame_timeout_s is None:
                return None
            quiet = now - max(self._t_armed, self._last_frame_at)
            if quiet <= request.frame_timeout_s:
                return None
            return self._end(None, f"no frame for {quiet:.1f} s")

    @property
    def collecting(self) -> bool:
        with self._lock:
            return self._request is not None

    @property
    def progress(self) -> tuple[int, int] | None:
        """(frames in, frames wanted) of the row being collected, None when none is."""
        with self._lock:
            return self._collector.progress if self._collector is not None else None

    def take(self) -> list[RecordedRow]:
        """The rows that ended by themselves since the last call (measured, or given up when the
        source went down), in order."""
        return self._ended.take()

    def wait(self, timeout_s: float) -> bool:
        """Block until a row ended by itself or ``timeout_s`` passed; True when one is ready."""
        return self._ended.wait(timeout_s)

    def measure(
        self,
        truth: GroundTruth | None,
        frames: int | None = None,
        *,
        note: str = "",
        follow_bench: bool = False,
        until: Callable[[], bool] | None = None,
        combo: str = "",
        frame_timeout_s: float | None = None,
    ) -> Measurement | None:
        """A terminal's row: collect the next ``frames`` frames (default: the session's frames per
        row), average and judge them. ``follow_bench``: the truth is the virtual bench's mean true
        pose (``truth`` may be None then; ``combo`` names the combination). ``until()`` True ends the
        wait early (the loop ended, a signal): None then. ``frame_timeout_s`` (the app's
        :class:`qrfield.sessions.criteria.SessionSettings` rule): the row waits through a gap in
        the frames up to this long and is given up after it (None then); without it, the loop's
        first "source down" (1 s without a frame) gives it up. Why a row gave None is in
        :attr:`last_problem`. ValueError when the truth was to follow the bench and the frames
        carry none."""
        self.last_problem = ""
        if not self.arm(
            truth, frames, note=note, follow_bench=follow_bench, combo=combo, frame_timeout_s=frame_timeout_s
        ):
            raise RuntimeError("a row is being collected already")
        try:
            while not self.wait(0.05):
                if until is not None and until():
                    got, wanted = self.progress or (0, 0)
                    self.last_problem = (
                        f"the frame loop ended (the source stopped or failed) after {got} of the "
                        f"row's {wanted} frames"
                    )
                    return None
                expired = self.expire() if frame_timeout_s is not None else None
                if expired is not None:
                    self.last_problem = expired.problem
                    return None
        finally:
            self.cancel()
        (row,) = self.take()
        if row.measurement is None and not row.stopped:
            raise ValueError(f"--truth virtual: {row.problem}")
        self.last_problem = row.problem if row.measurement is None else ""
        return row.measurement

    # ---------------------------------------------------------------- the frame loop's thread
    def on_result(self, result: Any, simulated: bool = True) -> None:
        """One processed frame (qrfield.pipeline.FrameResult): collected when a row is asked for
        and the frame was captured after the request (a result without a finite ``t_capture``
        counts)."""
        with self._lock:
            self.frames_seen += 1
            self._last_frame_at = time.monotonic()
            collector, request = self._collector, self._request
            if collector is None or request is None:
                return
            t_capture = float(getattr(result, "t_capture", math.nan))
            if math.isfinite(t_capture) and t_capture < request.captured_after:
                return  # captured before the row was asked for
            if collector.add(result):
                self._finish(request, collector)

    def on_source_down(self, reason: str) -> None:
        """No frames come: a row without a frame timeout is given up (nothing measured)."""
        with self._lock:
            if self._request is not None and self._request.frame_timeout_s is None:
                row = self._end(None, f"no frames ({reason})")
                if row is not None:
                    self._ended.put(row)

    # ---------------------------------------------------------------- internals (under the lock)
    def _finish(self, request: RowRequest, collector: FrameCollector) -> None:
        truth = request.truth
        if request.follow_bench:
            name = truth.combo if truth is not None else request.combo
            truth = bench_mean_truth(collector.frames, name, collector.method) or truth
        if truth is None:
            row = self._end(None, NO_BENCH_TRUTH, stopped=False)
        else:
            measurement = collector.measurement(truth, request.criteria, note=request.note)
            row = self._end(measurement, "")
        assert row is not None
        self._ended.put(row)

    def _end(
        self, measurement: Measurement | None, problem: str, *, stopped: bool = True
    ) -> RecordedRow | None:
        request, collector = self._request, self._collector
        self._request, self._collector = None, None
        if request is None:
            return None
        got = collector.progress[0] if collector is not None else 0
        return RecordedRow(request, measurement, got, problem, stopped=stopped and measurement is None)
