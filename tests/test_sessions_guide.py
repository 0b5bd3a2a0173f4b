"""The guide of a planned experiment: the grades of a difference against the criteria (hand values),
the stillness rule on pose sequences of known noise, and the guide fed frame by frame as the frame
loop feeds its sinks: a tap, "once still", automatic rows only after a move and near the target."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qrfield.sessions.criteria import FAR, GOOD, NEAR, AcceptanceCriteria
from qrfield.sessions.guide import Guide, GuideSettings
from qrfield.sessions.plan import generate_plan
from qrfield.sessions.stillness import StillnessDetector, StillnessSettings

CRITERIA = AcceptanceCriteria()  # 2 degrees, 5 mm
SIGMA = np.array([0.3, 0.3, 1.0, 0.2, 0.2, 0.1])  # mm, mm, mm, deg, deg, deg


def pose(values, sigma=SIGMA, converged=True) -> dict:
    v = np.asarray(values, dtype=float)
    return {
        "converged": converged,
        "position_mm": v[:3],
        "angles_deg": v[3:],
        "position_std_mm": sigma[:3],
        "angles_std_deg": sigma[3:],
        "iterations": 4,
        "reprojection_px": 0.1,
    }


def frame(t_s: float, values, method="numerical", **kwargs) -> SimpleNamespace:
    """A FrameResult as a sink gets it: capture time in ms and the poses by method."""
    return SimpleNamespace(t_ms=round(t_s * 1000), poses={method: pose(values, **kwargs)})


# ------------------------------------------------------------------------------------ grades
@pytest.mark.parametrize(
    ("position", "angles", "expected_pos", "expected_ang", "distance", "passes"),
    [
        ((1, -2, 3), (0.5, -2.0, 1.9), (GOOD, GOOD, GOOD), (GOOD, GOOD, GOOD), GOOD, True),
        ((4, 4, 0), (2.01, -4.0, 4.01), (GOOD, GOOD, GOOD), (NEAR, NEAR, FAR), NEAR, False),  # 5.66 mm
        ((5, 0, 0), (0, 0, 0), (NEAR, GOOD, GOOD), (GOOD, GOOD, GOOD), NEAR, False),  # 5 mm is not < 5
        ((0, 0, -12), (0, 361.5, 0), (GOOD, GOOD, FAR), (GOOD, GOOD, GOOD), FAR, False),  # 361.5 = 1.5
        ((math.nan, 0, 0), (0, 0, 0), (FAR, GOOD, GOOD), (GOOD, GOOD, GOOD), FAR, False),
    ],
)
def test_grades_of_a_difference_against_the_criteria(
    position, angles, expected_pos, expected_ang, distance, passes
) -> None:
    g = CRITERIA.grade(position, angles)
    assert g.position == expected_pos and g.angles == expected_ang
    assert g.distance == distance and g.passes is passes
    if math.isfinite(position[0]):
        assert g.distance_mm == pytest.approx(math.dist(position, (0, 0, 0)))


def test_grades_follow_tighter_criteria() -> None:
    tight = AcceptanceCriteria(max_angle_error_deg=0.5, max_position_error_mm=1.0)
    g = tight.grade((0.9, 1.5, 2.5), (0.5, 0.9, 1.1))
    assert g.position == (GOOD, NEAR, FAR) and g.angles == (GOOD, NEAR, FAR) and g.distance == FAR


# ------------------------------------------------------------------------------------ stillness
def run(detector: StillnessDetector, times, values_of) -> list:
    return [detector.add(t, pose(values_of(k))) for k, t in enumerate(times)]


def test_a_noisy_still_pose_is_still_after_the_hold_time_and_not_before() -> None:
    rng = np.random.default_rng(7)
    base = np.array([10.0, -5.0, 300.0, 15.0, -20.0, 10.0])
    detector = StillnessDetector(StillnessSettings(hold_s=1.0))
    times = np.arange(0, 3.0, 1 / 30)
    states = run(detector, times, lambda k: base + rng.normal(0, SIGMA))
    first_still = next(t for t, s in zip(times, states, strict=True) if s.still)
    assert first_still == pytest.approx(1.0, abs=1 / 30 + 1e-9)
    assert all(s.still for t, s in zip(times, states, strict=True) if t >= 1.0 + 1 / 30)
    assert np.allclose(states[-1].mean[:3], base[:3], atol=0.5)


def test_a_jump_starts_the_hold_again_and_says_what_moved() -> None:
    base = np.array([0.0, 0.0, 300.0, 0.0, 0.0, 0.0])
    detector = StillnessDetector(StillnessSettings(hold_s=0.5, noise_factor=4.0))
    times = np.arange(0, 1.0, 0.05)
    states = run(detector, times, lambda k: base)
    assert states[-1].still
    moved = base + np.array([0, 0, 0, 0, 1.0, 0])  # 1 deg in beta = 5 sigma of 0.2 deg
    jumped = detector.add(1.0, pose(moved))
    assert not jumped.still and "beta" in jumped.reason and jumped.deviation == pytest.approx(5.0)
    assert detector.moves == 1
    later = [detector.add(1.0 + 0.05 * k, pose(moved)) for k in range(1, 12)]
    first = next(k for k, s in enumerate(later, start=1) if s.still)
    assert first == 10  # 0.5 s after the jump


def test_within_the_noise_band_is_still() -> None:
    base = np.array([0.0, 0.0, 300.0, 0.0, 0.0, 0.0])
    detector = StillnessDetector(StillnessSettings(hold_s=0.3, noise_factor=4.0))
    # alternating +-3.9 sigma in z around the mean (whose own value moves less)
    states = [
        detector.add(0.05 * k, pose(base + np.array([0, 0, 3.9 * (-1) ** k * 0.5, 0, 0, 0])))
        for k in range(20)
    ]
    assert states[-1].still and detector.moves == 0


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(hold=st.floats(min_value=0.2, max_value=2.0), fast=st.booleans(), share=st.floats(0.0, 1.0))
def test_a_steady_turn_is_still_only_below_the_documented_rate(hold: float, fast: bool, share: float) -> None:
    """alpha turns steadily, 30 frames per second, sigma 0.2 deg, band 4 sigma: the newest frame
    lags the mean of the last hold seconds by rate * hold / 2, so (stillness module doc) a turn
    faster than 2 * 4 * 0.2 / hold deg/s is never still and a slower one is, once held."""
    threshold = 2 * 4.0 * 0.2 / hold
    rate = threshold * (1.2 + 3 * share if fast else 0.6 * share)
    detector = StillnessDetector(StillnessSettings(hold_s=hold, noise_factor=4.0))
    base = np.array([0.0, 0.0, 300.0, 0.0, 0.0, 0.0])
    times = np.arange(0, hold * 3, 1 / 30)
    states = [detector.add(t, pose(base + np.array([0, 0, 0, rate * t, 0, 0]))) for t in times]
    if fast:
        assert not any(s.still for s in states)
    else:
        assert states[-1].still and detector.moves == 0


def test_no_pose_no_uncertainty_a_pause_and_a_new_stream_end_the_run() -> None:
    base = np.array([0.0, 0.0, 300.0, 0.0, 0.0, 0.0])
    detector = StillnessDetector(StillnessSettings(hold_s=0.2))
    for k in range(6):
        detector.add(0.05 * k, pose(base))
    assert detector.state.still
    assert not detector.add(0.3, pose(base, converged=False)).still
    assert detector.state.reason == "no converged pose" and detector.moves == 1
    for k in range(6):
        detector.add(0.35 + 0.05 * k, pose(base))
    assert detector.state.still
    no_std = detector.add(0.65, pose(base, sigma=np.full(6, np.nan)))
    assert not no_std.still and "uncertainty" in no_std.reason
    detector.add(0.7, pose(base))
    paused = detector.add(5.0, pose(base))  # 4.3 s without frames, more than the hold
    assert not paused.still and paused.held_s == 0.0
    back = detector.add(1.0, pose(base))  # the clock went back: another stream
    assert not back.still and back.held_s == 0.0


# ------------------------------------------------------------------------------------ guide
TARGETS = generate_plan("alpha,beta", [10, 20], z_mm=300)
N = 4


def values_of(target, offset=(0, 0, 0, 0, 0, 0)) -> np.ndarray:
    return np.array([*target.truth.position_mm, *target.truth.angles_deg], dtype=float) + offset


def feed(guide: Guide, t0: float, seconds: float, values, fps: float = 20.0) -> float:
    t = t0
    while t < t0 + seconds - 1e-9:
        guide.on_result(frame(t, values))
        t += 1 / fps
    return t


def test_a_tap_collects_the_next_frames_and_gives_a_row_with_the_target_as_truth() -> None:
    guide = Guide("numerical", CRITERIA, frames_per_row=N, stillness=StillnessSettings(hold_s=0.5))
    target = TARGETS[1]  # alpha 20
    guide.set_target(target)
    measured = values_of(target, (1.0, 0, 0, 0.5, 0, 0))
    t = feed(guide, 0.0, 0.2, measured)
    view = guide.view()
    assert view.target == target and not view.stillness.still
    assert view.difference == pytest.approx([1.0, 0, 0, 0.5, 0, 0])
    assert view.grades.position[0] == GOOD and view.grades.passes
    assert guide.arm() and not guide.arm()  # one row at a time
    feed(guide, t, (N - 1) / 20, measured)
    assert guide.take() == [] and guide.view().collecting == (N - 1, N)
    guide.on_result(frame(t + 1, measured))
    rows = guide.take()
    assert len(rows) == 1 and rows[0].target == target
    m = rows[0].measurement
    assert m.truth == target.truth  # the target itself is the ground truth
    assert m.average.n_frames == N and m.average.n_converged == N
    assert m.judgement.err_pos_mm == pytest.approx(1.0) and m.judgement.passed


def test_once_still_waits_for_a_fresh_hold_and_the_typed_truth_is_used() -> None:
    guide = Guide("numerical", CRITERIA, frames_per_row=N, stillness=StillnessSettings(hold_s=0.5))
    target = TARGETS[0]
    guide.set_target(target)
    at = values_of(target)
    t = feed(guide, 0.0, 1.0, at)
    assert guide.view().stillness.still
    edited = target.truth.__class__(
        *target.truth.position_mm[:2], 301.0, *target.truth.angles_deg, target.combo
    )
    guide.set_truth(edited)
    assert guide.view().difference[2] == pytest.approx(-1.0)
    assert guide.arm(when_still=True)
    view = guide.view()
    assert view.waiting and not view.stillness.still  # the hold starts after the request
    t = feed(guide, t, 0.45, at)
    assert guide.view().collecting is None
    feed(guide, t, 0.1 + N / 20, at)
    rows = guide.take()
    assert len(rows) == 1 and rows[0].measurement.truth == edited


def test_auto_logs_only_after_a_move_and_near_the_target() -> None:
    guide = Guide(
        "numerical",
        CRITERIA,
        frames_per_row=N,
        stillness=StillnessSettings(hold_s=0.3),
        settings=GuideSettings(auto_gate=3.0),
    )
    first, second = TARGETS[0], TARGETS[1]  # alpha 10, alpha 20
    guide.set_auto(True)
    guide.set_target(first)
    t = feed(guide, 0.0, 1.0, values_of(first))  # still at the target, but it never moved
    assert guide.take() == []
    assert "move the card" in guide.view().auto_reason
    t = feed(guide, t, 0.1, values_of(first, (0, 0, 0, 5, 0, 0)))  # picked up ...
    t = feed(guide, t, 1.0, values_of(first))  # ... and put back: logged by itself
    rows = guide.take()
    assert [r.target for r in rows] == [first]
    guide.set_target(second)
    t = feed(guide, t, 1.0, values_of(first))  # still where the last row was: not logged for target 2
    assert guide.take() == []
    t = feed(guide, t, 1.0, values_of(second, (0, 0, 0, -7, 0, 0)))  # moved, still, 7 deg off: gate
    assert guide.take() == [] and "3 x the criteria" in guide.view().auto_reason
    t = feed(guide, t, 1.0, values_of(second, (0, 0, 0, 0.4, 0, 0)))
    rows = guide.take()
    assert [r.target for r in rows] == [second]
    assert rows[0].measurement.judgement.err_angles_deg[0] == pytest.approx(0.4)


def test_frames_that_stop_give_up_the_row() -> None:
    guide = Guide("numerical", CRITERIA, frames_per_row=N)
    guide.set_target(TARGETS[0])
    guide.arm()
    guide.on_result(frame(0.0, values_of(TARGETS[0])))
    guide.on_source_down("no frame for 1.0 s")
    view = guide.view()
    assert view.collecting is None and "1 of 4" in view.problem
    assert guide.take() == []


def test_another_method_and_frames_without_a_pose() -> None:
    guide = Guide("ippe", CRITERIA, frames_per_row=2)
    guide.set_target(TARGETS[0])
    guide.on_result(frame(0.0, values_of(TARGETS[0])))  # a numerical pose only: nothing for ippe
    assert guide.view().grades is None and guide.view().stillness.reason == "no converged pose"
    guide.arm()
    guide.on_result(frame(0.1, values_of(TARGETS[0])))
    guide.on_result(frame(0.2, values_of(TARGETS[0]), method="ippe"))
    (row,) = guide.take()
    assert row.measurement.average.n_frames == 2 and row.measurement.average.n_converged == 1
