"""The stream's optional filter: a random-walk Kalman filter on position and rotation.

docs/conventions.md, "The live stream" (``filter_s``, a time constant S in s; 0 = off). Per method,
:class:`PoseFilter` keeps the estimate (position p mm, rotation R_ref) and its covariance over
(p, theta), theta a small rotation of the camera frame about the estimate (R = exp([theta]x) R_ref,
the solvers' omega), folded into R_ref after each update so that it stays small. Each frame's pose
is a measurement of (p, theta) with its own covariance (``pose_cov`` converted to (x, y, z mm,
w rad): :func:`qrfield.stream.poses.vector_cov`).

- Measurement noise: the part of the frame's covariance that is the frame's own. Frames of one
  card share much of their error (the corner fit's error is fixed by the view, not drawn afresh per
  frame: docs/uncertainty.md, ``FRAME_SHARED_SHARE`` = rho), and no filter averages that part away:
  the filter takes (1 - rho) C_frame as its noise and reports P + rho C_bar (C_bar the recent
  frames' running mean), so that its sigma stays honest for a still card. Position and rotation
  are two blocks (the frame covariance's coupling between them is left out: near frontal it is
  strong and unreliable, and a precise position moved the rotation through it by degrees).
- Process noise from S: the pose is a random walk whose variance grows by r_max dt_bar dt / S^2 in
  dt, the same in every direction of a block (position; rotation), r_max the largest variance of the
  recent frames' own noise in that block and dt_bar the recent frame interval. Along the noisiest
  direction the steady-state filter is then an exponential average with time constant S (its gain
  K = sqrt(q dt / r) = dt / S); along more precise ones it follows faster (a precise coordinate is
  not assumed to hold still). The price: a card moving at a steady rate v is reported about S late
  (S times the frame rate frames, v S behind) while the filter stays on; ``qrfield benchmark
  stream`` measures it. The reported covariance holds that lag too: the running mean innovation
  nu (over about S / LAG_WEIGHT) leaves the estimate (I - K) nu behind the frames, added as its
  outer product (the share of it that the frames' noise does not explain). A random walk was
  chosen over a constant-velocity model by measurement: the frames' errors drift with the view
  (their lag-1 correlation on a moving far card is 0.5-0.7), which a velocity state takes for
  motion and extrapolates (the tuning seeds 1 and 2 of the benchmark: fewer frames within 2 deg /
  5 mm and more confidently wrong ones at modules of 1.2 and 1.4 px, and an overshoot after each
  start on the still card).
- Resets: when the innovation's chi-square exceeds GATE_CHI2 under the frame's whole covariance and
  the filter's (a jump, or a motion faster than S lets the filter follow), after a gap of more than
  GAP_S without a measurement, on another code, and by :meth:`PoseFilter.reset`. The first frame
  after a reset is reported as it is (not filtered).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from qrfield.geometry import rotation_from_vector, rotation_vector
from qrfield.solvers.uncertainty import FRAME_SHARED_SHARE

#: A gap longer than this (s) without a measurement resets the filter (docs/conventions.md).
GAP_S = 0.5
#: An innovation whose chi-square exceeds this (6 degrees of freedom, 0.999) is a jump: reset.
GATE_CHI2 = 22.46
#: The frame interval assumed before any was seen (s).
NOMINAL_FRAME_S = 1.0 / 30.0
#: The weight of each new frame in the running mean of the frames' own noise and interval.
NOISE_WEIGHT = 0.1
#: A frame's noise enters that mean at most this many times the mean (one frame with a huge std
#: does not make the filter forget).
NOISE_CLIP = 10.0
#: The mean innovation is a running mean over about S / LAG_WEIGHT (the lag builds within about S).
LAG_WEIGHT = 3.0
#: Riccati steps from a single frame to the steady state at a start.
STEADY_STEPS = 60


def shared_scale() -> np.ndarray:
    """(6,) square roots of the shared share of a frame's variance, per block (x, y, z; w): the
    position coordinates' and the angles' mean of ``FRAME_SHARED_SHARE``."""
    share = np.asarray(FRAME_SHARED_SHARE, dtype=float)
    return np.sqrt(np.repeat([share[:3].mean(), share[3:].mean()], 3))


@dataclass(frozen=True)
class Estimate:
    """The filter's answer for one frame.

    Attributes:
        rotation: (3, 3) marker to camera; position_mm: (3,) mm.
        cov: (6, 6) covariance of (x, y, z mm, w rad) (the filter's and the frame's shared part).
        filtered: False for the frame itself (the first after a reset), True when earlier frames
            were used.
        reset: why the filter started again with this frame ("" when it did not).
    """

    rotation: np.ndarray
    position_mm: np.ndarray
    cov: np.ndarray
    filtered: bool
    reset: str = ""


class PoseFilter:
    """A random-walk filter of one method's poses (see the module doc).

    Args:
        time_constant_s: S > 0 (s).
    """

    def __init__(self, time_constant_s: float) -> None:
        s = float(time_constant_s)
        if not math.isfinite(s) or s <= 0.0:
            raise ValueError(f"the filter's time constant must be > 0 s, got {time_constant_s!r}")
        self.time_constant_s = s
        self._shared = shared_scale()
        self._own = np.sqrt(1.0 - self._shared**2)
        self.reset()

    def reset(self) -> None:
        """Forget the estimate and the frame interval: the next frame starts the filter again."""
        self._position = np.zeros(3)
        self._rotation = np.eye(3)
        self._p = np.zeros((6, 6))
        self._t_ms: int | None = None
        self._key: object = None
        self._noise = np.zeros((6, 6))
        self._innovation = np.zeros(6)  # the running mean innovation (over about S)
        self._lag = np.zeros(6)  # how far the estimate trails the frames, (x, y, z mm, w rad)
        self._dt = 0.0  # the running mean frame interval, s (kept over the gate's resets)

    def update(
        self, rotation: np.ndarray, position_mm: np.ndarray, cov: np.ndarray, t_ms: int, key: object
    ) -> Estimate:
        """Take one frame's pose (R (3, 3), t (3,) mm, covariance (6, 6) over (x, y, z mm, w rad))
        captured at ``t_ms`` (ms) of the code ``key`` (its text); return the estimate at that time."""
        rotation = np.asarray(rotation, dtype=float)
        position = np.asarray(position_mm, dtype=float).reshape(3)
        cov = np.asarray(cov, dtype=float)
        if rotation.shape != (3, 3) or cov.shape != (6, 6) or not np.all(np.isfinite(cov)):
            raise ValueError(
                "the filter takes a (3, 3) rotation, a (3,) position and a finite (6, 6) covariance"
            )
        # Position and rotation are filtered as two blocks: near frontal a frame's covariance
        # couples them strongly and unreliably (its rotation std jumps from 0.4 to 30 degrees from
        # frame to frame), and through that coupling a precise position would move the rotation.
        cov = cov.copy()
        cov[:3, 3:] = cov[3:, :3] = 0.0
        own = self._own[:, None] * cov * self._own[None, :]
        shared = self._shared[:, None] * cov * self._shared[None, :]
        why = self._why_reset(t_ms, key)
        if not why:
            assert self._t_ms is not None
            self._predict((t_ms - self._t_ms) / 1000.0, own)
            innovation = np.concatenate(
                [position - self._position, rotation_vector(rotation @ self._rotation.T)]
            )
            s = self._p + own
            # The gate takes the frame's whole covariance and the drift of its shared part since the
            # estimate (at most twice that part): a moving card's shared error changes with the view.
            try:
                chi2 = float(innovation @ np.linalg.solve(s + 2.0 * shared, innovation))
            except np.linalg.LinAlgError:
                chi2 = math.inf
            if chi2 <= GATE_CHI2:
                self._correct(innovation, s, own)
                self._t_ms = t_ms
                # The shared part of the recent frames' noise (their running mean), not this frame's
                # alone: a frame's covariance near frontal jumps by 10x and more from frame to frame.
                recent = (self._shared / self._own)[:, None] ** 2 * self._noise
                cov = self._p + recent + np.outer(self._lag, self._lag)
                return Estimate(self._rotation.copy(), self._position.copy(), cov, True)
            why = f"a jump the covariance cannot explain (chi-square {chi2:.0f} > {GATE_CHI2})"
        self._start(rotation, position, own, t_ms, key)
        return Estimate(rotation.copy(), position.copy(), cov.copy(), False, why)

    # ------------------------------------------------------------------ steps
    def _why_reset(self, t_ms: int, key: object) -> str:
        if self._t_ms is None:
            return "first frame"
        if key != self._key:
            return "another code"
        gap = (t_ms - self._t_ms) / 1000.0
        if gap > GAP_S or gap < 0.0:
            return f"a gap of {gap:.2f} s"
        return ""

    def _start(
        self, rotation: np.ndarray, position: np.ndarray, own: np.ndarray, t_ms: int, key: object
    ) -> None:
        """Start again at this frame with the steady-state covariance at its noise (the frames
        before are forgotten, but the next ones are weighed as in a running filter)."""
        self._position = position.copy()
        self._rotation = rotation.copy()
        self._t_ms = t_ms
        self._key = key
        self._noise = own.copy()
        self._innovation = np.zeros(6)
        self._lag = np.zeros(6)
        self._dt = self._dt or NOMINAL_FRAME_S
        q = self._growth(self._dt, own)
        p = own.copy()
        for _ in range(STEADY_STEPS):
            ahead = p + q
            p = ahead - ahead @ np.linalg.solve(ahead + own, ahead)
        self._p = 0.5 * (p + p.T)

    def _growth(self, dt: float, noise: np.ndarray) -> np.ndarray:
        """(6, 6) the random walk's covariance growth over dt (s) for frames of own noise ``noise``."""
        q = np.zeros((6, 6))
        for block in (slice(0, 3), slice(3, 6)):
            # Isotropic in each block, at its noisiest direction.
            r = float(np.linalg.eigvalsh(noise[block, block])[-1]) * max(self._dt, 1e-3)
            q[block, block] = np.eye(3) * (r / self.time_constant_s**2 * dt)
        return q

    def _predict(self, dt: float, own: np.ndarray) -> None:
        """Grow the covariance over dt (s); update the running mean of the own noise and interval."""
        level = float(np.trace(self._noise)) or float(np.trace(own)) or 1.0
        clip = min(1.0, NOISE_CLIP * level / max(float(np.trace(own)), 1e-300))
        self._noise = (1.0 - NOISE_WEIGHT) * self._noise + NOISE_WEIGHT * own * clip
        if dt <= 0.0:
            return
        self._dt = (1.0 - NOISE_WEIGHT) * self._dt + NOISE_WEIGHT * dt
        self._p = self._p + self._growth(dt, self._noise)

    def _correct(self, innovation: np.ndarray, s: np.ndarray, own: np.ndarray) -> None:
        """The Kalman update (6,) innovation with covariance ``s``; theta folded into the rotation."""
        gain = np.linalg.solve(s, self._p).T  # P S^-1 (both symmetric)
        step = gain @ innovation
        # Joseph form (I - K) P (I - K)^T + K R K^T keeps P symmetric and positive definite.
        ik = np.eye(6) - gain
        self._p = ik @ self._p @ ik.T + gain @ own @ gain.T
        self._position = self._position + step[:3]
        self._rotation = rotation_from_vector(step[3:]) @ self._rotation
        # How far the estimate trails: a steady motion leaves a mean innovation nu and an estimate
        # (I - K) nu behind the frames (a random walk's lag), which P does not hold.
        weight = min(1.0, LAG_WEIGHT * max(self._dt, 1e-3) / self.time_constant_s)
        self._innovation = (1.0 - weight) * self._innovation + weight * innovation
        # Only what the noise cannot explain: a running mean of innovations of covariance s has
        # covariance about weight / (2 - weight) s; its chi-square there is 6 on average for a still
        # card, so the lag counts by the share 1 - 6 / chi-square beyond that.
        spread = s * (weight / (2.0 - weight))
        try:
            chi2 = float(self._innovation @ np.linalg.solve(spread, self._innovation))
        except np.linalg.LinAlgError:
            chi2 = 0.0
        share = max(0.0, 1.0 - 6.0 / chi2) if chi2 > 6.0 else 0.0
        self._lag = math.sqrt(share) * (ik @ self._innovation)
