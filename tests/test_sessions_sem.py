"""The standard uncertainty of a row's (and a MEAS answer's) mean: frames of a still card share most
of their error, so it is not the spread / sqrt(n). Checked by hand and against seeded still cards
drawn with a shared error (FRAME_SHARED_SHARE of each frame's variance) and fresh noise per frame."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from qrfield.sessions import average_frames
from qrfield.sessions.averaging import mean_uncertainty
from qrfield.solvers.uncertainty import FRAME_SHARED_SHARE
from qrfield.stream import StreamMark

RHO = np.asarray(FRAME_SHARED_SHARE)


def _frame(position, angles, sigma):
    return SimpleNamespace(
        position_mm=np.asarray(position, float),
        angles_deg=np.asarray(angles, float),
        converged=True,
        position_std_mm=np.asarray(sigma[:3], float),
        angles_std_deg=np.asarray(sigma[3:], float),
    )


def test_the_mean_uncertainty_by_hand() -> None:
    # Four frames, each sigma 1 in every component; z 299, 301, 299, 301 (s = 1.1547).
    frames = [_frame([0, 0, z], [0, 0, 0], [1.0] * 6) for z in (299.0, 301.0, 299.0, 301.0)]
    mean = average_frames(frames)
    rho_z = RHO[2]
    s2 = 4.0 / 3.0
    assert mean.sem_position_mm[2] == pytest.approx(math.sqrt(rho_z + max(s2, 1 - rho_z) / 4))
    # x never moved: the frames' own part is taken as (1 - rho) sigma^2, not as 0.
    assert mean.sem_position_mm[0] == pytest.approx(math.sqrt(RHO[0] + (1 - RHO[0]) / 4))
    assert mean.sem_angles_deg[0] == pytest.approx(math.sqrt(RHO[3] + (1 - RHO[3]) / 4))
    # One frame: its own sigma.
    assert average_frames(frames[:1]).sem_position_mm == pytest.approx([1.0, 1.0, 1.0])


def test_filtered_frames_keep_their_sigma_as_the_mean_uncertainty() -> None:
    frames = [_frame([0, 0, 300 + 0.01 * k], [0, 0, 0], [0.5] * 6) for k in range(10)]
    results = [
        SimpleNamespace(poses={"ippe": f}, stream={"ippe": StreamMark("frame", True, False)}) for f in frames
    ]
    mean = average_frames(results)
    assert mean.filtered and mean.n_filtered == 10
    assert mean.sem_position_mm == pytest.approx([0.5, 0.5, 0.5]) and mean.sem_angles_deg == pytest.approx(
        [0.5] * 3
    )


def test_frames_resolved_by_history_are_counted() -> None:
    frames = [_frame([0, 0, 300], [0, 0, 0], [0.5] * 6) for _ in range(3)]
    marks = ["history", "frame", "history"]
    results = [
        SimpleNamespace(poses={"numerical": f}, stream={"numerical": StreamMark(m, False, m == "history")})
        for f, m in zip(frames, marks, strict=True)
    ]
    mean = average_frames(results)
    assert mean.n_resolved_by_history == 2 and not mean.filtered


@pytest.mark.slow
@pytest.mark.parametrize("n", [1, 5, 20])
def test_on_still_cards_the_mean_uncertainty_covers_the_error_and_the_naive_one_does_not(n: int) -> None:
    """3000 seeded still cards: each has a sigma per component (0.05-2, log-uniform), an error shared
    by its frames (variance rho sigma^2) and fresh noise per frame ((1 - rho) sigma^2)."""
    rng = np.random.default_rng(25)
    ours, naive = [], []
    for _ in range(3000):
        sigma = np.exp(rng.uniform(math.log(0.05), math.log(2.0), 6))
        shared = rng.normal(0.0, np.sqrt(RHO) * sigma)
        own = rng.normal(0.0, np.sqrt(1.0 - RHO) * sigma, (n, 6))
        errors = shared + own
        frames = [_frame(np.array([0.0, 0.0, 300.0]) + e[:3], e[3:], sigma) for e in errors]
        mean = average_frames(frames)
        error = np.concatenate([mean.position_mm - [0, 0, 300], mean.angles_deg])
        ours.append(error / np.concatenate([mean.sem_position_mm, mean.sem_angles_deg]))
        if n > 1:
            naive.append(error / (np.concatenate([mean.std_position_mm, mean.std_angles_deg]) / math.sqrt(n)))
    rms = np.sqrt(np.mean(np.array(ours) ** 2, axis=0))
    assert np.all(rms > 0.85) and np.all(rms < 1.1)
    if n > 1:
        assert np.all(np.sqrt(np.nanmean(np.array(naive) ** 2, axis=0)) > 1.5)


def test_without_a_frame_sigma_the_spread_is_taken_as_the_frames_own_part() -> None:
    sem = mean_uncertainty(np.full(6, np.nan), np.full(6, 0.4), 8, False)
    assert sem == pytest.approx(0.4 * np.sqrt(RHO / (1 - RHO) + 1 / 8))
    assert np.all(np.isnan(mean_uncertainty(np.full(6, np.nan), np.full(6, np.nan), 1, False)))


def test_a_logged_row_records_the_mean_uncertainty_and_whether_the_filter_was_on(
    tmp_path, camera_vga
) -> None:
    import csv

    from qrfield.sessions import GroundTruth, Session, measure

    frames = [_frame([0, 0, z], [0, 0, 0], [1.0] * 6) for z in (299.0, 301.0, 299.0, 301.0)]
    filtered = [
        SimpleNamespace(poses={"numerical": f}, stream={"numerical": StreamMark("history", True, True)})
        for f in frames
    ]
    session = Session.create(tmp_path, "sem", camera=camera_vga, side_mm=50.0, solver="numerical")
    truth = GroundTruth(0, 0, 300, 0, 0, 0, "still")
    assert session.log(measure(frames, truth)).ok
    assert session.log(measure(filtered, truth)).ok
    with session.rows_path.open(encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    rho_z = RHO[2]
    assert rows[0]["sem_z"] == f"{math.sqrt(rho_z + max(4 / 3, 1 - rho_z) / 4):.3f}"
    assert rows[0]["filtered"] == "0" and rows[0]["resolved_by_history"] == "0"
    assert (
        rows[1]["sem_z"] == "1.000" and rows[1]["filtered"] == "1" and rows[1]["resolved_by_history"] == "4"
    )
    assert rows[0]["n_misfit"] == rows[1]["n_misfit"] == "0"


def test_a_logged_row_counts_its_frames_that_misfit_their_corners(tmp_path, camera_vga) -> None:
    """Two of four frames with a chi-square above FIT_CHI2 (PoseResult.misfit): the row's
    ``n_misfit`` is 2 in rows.csv."""
    import csv

    from qrfield.sessions import GroundTruth, Session, measure
    from qrfield.solvers.uncertainty import FIT_CHI2, is_misfit

    frames = [_frame([0, 0, z], [0, 0, 0], [1.0] * 6) for z in (299.0, 301.0, 299.0, 301.0)]
    for k, f in enumerate(frames):
        f.chi2 = 3.0 * FIT_CHI2 if k < 2 else 1.0
        f.misfit = is_misfit(f.chi2)
    session = Session.create(tmp_path, "misfit", camera=camera_vga, side_mm=50.0, solver="numerical")
    assert session.log(measure(frames, GroundTruth(0, 0, 300, 0, 0, 0, "still"))).ok
    with session.rows_path.open(encoding="utf-8") as f:
        (row,) = list(csv.DictReader(f))
    assert row["n_misfit"] == "2"
