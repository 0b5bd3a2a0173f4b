"""When the card is still: the pose has stayed within its own noise for a set time.

The rule (docs/conventions.md, "Guided experiments and the session report"; the numbers are
:class:`StillnessSettings`): frame by frame, the converged pose of the session's solver is compared
with the mean of the frames of the current run that lie within the last ``hold_s`` seconds
(positions arithmetic, angles circular, :func:`qrfield.sessions.averaging.circular_mean_deg`).
When every one of x, y, z, alpha, beta, gamma of the new frame lies within ``noise_factor`` times
that frame's own standard uncertainty (``position_std_mm``, ``angles_std_deg``: docs/conventions.md
"Pose uncertainty") of that mean, the run goes on; otherwise a new run starts at this frame. A
frame without a converged pose, or without an uncertainty, ends the run (nothing to judge
stillness by), as does a gap in the frames longer than ``hold_s`` or a clock that goes back (a new
stream). The card is **still** once the run has lasted ``hold_s`` seconds (capture times).

A steady turn or drift is caught by the same test: the newest frame lags the mean of the last
``hold_s`` seconds by half the motion over them, so a motion of more than 2 x ``noise_factor``
sigma within ``hold_s`` is never still (at the defaults and an angle sigma of 0.2 deg, 1.6 deg/s),
a slower one is.

An uncertainty below :data:`MIN_SIGMA_MM` / :data:`MIN_SIGMA_DEG` counts as that floor: a view
rendered without noise would otherwise never be still to within 0 mm. The default band of 4 sigma
on each of six values lets a calibrated, truly still pose through: a frame of independent Gaussian
errors leaves it with probability about 6 x 6.3e-5 = 0.04 %, once in some 2600 frames.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.geometry import POSE_NAMES, angle_difference
from qrfield.sessions.averaging import circular_mean_deg
from qrfield.settings import setting

#: Floors of a frame's own standard uncertainty, mm and degrees (see the module doc).
MIN_SIGMA_MM = 0.02
MIN_SIGMA_DEG = 0.02
#: The six values' names, in order (mm, mm, mm, deg, deg, deg).
DOF = POSE_NAMES


@dataclass(frozen=True)
class StillnessSettings:
    """How long, and how closely, the pose must stay put to count as still (the guided logging)."""

    hold_s: float = setting(
        1.0,
        label="still for",
        unit="s",
        minimum=0.1,
        maximum=30.0,
        decimals=1,
        help="the pose counts as still once it has stayed within its noise this long",
    )
    noise_factor: float = setting(
        4.0,
        label="noise band",
        unit="sigma",
        minimum=1.0,
        maximum=50.0,
        decimals=1,
        help="within its noise = each of x, y, z, alpha, beta, gamma within this many of the frame's "
        "own standard uncertainty of the recent mean",
    )


@dataclass(frozen=True)
class Stillness:
    """The state after a frame: still or not, for how long (s), and why not ("" when still).

    ``mean``: (6,) the current run's recent mean (x, y, z mm; alpha, beta, gamma deg), NaN
    without a run. ``deviation``: the largest |new frame - mean| / sigma of the last frame (0 for
    the first frame of a run, NaN without a pose).
    """

    still: bool
    held_s: float
    hold_s: float
    reason: str
    mean: np.ndarray
    deviation: float = math.nan

    @property
    def progress(self) -> float:
        """held / hold in 0..1."""
        return min(1.0, self.held_s / self.hold_s) if self.hold_s > 0 else 1.0


def _get(pose: Any, key: str) -> Any:
    return pose.get(key) if isinstance(pose, Mapping) else getattr(pose, key, None)


def pose_values(pose: Any) -> tuple[np.ndarray, np.ndarray] | str:
    """(values (6,), sigmas (6,) with the floors applied) of a PoseResult-like pose, or why it
    cannot be judged ("no converged pose", "no uncertainty")."""
    if pose is None or not bool(_get(pose, "converged")):
        return "no converged pose"
    position = np.asarray(_get(pose, "position_mm"), dtype=float).reshape(-1)
    angles = np.asarray(_get(pose, "angles_deg"), dtype=float).reshape(-1)
    if position.shape != (3,) or angles.shape != (3,):
        raise ValueError(
            f"a pose needs position_mm (3, mm) and angles_deg (3, deg), got {position.size} and {angles.size}"
        )
    values = np.concatenate([position, angles])
    if not np.all(np.isfinite(values)):
        return "no converged pose"
    sigmas = []
    for key in ("position_std_mm", "angles_std_deg"):
        value = _get(pose, key)
        arr = np.full(3, np.nan) if value is None else np.asarray(value, dtype=float).reshape(-1)
        if arr.shape != (3,):
            raise ValueError(f"{key} needs 3 values, got {arr.size}")
        sigmas.append(arr)
    sigma = np.concatenate(sigmas)
    if not np.all(np.isfinite(sigma)) or np.any(sigma < 0):
        return "no uncertainty for this pose (the solver gave none)"
    floors = np.array([MIN_SIGMA_MM] * 3 + [MIN_SIGMA_DEG] * 3)
    return values, np.maximum(sigma, floors)


def mean_pose(values: np.ndarray) -> np.ndarray:
    """(6,) mean of (N, 6) poses: positions arithmetic, angles circular (degrees)."""
    v = np.asarray(values, dtype=float).reshape(-1, 6)
    return np.concatenate([v[:, :3].mean(axis=0), [circular_mean_deg(v[:, k]) for k in (3, 4, 5)]])


def pose_difference(values: Any, reference: Any) -> np.ndarray:
    """(…, 6) values minus reference: mm for x, y, z; degrees wrapped to (-180, 180] for the angles."""
    v, r = np.asarray(values, dtype=float), np.asarray(reference, dtype=float)
    if v.shape[-1:] != (6,) or r.shape[-1:] != (6,):
        raise ValueError(f"poses of 6 values (x, y, z mm; alpha, beta, gamma deg) expected, got {v.shape}")
    out = np.broadcast_to(v - r, np.broadcast_shapes(v.shape, r.shape)).copy()
    out[..., 3:] = angle_difference(v[..., 3:], r[..., 3:])
    return out


class StillnessDetector:
    """Feed it each frame's pose with its capture time; it says whether the card is still.

    Not thread-safe: one feeder (the guide holds it under its lock).
    """

    def __init__(self, settings: StillnessSettings | None = None) -> None:
        self.settings = settings or StillnessSettings()
        self._frames: deque[tuple[float, np.ndarray]] = deque()
        self._since: float | None = None
        self._last_t: float | None = None
        #: Runs ended by a move or by the loss of the pose (not by a pause or a restart): the
        #: guide's "the card moved since the target was set".
        self.moves = 0
        self.state = self._idle("no frame yet")

    def _idle(self, reason: str) -> Stillness:
        return Stillness(False, 0.0, self.settings.hold_s, reason, np.full(6, np.nan))

    def restart(self, reason: str = "waiting for the pose to settle") -> None:
        """Forget the current run: stillness must be shown afresh from the next frame."""
        self._frames.clear()
        self._since = None
        self.state = self._idle(reason)

    def add(self, t_s: float, pose: Any) -> Stillness:
        """The next frame: capture time in seconds (any origin, one clock) and its pose
        (PoseResult-like, or None when no code was seen). Returns the new state."""
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"capture time must be a finite number of seconds, got {t_s!r}")
        hold = self.settings.hold_s
        last, self._last_t = self._last_t, t
        judged = pose_values(pose)
        if isinstance(judged, str):
            if self._frames:
                self.moves += 1  # the card left the view, or was turned until no pose was found
            self.restart(judged)
            return self.state
        values, sigma = judged
        if last is not None and (t < last or t - last > hold):
            self.restart("the frames paused" if t >= last else "a new stream")
        while self._frames and self._frames[0][0] < t - hold:
            self._frames.popleft()
        deviation = 0.0
        if self._frames and self._since is not None:
            reference = mean_pose(np.array([v for _, v in self._frames]))
            spread = np.abs(pose_difference(values, reference)) / sigma
            deviation = float(np.max(spread))
            if deviation > self.settings.noise_factor:
                worst = DOF[int(np.argmax(spread))]
                self.moves += 1
                self._frames.clear()
                self._frames.append((t, values))
                self._since = t
                self.state = Stillness(
                    False,
                    0.0,
                    hold,
                    f"moving ({worst} moved {deviation:.1f} sigma)",
                    values.copy(),
                    deviation,
                )
                return self.state
        elif self._since is None or not self._frames:
            self._since = t
        self._frames.append((t, values))
        held = t - (self._since if self._since is not None else t)
        mean = mean_pose(np.array([v for _, v in self._frames]))
        still = held >= hold - 1e-9
        reason = "" if still else f"settling: still for {held:.1f} of {hold:.1f} s"
        self.state = Stillness(still, held, hold, reason, mean, deviation)
        return self.state
