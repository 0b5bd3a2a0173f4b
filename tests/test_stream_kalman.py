"""The stream's filter (qrfield/stream/kalman.py): seeded poses with Gaussian noise of a known
covariance around a known truth; what it does to the noise, when it resets, how far it trails."""

from __future__ import annotations

import math

import numpy as np
import pytest

from qrfield.geometry import rotation_from_vector, rotation_matrix, rotation_vector
from qrfield.stream.kalman import GAP_S, PoseFilter, shared_scale

FRAME_MS = 1000.0 / 30.0
TRUE_R = rotation_matrix([12.0, -6.0, 25.0])
TRUE_T = np.array([15.0, -8.0, 450.0])
# A frame's std: x, y, z mm; rotation rad (about 0.3, 0.3, 0.05 degrees).
STD = np.array([0.2, 0.2, 1.0, math.radians(0.3), math.radians(0.3), math.radians(0.05)])
COV = np.diag(STD**2)


def _run(filter_: PoseFilter, frames: int, seed: int, *, truth_at=None, key: object = "code"):
    """Feed ``frames`` noisy frames at 30 fps; (estimates, truths) as (k, 6) errors-ready arrays."""
    rng = np.random.default_rng(seed)
    estimates, truths = [], []
    for k in range(frames):
        rotation, position = truth_at(k) if truth_at is not None else (TRUE_R, TRUE_T)
        noise = rng.normal(0.0, STD)
        measured_r = rotation_from_vector(noise[3:]) @ rotation
        estimate = filter_.update(measured_r, position + noise[:3], COV, round(k * FRAME_MS), key)
        estimates.append(estimate)
        truths.append((rotation, position))
    return estimates, truths


def _error(estimate, truth) -> np.ndarray:
    rotation, position = truth
    return np.concatenate([estimate.position_mm - position, rotation_vector(estimate.rotation @ rotation.T)])


def test_a_still_card_with_fresh_noise_is_steadier_filtered_and_its_sigma_covers_the_error() -> None:
    estimates, truths = _run(PoseFilter(0.2), 400, seed=3)
    errors = np.array([_error(e, t) for e, t in zip(estimates[30:], truths[30:], strict=True)])
    assert all(e.filtered for e in estimates[1:]) and not estimates[0].filtered
    # 0.2 s at 30 fps along the noisiest direction of each block (z; alpha and beta): an
    # exponential average of about 6 frames, sqrt(K / (2 - K)) = 0.3 of a frame's noise; the
    # precise directions (x, y; gamma) are followed faster, so smoothed less, but smoothed.
    ratio = errors.std(axis=0) / STD
    assert np.all(ratio[[2, 3, 4]] < 0.45) and np.all(ratio > 0.2) and np.all(ratio < 0.75)
    # Honest: the reported sigma is at least the error's spread (it keeps the frames' shared part,
    # which this white noise does not have, so it is larger here).
    sigma = np.sqrt(np.diag(estimates[-1].cov))
    assert np.all(errors.std(axis=0) <= sigma)
    assert np.all(sigma <= STD)


def test_a_longer_time_constant_smooths_more() -> None:
    spreads = []
    for s in (0.1, 0.2, 0.5):
        estimates, truths = _run(PoseFilter(s), 400, seed=5)
        spreads.append(
            np.array([_error(e, t) for e, t in zip(estimates[60:], truths[60:], strict=True)]).std(axis=0)
        )
    assert np.all(spreads[0] > spreads[1]) and np.all(spreads[1] > spreads[2])


def test_a_jump_the_covariance_cannot_explain_restarts_the_filter_at_the_frame() -> None:
    filter_ = PoseFilter(0.2)
    _run(filter_, 30, seed=1)
    jumped = TRUE_T + np.array([0.0, 0.0, 20.0])  # 20 std of z in one frame
    estimate = filter_.update(TRUE_R, jumped, COV, round(30 * FRAME_MS), "code")
    assert not estimate.filtered and "jump" in estimate.reset
    assert np.array_equal(estimate.position_mm, jumped) and np.array_equal(estimate.cov, COV)
    after = filter_.update(TRUE_R, jumped, COV, round(31 * FRAME_MS), "code")
    assert after.filtered and np.allclose(after.position_mm, jumped)


@pytest.mark.parametrize(
    ("gap_s", "key", "why"), [(GAP_S + 0.05, "code", "gap"), (0.033, "other", "another code")]
)
def test_a_gap_or_another_code_restarts_the_filter(gap_s: float, key: str, why: str) -> None:
    filter_ = PoseFilter(0.2)
    _run(filter_, 10, seed=2)
    t_ms = round(9 * FRAME_MS + gap_s * 1000.0)
    estimate = filter_.update(TRUE_R, TRUE_T + 0.5, COV, t_ms, key)
    assert not estimate.filtered and why in estimate.reset
    assert np.array_equal(estimate.position_mm, TRUE_T + 0.5)


def test_a_steadily_turning_card_is_followed_about_one_time_constant_late() -> None:
    """A random walk trails a steady motion by about S: at 2 deg/s and S = 0.2 s about 0.4 deg."""
    rate = math.radians(2.0)  # rad/s about the camera's x axis
    axis = np.array([1.0, 0.0, 0.0])

    def turning(k: int):
        return rotation_from_vector(axis * rate * k / 30.0) @ TRUE_R, TRUE_T

    filter_ = PoseFilter(0.2)
    estimates, truths = _run(filter_, 240, seed=4, truth_at=turning)
    assert sum(e.filtered for e in estimates) == 239  # it never gave up
    lag = np.array([_error(e, t)[3] for e, t in zip(estimates[90:], truths[90:], strict=True)])
    behind_s = -lag.mean() / rate
    assert 0.05 < behind_s < 0.4
    # The reported sigma holds that lag (the running mean innovation): about one sigma, where the
    # filter's covariance alone would put it at several.
    sigma = np.array([math.sqrt(e.cov[3, 3]) for e in estimates[90:]])
    assert np.sqrt(np.mean((lag / sigma) ** 2)) < 1.5


def test_the_filter_keeps_the_frames_shared_part_in_its_sigma() -> None:
    """FRAME_SHARED_SHARE: after many frames of a still card the reported variance does not fall
    below the shared share of a frame's variance (it cannot be averaged away)."""
    estimates, _ = _run(PoseFilter(2.0), 300, seed=6)
    floor = shared_scale() ** 2 * STD**2
    assert np.all(np.diag(estimates[-1].cov) >= floor * 0.999)


def test_bad_input_is_refused_with_a_clear_error() -> None:
    with pytest.raises(ValueError, match="time constant"):
        PoseFilter(0.0)
    with pytest.raises(ValueError, match="finite"):
        PoseFilter(0.2).update(TRUE_R, TRUE_T, np.full((6, 6), np.nan), 0, "code")
