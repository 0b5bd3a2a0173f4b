"""The stream stage: after each frame's solve, branch continuity and the optional filter, per method.

:class:`StreamStage` is what a :class:`qrfield.pipeline.Pipeline` runs after the solvers
(docs/conventions.md, "The live stream"). Per method it keeps a
:class:`~qrfield.stream.continuity.BranchHistory` (on unless ``continuity`` is off) and, with
``filter_s`` > 0, a :class:`~qrfield.stream.kalman.PoseFilter`. For each frame it replaces each
method's PoseResult in ``FrameResult.poses`` by the one to report:

- the frame's answer, or the mirror's full result when the history chose the mirror branch, with
  ``ambiguous`` the flag after history (so ``FrameResult.ambiguous``, the status AMBIG and the
  serial link follow the history's decision);
- then, with the filter on and the flip resolved, the filtered pose (its position, rotation,
  angles, std, vertices and reprojection), ``filtered`` True once earlier frames were used. A frame
  still ambiguous after the history is reported as it is and is not given to the filter.

The mirror the history weighs is the numerical model's own (its search ends on a minimum); IPPE's
is refined first (:func:`qrfield.solvers.mirror.refined_mirror_result`): near frontal its second
closed-form solution slides onto the answer, so there is no distinct mirror, and, as for the
numerical model's mirror search that slides back, the history confirms the answer unless it points
nearer the candidate the refinement started from (:func:`qrfield.solvers.mirror.mirror_start`).

It records per method a :class:`StreamMark` in ``FrameResult.stream`` (``resolved_by``,
``filtered``) and keeps the frame's own solver results in ``FrameResult.frame_poses``. A single
frame (no history, filter off or just started) comes out as the solvers made it: the same pose,
branch and flag, and the same std unless, with continuity on, its fit's chi-square exceeds
FIT_CHI2 (its covariance scaled by 1 + (chi2 - FIT_CHI2) / FIT_DOF:
:func:`qrfield.stream.continuity.fit_scaled`)
or its mirror fits within NEAR_FOLD_CHI2, where the std of its tilt is widened
(:func:`qrfield.stream.continuity.near_fold_widening`; near the fold the linearised std of the
tilt is several times too small, docs/uncertainty.md) and its position's with it, along the
corners' valley (:func:`qrfield.stream.continuity.coupled_position_widening`). From a stream's
second frame on, with continuity on, the numerical model's covariance is also raised to at
least what the corners' best fit allows, H^-1 + d d^T
(:func:`qrfield.stream.crosscheck.crosscheck_widening`: near frontal the length fit's linearised
std is several times too small where the corners carried its tilt away from frontal); the
filter counts that as shared in full, as the widening near the fold.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.solvers.mirror import mirror_result, mirror_start, refined_mirror_result, reflected_rotation
from qrfield.solvers.registry import uses_depth_model
from qrfield.solvers.result import PoseResult
from qrfield.status import usable_pose
from qrfield.stream.continuity import BY_FRAME, BranchHistory, Decision
from qrfield.stream.crosscheck import crosscheck_widening
from qrfield.stream.kalman import PoseFilter, shared_scale
from qrfield.stream.poses import moved_result, vector_cov
from qrfield.stream.settings import StreamSettings


@dataclass(frozen=True)
class StreamMark:
    """What the stream stage did to one method's pose of one frame.

    Attributes:
        resolved_by: "frame" (the frame alone decided its branch, or nothing decided it) or
            "history" (the stream's recent resolved pose did).
        filtered: the pose reported is the filter's (earlier frames were used).
        frame_ambiguous: the frame alone was ambiguous (its solver's ``ambiguous``).
        flipped: the history chose the mirror branch (the reported pose is the mirror's).
        reset: why the filter started again at this frame ("" when it did not or is off).
    """

    resolved_by: str
    filtered: bool
    frame_ambiguous: bool
    flipped: bool = False
    reset: str = ""


def shared_widening(cov: np.ndarray, decision: Decision) -> np.ndarray:
    """The filter's covariance ``cov`` (6, 6) over (x, y, z mm, w rad) with the frame's widening
    near the fold (``decision.widening``, continuity's) counted as shared in full: the
    filter already reports the shared share rho of the frames' variance (qrfield.stream.kalman),
    and takes the rest for noise it averages away; near the fold the error of the tilt stays with
    the view, so (1 - rho) of the widening is added back."""
    extra, moved = decision.widening, decision.position_widening
    if extra is None and moved is None:
        return cov
    out = np.array(cov, dtype=float)
    scale = shared_scale()
    if extra is not None:
        out[3:, 3:] += (1.0 - scale[3] ** 2) * np.asarray(extra, dtype=float)
    if moved is not None:
        out[:3, :3] += (1.0 - scale[0] ** 2) * np.asarray(moved, dtype=float)
    return out


class _MethodStream:
    """One method's history and filter."""

    def __init__(self, settings: StreamSettings) -> None:
        self.history = BranchHistory(enabled=settings.continuity)
        self.filter = PoseFilter(settings.filter_s) if settings.filter_s > 0 else None
        self.frames = 0  # the frames with a usable pose since the stream (re)started

    def reset(self) -> None:
        self.frames = 0
        self.history.reset()
        if self.filter is not None:
            self.filter.reset()


class StreamStage:
    """Continuity and the filter for one stream (see the module doc); not thread-safe (one frame
    loop owns it)."""

    def __init__(self, settings: StreamSettings | None = None) -> None:
        self.settings = settings if settings is not None else StreamSettings()
        self._methods: dict[str, _MethodStream] = {}

    def reset(self) -> None:
        """Forget every method's history and filter (a new source)."""
        for state in self._methods.values():
            state.reset()

    def apply(self, result: Any, side_mm: float, corners_cov: np.ndarray | None) -> None:
        """Replace ``result.poses`` (a qrfield.pipeline.FrameResult of this stream, solved with
        ``corners_cov`` (4, 2, 2) px^2 for a QR side of ``side_mm``) by the poses to report, and
        fill ``result.stream`` and ``result.frame_poses`` (see the module doc)."""
        result.frame_poses = dict(result.poses)
        detection = result.detection
        text = None if detection is None else detection.text
        camera = result.camera
        for name, pose in result.frame_poses.items():
            if not (isinstance(pose, PoseResult) and usable_pose(pose)) or camera is None:
                continue  # no pose (or a stand-in solver's result): reported as the frame made it
            state = self._methods.get(name)
            if state is None:
                state = self._methods[name] = _MethodStream(self.settings)
            try:
                self._apply_one(result, name, pose, state, text, camera, side_mm, corners_cov)
            except Exception as exc:  # the frame's own pose stands; the stage must not lose it
                result.poses[name] = pose
                result.stream[name] = StreamMark(BY_FRAME, False, bool(pose.ambiguous))
                note = f"stream stage ({name}): {type(exc).__name__}: {exc}"
                result.reason = f"{result.reason}; {note}" if result.reason else note

    def _apply_one(
        self,
        result: Any,
        name: str,
        pose: PoseResult,
        state: _MethodStream,
        text: str | None,
        camera: Any,
        side_mm: float,
        corners_cov: np.ndarray | None,
    ) -> None:
        """Continuity, then the filter, for one method's pose of one frame."""
        checked = None
        if uses_depth_model(name):  # the numerical model: its mirror search ends on a minimum
            mirror = lambda p: mirror_result(p, camera, side_mm, corners_cov)  # noqa: E731
            reflected = lambda p: reflected_rotation(p, camera)  # noqa: E731
            if state.frames > 0:  # the first frame is a single image: the solver's std
                checked = lambda p: crosscheck_widening(p, camera, side_mm, corners_cov)  # noqa: E731
        else:  # IPPE's mirror may be its closed-form second solution: refined first
            mirror = lambda p: refined_mirror_result(p, camera, side_mm, corners_cov)  # noqa: E731
            reflected = mirror_start
        state.frames += 1
        decision = state.history.decide(
            pose, result.t_ms, text, mirror=mirror, reflected=reflected, checked=checked
        )
        out, filtered, reset = decision.pose, False, ""
        if state.filter is not None and not decision.ambiguous:
            cov = vector_cov(out)
            if cov is not None:
                estimate = state.filter.update(out.rotation, out.position_mm, cov, result.t_ms, text)
                if estimate.filtered:
                    out = moved_result(
                        out,
                        estimate.rotation,
                        estimate.position_mm,
                        shared_widening(estimate.cov, decision),
                        camera,
                        side_mm,
                    )
                filtered, reset = estimate.filtered, estimate.reset
        result.poses[name] = out
        result.stream[name] = StreamMark(
            decision.resolved_by, filtered, bool(pose.ambiguous), decision.flipped, reset
        )
