"""Log session rows from a running frame loop, without a screen (``qrfield session log``).

What the app's "Log row" does, for a terminal: :class:`RowRecorder` is the frame loop's event
handler; :meth:`RowRecorder.measure` arms a :class:`~qrfield.sessions.FrameCollector` for the next
N frames captured after the call (the session's solver, the session's frames per row unless
another count is given), waits for them, and averages and judges them with the session's criteria
exactly as the app does (:meth:`FrameCollector.measurement`). The row is then logged with
:meth:`Session.log` (appended and fsynced before it is reported as logged).

:func:`bench_mean_truth` is the ground truth of a row on the virtual bench: its mean true pose over
the frames the row's mean is made of (the app's "follow the bench", and ``--truth virtual``).
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from qrfield.runconfig import RunConfig
from qrfield.seams import LoopEventsBase
from qrfield.sessions.averaging import FrameCollector, Measurement, circular_mean_deg
from qrfield.sessions.groundtruth import GroundTruth
from qrfield.sessions.store import SessionInfo


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


class RowRecorder(LoopEventsBase):
    """A frame loop's event handler that collects frames for one row at a time (thread-safe).

    ``say(text)`` receives the loop's messages (source opened or failed, notes).
    """

    def __init__(self, info: SessionInfo, say: Any = None) -> None:
        self.info = info
        self.say = say or (lambda text: None)
        self._lock = threading.Lock()
        self._collector: FrameCollector | None = None
        self._t_armed = 0.0
        self._done = threading.Event()
        self.frames_seen = 0

    # ----- frame loop events (the loop's thread)
    def opened(self, description: str, again: bool) -> None:
        self.say(f"source {'reopened' if again else 'opened'}: {description}")

    def failed(self, message: str, ended: bool) -> None:
        self.say(message)

    def note(self, message: str) -> None:
        self.say(message)

    def processed(self, frame: Any, result: Any, behind: int) -> None:
        with self._lock:
            self.frames_seen += 1
            collector = self._collector
            if collector is None or frame.t_capture < self._t_armed:
                return  # not collecting, or captured before the row was asked for
            if collector.add(result):
                self._done.set()

    # ----- the caller's thread
    def measure(
        self,
        truth: GroundTruth | None,
        frames: int | None = None,
        *,
        note: str = "",
        follow_bench: bool = False,
        until: Any = None,
        combo: str = "",
    ) -> Measurement | None:
        """Collect the next ``frames`` frames (default: the session's frames per row) and average
        and judge them. ``follow_bench``: the truth is the virtual bench's mean true pose (``truth``
        may be None then; ``combo`` names the combination). ``until()`` True ends the wait early
        (the loop ended, a signal): None is returned then."""
        collector = FrameCollector(frames or self.info.frames_per_row, method=self.info.solver)
        with self._lock:
            self._done.clear()
            self._collector = collector
            self._t_armed = time.monotonic()
        try:
            while not self._done.wait(0.05):
                if until is not None and until():
                    return None
        finally:
            with self._lock:
                self._collector = None
        if follow_bench:
            name = truth.combo if truth is not None else combo
            bench = bench_mean_truth(collector.frames, name, collector.method)
            if bench is None:
                raise ValueError(
                    "--truth virtual needs the virtual bench as the source (its frames carry the truth)"
                )
            truth = bench
        assert truth is not None
        return collector.measurement(truth, self.info.criteria, note=note)
