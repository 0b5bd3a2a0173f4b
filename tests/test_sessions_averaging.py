"""Averaging frames into a row: circular means, deviations, errors and the criteria, by hand."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from qrfield.sessions import (
    AcceptanceCriteria,
    FrameCollector,
    GroundTruth,
    average_frames,
    circular_mean_deg,
    judge_row,
    measure,
)


def frame(pos, ang, converged=True, iterations=4, reprojection_px=0.2):
    return SimpleNamespace(
        position_mm=pos,
        angles_deg=ang,
        converged=converged,
        iterations=iterations,
        reprojection_px=reprojection_px,
    )


def test_circular_mean_across_the_wrap():
    assert circular_mean_deg([179.0, -179.0]) == pytest.approx(180.0)
    assert circular_mean_deg([179.0, -179.0, 180.0]) == pytest.approx(180.0)
    # sin: -0.173648 + 0.173648 + 0.342020; cos: -0.984808 - 0.984808 - 0.939693
    # -> atan2(0.342020, -2.909308) = 180 - atan(0.117561) = 180 - 6.7050 = 173.2950 deg.
    assert circular_mean_deg([-170.0, 170.0, 160.0]) == pytest.approx(173.2950, abs=1e-3)
    assert circular_mean_deg([10.0, 20.0]) == pytest.approx(15.0)
    assert math.isnan(circular_mean_deg([]))


def test_three_frames_by_hand():
    frames = [
        frame([10.0, 20.0, 300.0], [179.0, 1.0, -2.0], iterations=3, reprojection_px=0.1),
        frame([12.0, 20.0, 303.0], [-179.0, 2.0, -3.0], iterations=5, reprojection_px=0.3),
        frame([14.0, 23.0, 297.0], [180.0, 3.0, -4.0], iterations=4, reprojection_px=0.2),
        frame([99.0, 99.0, 99.0], [50.0, 50.0, 50.0], converged=False),  # counted, not averaged
        None,  # no code in this frame
    ]
    avg = average_frames(frames)
    assert (avg.n_frames, avg.n_converged) == (5, 3)
    np.testing.assert_allclose(avg.position_mm, [12.0, 21.0, 300.0])
    np.testing.assert_allclose(avg.angles_deg, [180.0, 2.0, -3.0], atol=1e-9)
    # Sample deviations: x 10,12,14 -> 2; y 20,20,23 -> sqrt(3); z 300,303,297 -> 3;
    # alpha -1,+1,0 about 180 -> 1; beta 1,2,3 -> 1; gamma -> 1.
    np.testing.assert_allclose(avg.std_position_mm, [2.0, math.sqrt(3.0), 3.0])
    np.testing.assert_allclose(avg.std_angles_deg, [1.0, 1.0, 1.0], atol=1e-9)
    assert avg.mean_iterations == pytest.approx(4.0)
    assert avg.mean_reprojection_px == pytest.approx(0.2)

    truth = GroundTruth(12.0, 21.0, 304.0, 179.0, 0.5, -1.0, "alpha")
    row = measure(frames, truth)
    # err_pos = |(0, 0, -4)| = 4 mm; alpha 180 - 179 = +1; beta 2 - 0.5 = 1.5; gamma -3 - -1 = -2.
    assert row.judgement.err_pos_mm == pytest.approx(4.0)
    np.testing.assert_allclose(row.judgement.err_angles_deg, [1.0, 1.5, -2.0], atol=1e-9)
    assert row.judgement.passed  # 4 < 5 mm and every |angle error| <= 2 deg


def test_dicts_are_accepted_as_frames():
    avg = average_frames([{"position_mm": [0, 0, 100], "angles_deg": [0, 0, 0], "converged": True}])
    assert avg.n_converged == 1
    assert np.all(np.isnan(avg.std_position_mm))  # one frame: no deviation


def test_no_converged_frame_never_passes():
    truth = GroundTruth(0, 0, 300, 0, 0, 0, "alpha")
    row = measure([None, frame([0, 0, 300], [0, 0, 0], converged=False)], truth)
    assert (row.average.n_frames, row.average.n_converged) == (2, 0)
    assert not row.judgement.passed
    assert math.isnan(row.judgement.err_pos_mm)
    assert row.judgement.reason == "no converged frame"


@pytest.mark.parametrize(
    ("pos", "ang", "passed"),
    [
        ([0.0, 3.0, 304.0], [0.0, 0.0, 0.0], False),  # exactly 5 mm: the position rule is strict
        ([0.0, 3.0, 303.9], [0.0, 0.0, 0.0], True),
        ([0.0, 0.0, 300.0], [2.0, -2.0, 2.0], True),  # exactly 2 deg: the angle rule is inclusive
        ([0.0, 0.0, 300.0], [0.0, 0.0, -2.01], False),
    ],
)
def test_criteria_boundaries(pos, ang, passed):
    truth = GroundTruth(0.0, 0.0, 300.0, 0.0, 0.0, 0.0, "alpha")
    assert judge_row(pos, ang, truth).passed is passed


def test_angle_errors_are_wrapped():
    truth = GroundTruth(0.0, 0.0, 300.0, 179.0, 0.0, -179.5, "gamma")
    result = judge_row([0, 0, 300], [-179.0, 0.0, 179.5], truth)
    np.testing.assert_allclose(result.err_angles_deg, [2.0, 0.0, -1.0])
    assert result.passed


def test_criteria_are_settings():
    truth = GroundTruth(0.0, 0.0, 300.0, 0.0, 0.0, 0.0, "alpha")
    strict = AcceptanceCriteria(max_angle_error_deg=0.5, max_position_error_mm=1.0)
    assert judge_row([0, 0, 300.5], [0.4, 0, 0], truth, strict).passed
    assert not judge_row([0, 0, 300.5], [0.6, 0, 0], truth, strict).passed
    assert "alpha error +0.60 deg" in judge_row([0, 0, 300.5], [0.6, 0, 0], truth, strict).reason


def test_frame_collector_progress():
    collector = FrameCollector(3)
    assert collector.progress == (0, 3)
    assert not collector.add(frame([0, 0, 300], [0, 0, 0]))
    assert not collector.add(None)
    assert collector.add(frame([0, 0, 302], [0, 0, 0]))
    assert collector.add(frame([50, 0, 300], [0, 0, 0]))  # ignored: already full
    row = collector.measurement(GroundTruth(0, 0, 301, 0, 0, 0, "alpha"))
    assert (row.average.n_frames, row.average.n_converged) == (3, 2)
    assert row.judgement.err_pos_mm == pytest.approx(0.0)
    with pytest.raises(ValueError, match="at least 1"):
        FrameCollector(0)


def test_pipeline_frames_give_the_chosen_methods_result():
    def pipeline_frame(numerical_z, ippe_z):
        return SimpleNamespace(
            poses={
                "numerical": frame([0, 0, numerical_z], [0, 0, 0]),
                "ippe": frame([0, 0, ippe_z], [0, 0, 0]),
            }
        )

    frames = [pipeline_frame(300.0, 310.0), pipeline_frame(302.0, 312.0), SimpleNamespace(poses={})]
    truth = GroundTruth(0, 0, 301, 0, 0, 0, "alpha")
    collector = FrameCollector(3, method="ippe")
    for f in frames:
        collector.add(f)
    row = collector.measurement(truth)
    assert row.method == "ippe"
    assert (row.average.n_frames, row.average.n_converged) == (3, 2)
    assert row.average.position_mm[2] == pytest.approx(311.0)
    # Without a method, a pipeline frame's first method is used.
    assert average_frames(frames).position_mm[2] == pytest.approx(301.0)


def test_sigma_is_the_mean_per_frame_uncertainty_and_std_the_frame_to_frame_spread():
    """Two kinds of spread, by hand: std_* over the frames' values, sigma_* the mean of their own
    reported stds (over the converged frames that report one; NaN where none does)."""
    frames = [
        {
            "position_mm": [0, 0, 300],
            "angles_deg": [0, 0, 0],
            "converged": True,
            "position_std_mm": [0.1, 0.2, 1.0],
            "angles_std_deg": [0.5, 0.4, 0.1],
        },
        {
            "position_mm": [0, 0, 302],
            "angles_deg": [2, 0, 0],
            "converged": True,
            "position_std_mm": [0.3, 0.2, 2.0],
            "angles_std_deg": [0.7, np.nan, 0.3],
        },
        {"position_mm": [0, 0, 304], "angles_deg": [4, 0, 0], "converged": True},  # no std known
        {
            "position_mm": [9, 9, 999],
            "angles_deg": [9, 9, 9],
            "converged": False,
            "position_std_mm": [50.0, 50.0, 50.0],
            "angles_std_deg": [50.0, 50.0, 50.0],
        },  # not averaged
    ]
    avg = average_frames(frames)
    np.testing.assert_allclose(avg.std_position_mm, [0.0, 0.0, 2.0])  # z 300, 302, 304
    np.testing.assert_allclose(avg.std_angles_deg, [2.0, 0.0, 0.0], atol=1e-9)  # alpha 0, 2, 4
    np.testing.assert_allclose(avg.sigma_position_mm, [0.2, 0.2, 1.5])
    np.testing.assert_allclose(avg.sigma_angles_deg, [0.6, 0.4, 0.2])  # beta: only the first has one
    plain = average_frames([frame([0, 0, 300], [0, 0, 0]), frame([0, 0, 301], [0, 0, 0])])
    assert np.all(np.isnan(plain.sigma_position_mm)) and np.all(np.isnan(plain.sigma_angles_deg))
    with pytest.raises(ValueError, match="position_std_mm needs 3 values"):
        average_frames([{**frames[0], "position_std_mm": [0.1, 0.2]}])


def test_a_row_misfits_when_most_of_its_frames_do_not_when_one_does():
    """A right camera model and side still put about 1 % of frames above FIT_CHI2 (chi-square(2)
    0.99), so a row of 10 with one misfit frame is not a misfit row; one with 6 of 10 is (a wrong
    model or side misfits every frame); the count is kept either way."""
    from qrfield.solvers.uncertainty import FIT_CHI2

    def framed(misfit: bool) -> SimpleNamespace:
        f = frame([0.0, 0.0, 300.0], [1.0, 2.0, 3.0])
        f.chi2 = 2.0 * FIT_CHI2 if misfit else 1.0
        f.misfit = misfit
        return f

    one = average_frames([framed(i == 0) for i in range(10)])
    most = average_frames([framed(i < 6) for i in range(10)])
    assert (one.n_misfit, one.mostly_misfit) == (1, False)
    assert (most.n_misfit, most.mostly_misfit) == (6, True)
