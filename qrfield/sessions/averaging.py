"""Average N frames of pose results into one session row and judge it against the ground truth.

Input frames are PoseResult-like: objects with attributes, or dicts with keys, ``position_mm``
(3, mm, camera frame), ``angles_deg`` (3: alpha, beta, gamma in degrees), ``converged`` (bool)
and optionally ``iterations``, ``reprojection_px`` and the per-frame uncertainty
``position_std_mm`` / ``angles_std_deg`` (3 each, NaN or absent when unknown); ``None`` stands for
a frame in which no code was found. Every frame counts in ``n_frames``; only converged frames with
a finite pose enter the means (``n_converged``).

Means: position arithmetic (mm); each angle the circular mean atan2(mean sin, mean cos), so
179 and -179 average to 180, not 0. Standard deviations: sample (ddof = 1) over the converged
frames, angles measured as wrapped differences from their circular mean; NaN below two frames.
Angles are averaged one by one (not as rotations): fine for the small spreads of a still card.
Two kinds of spread, kept apart: ``std_*`` is the frame-to-frame sample standard deviation (what
the frames did); ``sigma_*`` is the mean of the frames' own uncertainty (what each frame's image
evidence allowed, docs/conventions.md "Pose uncertainty"), over the converged frames that have one.
The mean's standard uncertainty ``sem_*`` (what a row or a ``MEAS`` answer reports as its sigma):
frames of a still card share most of their error (the corner fit's error is fixed by the view, not
drawn afresh each frame), so it is not the spread / sqrt(n). With rho the share of a frame's
variance that the frames share (``qrfield.solvers.uncertainty.FRAME_SHARED_SHARE``, measured on
still cards: docs/uncertainty.md) and sigma the frames' RMS own uncertainty,
sem^2 = rho sigma^2 + max(s^2, (1 - rho) sigma^2) / n (s the frames' sample std; the frames' own
part is never taken as smaller than the share sigma gives it). Frames that are the stream filter's
output (``filtered``) have already averaged their own part, and their sigma holds the shared part:
then sem = their RMS sigma. Without a per-frame sigma: sem^2 = s^2 (rho / (1 - rho) + 1 / n)
(the spread is the frames' own part), and sigma alone for one frame.
Errors: err_pos = |mean position - truth| (Euclidean, mm); err_alpha/beta/gamma = mean minus
truth, wrapped to (-180, 180] (signed, degrees).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from qrfield.geometry import ANGLE_NAMES, angle_difference, wrap_degrees
from qrfield.sessions.criteria import AcceptanceCriteria, pose_errors
from qrfield.sessions.groundtruth import GroundTruth
from qrfield.solvers.uncertainty import FRAME_SHARED_SHARE


def _get(frame: Any, key: str, default: Any = None) -> Any:
    if isinstance(frame, Mapping):
        return frame.get(key, default)
    return getattr(frame, key, default)


def circular_mean_deg(angles_deg: Sequence[float] | np.ndarray) -> float:
    """Circular mean of angles in degrees, wrapped to (-180, 180]; NaN for none (or a spread that cancels)."""
    a = np.radians(np.asarray(angles_deg, dtype=float).reshape(-1))
    if a.size == 0:
        return math.nan
    s, c = float(np.mean(np.sin(a))), float(np.mean(np.cos(a)))
    if math.hypot(s, c) < 1e-12:
        return math.nan  # e.g. 0 and 180: no meaningful mean direction
    return float(wrap_degrees(math.degrees(math.atan2(s, c))))


#: A row is said to misfit (:attr:`AveragedPose.mostly_misfit`) when more than this share of its
#: frames do: with a wrong camera model or side every frame does; with right ones about 1 % of
#: frames lie above FIT_CHI2 by chance, so a row of 10-30 frames often holds one.
MISFIT_ROW_SHARE = 0.5


@dataclass(frozen=True)
class AveragedPose:
    """What N frames measured (mm and degrees; NaN where no converged frame)."""

    n_frames: int
    n_converged: int
    position_mm: np.ndarray
    angles_deg: np.ndarray
    std_position_mm: np.ndarray
    std_angles_deg: np.ndarray
    mean_iterations: float
    mean_reprojection_px: float
    sigma_position_mm: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    sigma_angles_deg: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    sem_position_mm: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    sem_angles_deg: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    n_filtered: int = 0
    n_resolved_by_history: int = 0
    #: Averaged frames whose fit misfits its corners (``PoseResult.misfit``: chi-square above
    #: FIT_CHI2; a wrong camera model, side or corners; their std and sigma are too small).
    n_misfit: int = 0

    @property
    def mostly_misfit(self) -> bool:
        """More than MISFIT_ROW_SHARE of the averaged frames misfit their corners: the row's
        camera model, side or corners are wrong (one frame in a hundred of right fits lies above
        FIT_CHI2, 2-3 % of tracked ones at modules of 1.2-1.4 px: a frame or two is not that)."""
        return self.n_converged > 0 and self.n_misfit > MISFIT_ROW_SHARE * self.n_converged

    @property
    def filtered(self) -> bool:
        """Some averaged frame was the stream filter's output (``--filter-s`` was on)."""
        return self.n_filtered > 0

    @property
    def has_pose(self) -> bool:
        return self.n_converged > 0 and bool(np.all(np.isfinite(self.position_mm)))


def method_result(frame: Any, method: str = "") -> Any:
    """The PoseResult-like part of a frame: a pipeline FrameResult (it has ``poses``, method name ->
    PoseResult) gives the result of ``method`` (or its first method when ``method`` is empty);
    anything else is taken as it is (None = no code in the frame)."""
    poses = frame.get("poses") if isinstance(frame, Mapping) else getattr(frame, "poses", None)
    if isinstance(poses, Mapping):
        if method:
            return poses.get(method)
        return next(iter(poses.values()), None)
    return frame


def stream_mark(frame: Any, method: str = "") -> tuple[bool, bool]:
    """(filtered, resolved by history) of a frame's result of ``method`` (its first method when
    empty): from a pipeline FrameResult's ``stream`` marks, or a dict's "filtered" and
    "resolved_by" keys; (False, False) for anything else."""
    if isinstance(frame, Mapping):
        return bool(frame.get("filtered", False)), frame.get("resolved_by") == "history"
    marks = getattr(frame, "stream", None)
    poses = getattr(frame, "poses", None)
    if not isinstance(marks, Mapping) or not isinstance(poses, Mapping):
        return False, False
    mark = marks.get(method or next(iter(poses), ""))
    if mark is None:
        return False, False
    return bool(getattr(mark, "filtered", False)), getattr(mark, "resolved_by", "") == "history"


def mean_uncertainty(
    sigma: np.ndarray,
    spread: np.ndarray,
    n: int,
    filtered: bool,
    shared: Sequence[float] = FRAME_SHARED_SHARE,
) -> np.ndarray:
    """(6,) the standard uncertainty of the mean of ``n`` frames (x, y, z mm; alpha, beta, gamma
    deg) from the frames' RMS own uncertainty ``sigma`` (6,) (NaN where unknown), their sample std
    ``spread`` (6,) (NaN below two frames) and whether they were filtered; ``shared`` (6,) the
    share of a frame's variance the frames share (the rule of the module doc)."""
    rho = np.asarray(shared, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    spread = np.asarray(spread, dtype=float)
    if n < 1:
        return np.full(6, np.nan)
    with np.errstate(invalid="ignore"):
        own = np.where(
            np.isfinite(spread), np.fmax(spread**2, (1.0 - rho) * sigma**2), (1.0 - rho) * sigma**2
        )
        with_sigma = np.sqrt(sigma**2 if filtered else rho * sigma**2 + own / n)
        without = np.sqrt(spread**2 * (rho / (1.0 - rho) + 1.0 / n))
    return np.where(np.isfinite(sigma), with_sigma, without)


def average_frames(frames: Iterable[Any], method: str = "") -> AveragedPose:
    """Means, standard deviations and the mean's standard uncertainty of the converged frames (see
    the module doc).

    ``method`` picks the solver's result out of pipeline frames (see :func:`method_result`).
    """
    positions: list[np.ndarray] = []
    angles: list[np.ndarray] = []
    iterations: list[float] = []
    reprojections: list[float] = []
    sigmas: list[np.ndarray] = []
    n_frames = n_filtered = n_history = n_misfit = 0
    for index, item in enumerate(frames):
        n_frames += 1
        frame = method_result(item, method)
        if frame is None or not bool(_get(frame, "converged", False)):
            continue
        pos = np.asarray(_get(frame, "position_mm"), dtype=float).reshape(-1)
        ang = np.asarray(_get(frame, "angles_deg"), dtype=float).reshape(-1)
        if pos.shape != (3,) or ang.shape != (3,):
            raise ValueError(
                f"frame {index}: position_mm needs 3 values (mm) and angles_deg 3 (deg), "
                f"got {pos.size} and {ang.size}"
            )
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(ang))):
            continue  # converged but without a usable pose: not averaged
        positions.append(pos)
        angles.append(ang)
        it = _get(frame, "iterations")
        if it is not None and math.isfinite(float(it)):
            iterations.append(float(it))
        rp = _get(frame, "reprojection_px")
        if rp is not None and math.isfinite(float(rp)):
            reprojections.append(float(rp))
        sigmas.append(_frame_sigma(frame, index))
        filtered, by_history = stream_mark(item, method)
        n_filtered += filtered
        n_misfit += bool(_get(frame, "misfit", False))
        n_history += by_history
    n = len(positions)
    nan3 = np.full(3, np.nan)
    if n == 0:
        return AveragedPose(n_frames, 0, nan3, nan3.copy(), nan3.copy(), nan3.copy(), math.nan, math.nan)
    pos_arr = np.array(positions)
    ang_arr = np.array(angles)
    mean_pos = pos_arr.mean(axis=0)
    mean_ang = np.array([circular_mean_deg(ang_arr[:, k]) for k in range(3)])
    if n >= 2:
        std_pos = pos_arr.std(axis=0, ddof=1)
        dev = angle_difference(ang_arr, mean_ang[None, :])
        std_ang = np.sqrt(np.sum(dev**2, axis=0) / (n - 1))
    else:
        std_pos, std_ang = nan3.copy(), nan3.copy()
    sigma = np.array(sigmas)
    known = np.isfinite(sigma)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_sigma = np.where(known.any(axis=0), np.nansum(sigma, axis=0) / known.sum(axis=0), np.nan)
        rms_sigma = np.where(
            known.any(axis=0), np.sqrt(np.nansum(sigma**2, axis=0) / known.sum(axis=0)), np.nan
        )
    sem = mean_uncertainty(rms_sigma, np.concatenate([std_pos, std_ang]), n, n_filtered > 0)
    return AveragedPose(
        n_frames=n_frames,
        n_converged=n,
        position_mm=mean_pos,
        angles_deg=mean_ang,
        std_position_mm=std_pos,
        std_angles_deg=std_ang,
        mean_iterations=float(np.mean(iterations)) if iterations else math.nan,
        mean_reprojection_px=float(np.mean(reprojections)) if reprojections else math.nan,
        sigma_position_mm=mean_sigma[:3],
        sigma_angles_deg=mean_sigma[3:],
        sem_position_mm=sem[:3],
        sem_angles_deg=sem[3:],
        n_filtered=n_filtered,
        n_resolved_by_history=n_history,
        n_misfit=n_misfit,
    )


def _frame_sigma(frame: Any, index: int) -> np.ndarray:
    """(6,) the frame's own std of x, y, z (mm) and alpha, beta, gamma (deg); NaN where unknown."""
    out = np.full(6, np.nan)
    for start, key in ((0, "position_std_mm"), (3, "angles_std_deg")):
        value = _get(frame, key)
        if value is None:
            continue
        arr = np.asarray(value, dtype=float).reshape(-1)
        if arr.shape != (3,):
            raise ValueError(f"frame {index}: {key} needs 3 values, got {arr.size}")
        out[start : start + 3] = np.where(arr >= 0.0, arr, np.nan)  # a negative std is no std
    return out


@dataclass(frozen=True)
class Judgement:
    """Errors of a measured pose against its ground truth, and the verdict."""

    err_pos_mm: float
    err_angles_deg: np.ndarray
    passed: bool
    reason: str


def judge_row(
    position_mm: Sequence[float] | np.ndarray,
    angles_deg: Sequence[float] | np.ndarray,
    truth: GroundTruth,
    criteria: AcceptanceCriteria | None = None,
    *,
    has_pose: bool = True,
) -> Judgement:
    """One session row's verdict: errors (mm; signed wrapped degrees, measured minus truth), pass
    by the criteria (qrfield.sessions.criteria, the rule's one home) and, for a fail, the reasons."""
    criteria = criteria or AcceptanceCriteria()
    pos = np.asarray(position_mm, dtype=float).reshape(-1)
    ang = np.asarray(angles_deg, dtype=float).reshape(-1)
    if pos.shape != (3,) or ang.shape != (3,):
        raise ValueError(f"position (3, mm) and angles (3, deg) expected, got {pos.size} and {ang.size}")
    if not has_pose or not (np.all(np.isfinite(pos)) and np.all(np.isfinite(ang))):
        return Judgement(math.nan, np.full(3, np.nan), False, "no converged frame")
    err_pos_, err_ang = pose_errors(pos, ang, truth.position_mm, truth.angles_deg)
    err_pos = float(err_pos_)
    passed = criteria.passes(err_pos, err_ang)
    reasons = []
    if not err_pos < criteria.max_position_error_mm:
        reasons.append(f"position error {err_pos:.2f} mm >= {criteria.max_position_error_mm:g} mm")
    for name, err in zip(ANGLE_NAMES, err_ang, strict=True):
        if abs(err) > criteria.max_angle_error_deg:
            reasons.append(f"{name} error {err:+.2f} deg beyond {criteria.max_angle_error_deg:g} deg")
    return Judgement(err_pos, err_ang, passed, "; ".join(reasons))


@dataclass(frozen=True)
class Measurement:
    """One row's content before it is numbered and logged: the truth, the average and the verdict."""

    truth: GroundTruth
    average: AveragedPose
    judgement: Judgement
    method: str = ""
    note: str = ""


def measure(
    frames: Iterable[Any],
    truth: GroundTruth,
    criteria: AcceptanceCriteria | None = None,
    *,
    method: str = "",
    note: str = "",
) -> Measurement:
    """Average ``frames`` and judge the mean against ``truth`` (pass needs >= 1 converged frame)."""
    average = average_frames(frames, method)
    judgement = judge_row(average.position_mm, average.angles_deg, truth, criteria, has_pose=average.has_pose)
    return Measurement(truth, average, judgement, method=method, note=note)


@dataclass
class FrameCollector:
    """Collects the next N frames for 'Log row' (the GUI feeds it and shows ``progress``).

    ``add`` takes a frame: a pipeline FrameResult, a PoseResult-like object or dict, or None for
    a frame without a code; it returns True once N frames are in; further frames are ignored.
    ``method`` names the solver whose results are averaged (default: a FrameResult's first method).
    ``measurement(truth)`` averages and judges.
    """

    frames_wanted: int
    method: str = ""
    frames: list[Any] = field(default_factory=list)

    def __post_init__(self) -> None:
        if int(self.frames_wanted) < 1:
            raise ValueError(f"frames per row must be at least 1, got {self.frames_wanted!r}")
        self.frames_wanted = int(self.frames_wanted)

    def add(self, frame: Any) -> bool:
        if len(self.frames) < self.frames_wanted:
            self.frames.append(frame)
        return self.done

    @property
    def done(self) -> bool:
        return len(self.frames) >= self.frames_wanted

    @property
    def progress(self) -> tuple[int, int]:
        """(frames collected, frames wanted)."""
        return len(self.frames), self.frames_wanted

    def measurement(
        self,
        truth: GroundTruth,
        criteria: AcceptanceCriteria | None = None,
        *,
        note: str = "",
    ) -> Measurement:
        return measure(self.frames, truth, criteria, method=self.method, note=note)
