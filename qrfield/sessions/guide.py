"""The guide of a planned experiment: the live difference to the target, stillness, and its rows.

:class:`Guide` is a frame sink of the core's frame loop (:class:`qrfield.engine.FrameLoop`: its
``on_result(result, simulated)`` sees every processed frame on the loop's thread, in the app as in
``qrfield session run-plan``), not a reader of what a window drew. For each frame it takes the
session solver's pose and keeps, under one lock:

- the difference measured - target per DOF (x, y, z mm; alpha, beta, gamma degrees, wrapped; the
  Euclidean distance), graded GOOD / NEAR / FAR against the session's acceptance criteria
  (:meth:`qrfield.sessions.criteria.AcceptanceCriteria.grade`): over the current still run's mean
  (:mod:`qrfield.sessions.stillness`), which is the newest frame right after a move;
- the stillness (:class:`~qrfield.sessions.stillness.StillnessDetector`);
- a row being collected: the next ``frames_per_row`` frames (a
  :class:`~qrfield.sessions.FrameCollector` for the session's solver), averaged and judged against
  the ground truth given (the target, or what the operator typed) exactly as "Log row" does.

A row is collected when the owner asks (:meth:`Guide.arm`: at once, a tap; or once still, the
terminal's Enter) or, with ``auto`` on, by itself when the card is still, **after it has moved
since the target was set** (so the pose the last row was logged at is not logged again for the next
target) and when every DOF's difference lies within ``auto_gate`` times the criteria (so a card
left at another target is not logged for this one; a tap still logs it). A finished row waits in
:meth:`Guide.take` for the owner, which logs it (:meth:`qrfield.sessions.Session.log`, on its own
thread) and saves the plan's progress. ``view()`` is the snapshot a screen or a terminal shows.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from qrfield.seams import BaseSink
from qrfield.sessions.averaging import FrameCollector, Measurement
from qrfield.sessions.criteria import AcceptanceCriteria, Grades
from qrfield.sessions.groundtruth import GroundTruth
from qrfield.sessions.plan import PlanTarget
from qrfield.sessions.stillness import Stillness, StillnessDetector, StillnessSettings, pose_difference
from qrfield.settings import setting


@dataclass(frozen=True)
class GuideSettings:
    """When the guide logs by itself."""

    auto_gate: float = setting(
        3.0,
        label="auto-log gate",
        unit="x criteria",
        minimum=0.0,
        maximum=1000.0,
        decimals=1,
        help="log automatically only when every difference to the target is within this many times "
        "the acceptance criteria (0 = at any difference); a tap logs at any difference",
    )
    still_timeout_s: float = setting(
        60.0,
        label="wait for still",
        unit="s",
        minimum=1.0,
        maximum=3600.0,
        decimals=0,
        help="a row asked for 'once still' (the terminal's Enter, the virtual bench) is given up when "
        "the card is not still within this long",
    )


@dataclass(frozen=True)
class GuideView:
    """What the guide knows now (a snapshot; arrays are copies).

    ``difference``: (6,) measured - truth (x, y, z mm; alpha, beta, gamma deg) over the still run's
    mean, NaN without a pose; ``grades``: their grades, None without a pose. ``collecting``:
    (frames in, frames wanted) while a row is collected, else None. ``waiting``: a row is asked
    for once the card is still. ``auto_reason``: why auto-logging does not log now ("" when it
    would, or when auto is off). ``problem``: the last row given up (frames stopped), "" if none.
    """

    target: PlanTarget | None
    truth: GroundTruth | None
    difference: np.ndarray
    grades: Grades | None
    stillness: Stillness
    collecting: tuple[int, int] | None
    waiting: bool
    auto: bool
    auto_reason: str
    frames_seen: int
    problem: str = ""


@dataclass(frozen=True)
class GuidedRow:
    """A finished row: the target it was measured for and its measurement (truth, average, verdict)."""

    target: PlanTarget | None
    measurement: Measurement


@dataclass
class _Request:
    truth: GroundTruth
    note: str
    target: PlanTarget | None
    when_still: bool
    collector: FrameCollector | None = None
    frames: list[Any] = field(default_factory=list)


class Guide(BaseSink):
    """See the module docstring. A :class:`qrfield.seams.Sink` of the frame loop. Thread-safe:
    frames come on the loop's thread, the owner calls the rest from its own."""

    def __init__(
        self,
        method: str,
        criteria: AcceptanceCriteria | None = None,
        frames_per_row: int = 10,
        stillness: StillnessSettings | None = None,
        settings: GuideSettings | None = None,
    ) -> None:
        self._lock = threading.Lock()
        self._ready_event = threading.Event()
        self.method = method
        self.criteria = criteria or AcceptanceCriteria()
        self.frames_per_row = int(frames_per_row)
        self.settings = settings or GuideSettings()
        self._detector = StillnessDetector(stillness)
        self._target: PlanTarget | None = None
        self._truth: GroundTruth | None = None
        self._note = ""
        self._auto = False
        self._moves_mark = 0  # the detector's moves when the target was set or the last row was taken
        self._request: _Request | None = None
        self._ready: list[GuidedRow] = []
        self._frames_seen = 0
        self._problem = ""

    # ---------------------------------------------------------------- the owner's thread
    def configure(
        self,
        *,
        method: str | None = None,
        criteria: AcceptanceCriteria | None = None,
        frames_per_row: int | None = None,
        stillness: StillnessSettings | None = None,
        settings: GuideSettings | None = None,
    ) -> None:
        """Another session's solver, criteria or frames per row, or other settings (a row being
        collected is given up)."""
        with self._lock:
            self._request = None
            if method is not None:
                self.method = method
            if criteria is not None:
                self.criteria = criteria
            if frames_per_row is not None:
                self.frames_per_row = int(frames_per_row)
            if settings is not None:
                self.settings = settings
            if stillness is not None and stillness != self._detector.settings:
                self._detector = StillnessDetector(stillness)
                self._moves_mark = 0

    @property
    def stillness_settings(self) -> StillnessSettings:
        return self._detector.settings

    def set_target(
        self, target: PlanTarget | None, truth: GroundTruth | None = None, note: str | None = None
    ) -> None:
        """The target to guide to (None: no plan, or the plan is done). ``truth``: the ground truth
        the row will carry (default: the target's pose); ``note``: the row's note (default: the
        target's). A row being collected for another target is given up."""
        with self._lock:
            if self._request is not None and self._request.target != target:
                self._request = None
            if target != self._target:
                self._moves_mark = self._detector.moves
            self._target = target
            self._truth = truth or (target.truth if target is not None else None)
            self._note = note if note is not None else (target.note if target is not None else "")

    def set_truth(self, truth: GroundTruth | None, note: str | None = None) -> None:
        """The operator edited the ground truth (e.g. the jig reads differently): the difference and
        the next row use it. None = back to the target's pose."""
        with self._lock:
            self._truth = truth or (self._target.truth if self._target is not None else None)
            if note is not None:
                self._note = note

    def set_auto(self, on: bool) -> None:
        with self._lock:
            self._auto = bool(on)

    def arm(self, *, when_still: bool = False) -> bool:
        """Collect a row for the current target: from the next frame (a tap), or ``when_still``,
        once the card has been still for the hold time counted from the next frame (the terminal's
        Enter: the hold starts after the operator says the jig is set). False without a target
        and truth, or while a row is collected."""
        with self._lock:
            if self._truth is None or self._request is not None:
                return False
            self._problem = ""
            self._request = _Request(self._truth, self._note, self._target, when_still)
            if when_still:
                self._detector.restart("waiting for the card to be still")
            else:
                self._start_collecting(self._request)
            return True

    def cancel(self) -> bool:
        """Give up the row being collected or waited for (nothing logged); True if there was one."""
        with self._lock:
            had, self._request = self._request is not None, None
            return had

    def take(self) -> list[GuidedRow]:
        """The rows finished since the last call, in order (the owner logs them)."""
        with self._lock:
            rows, self._ready = self._ready, []
            self._ready_event.clear()
            return rows

    def wait(self, timeout_s: float) -> bool:
        """Block until a row is finished or ``timeout_s`` passed; True when one is ready."""
        return self._ready_event.wait(timeout_s)

    def view(self) -> GuideView:
        with self._lock:
            return self._view()

    # ---------------------------------------------------------------- the frame loop's thread
    def on_result(self, result: Any, simulated: bool = True) -> None:
        """One processed frame (qrfield.pipeline.FrameResult: ``t_ms``, ``poses``)."""
        pose = result.poses.get(self.method) if getattr(result, "poses", None) else None
        t_s = float(result.t_ms) / 1000.0
        with self._lock:
            self._frames_seen += 1
            state = self._detector.add(t_s, pose)
            request = self._request
            if request is not None:
                if request.collector is not None:
                    if request.collector.add(result):
                        self._finish(request)
                elif state.still:
                    self._start_collecting(request)
            elif self._auto and state.still and not self._auto_reason(state):
                self._request = _Request(self._truth, self._note, self._target, False)  # type: ignore[arg-type]
                self._start_collecting(self._request)

    def on_source_down(self, reason: str) -> None:
        """No frames: a row being collected is given up (nothing logged), stillness starts over."""
        with self._lock:
            if self._request is not None:
                got = len(self._request.collector.frames) if self._request.collector is not None else 0
                self._problem = f"row not logged: no frames ({reason}); {got} of {self.frames_per_row} came"
                self._request = None
            self._detector.restart(f"no frames: {reason}")

    # ---------------------------------------------------------------- internals (under the lock)
    def _start_collecting(self, request: _Request) -> None:
        request.collector = FrameCollector(self.frames_per_row, method=self.method)

    def _finish(self, request: _Request) -> None:
        assert request.collector is not None
        measurement = request.collector.measurement(request.truth, self.criteria, note=request.note)
        self._ready.append(GuidedRow(request.target, measurement))
        self._request = None
        self._moves_mark = self._detector.moves  # the next automatic row needs another move
        self._ready_event.set()

    def _difference(self, state: Stillness) -> np.ndarray:
        if self._truth is None:
            return np.full(6, np.nan)
        truth = np.array([*self._truth.position_mm, *self._truth.angles_deg], dtype=float)
        return pose_difference(state.mean, truth)

    def _auto_reason(self, state: Stillness) -> str:
        if not self._auto:
            return ""
        if self._truth is None:
            return "no target"
        if self._detector.moves <= self._moves_mark:
            return "move the card to the target first (it has not moved since the last row)"
        if not state.still:
            return state.reason or "not still"
        gate = self.settings.auto_gate
        if gate > 0:
            d = self._difference(state)
            c = self.criteria
            limits = np.array([c.max_position_error_mm] * 3 + [c.max_angle_error_deg] * 3) * gate
            if not np.all(np.abs(d) <= limits):
                return (
                    f"the pose is more than {gate:g} x the criteria from the target: tap Log to log it anyway"
                )
        return ""

    def _view(self) -> GuideView:
        state = self._detector.state
        difference = self._difference(state)
        grades = (
            self.criteria.grade(difference[:3], difference[3:]) if np.all(np.isfinite(difference)) else None
        )
        request = self._request
        collecting = None
        if request is not None and request.collector is not None:
            collecting = request.collector.progress
        return GuideView(
            target=self._target,
            truth=self._truth,
            difference=difference,
            grades=grades,
            stillness=state,
            collecting=collecting,
            waiting=request is not None and request.collector is None,
            auto=self._auto,
            auto_reason=self._auto_reason(state) if self._auto and request is None else "",
            frames_seen=self._frames_seen,
            problem=self._problem,
        )


def difference_text(view: GuideView) -> str:
    """One line for a terminal: the difference per DOF with its grade, and the stillness."""
    if view.grades is None:
        return f"no pose ({view.stillness.reason})"
    d = view.difference
    marks = {"good": "ok", "near": "~", "far": "!!"}
    g = view.grades
    parts = [f"{name} {d[k]:+.1f}{marks[g.position[k]]}" for k, name in enumerate("xyz")]
    parts += [f"{name} {d[3 + k]:+.2f}{marks[g.angles[k]]}" for k, name in enumerate(("a", "b", "g"))]
    still = (
        "still"
        if view.stillness.still
        else f"settling {view.stillness.held_s:.1f}/{view.stillness.hold_s:.1f} s"
    )
    return f"{' '.join(parts)} | {g.distance_mm:.1f} mm | {still}"
