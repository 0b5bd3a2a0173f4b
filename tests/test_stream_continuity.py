"""Branch continuity (qrfield/stream/continuity.py through the stream stage): an ambiguous frame takes
the branch its recent history points to, against the truth of cv2.projectPoints (tests/stream_cases.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from stream_cases import SIDE_MM, TEXT, TRUTH, frame_result, solved, wrong_branch_seeds

from qrfield.geometry import Pose, rotation_angle_deg
from qrfield.status import Reported
from qrfield.stream import StreamSettings, StreamStage

NOISE = 0.15
QUIET = 0.005  # corner noise of the history's frame: unambiguous


def _history_then(
    stage: StreamStage, seed: int, *, dt_ms: int = 33, text: str = TEXT, method: str = "numerical"
):
    """Two unambiguous frames of the still card at t = -33 and 0 ms, then the ambiguous frame of
    ``seed`` dt_ms later; its result."""
    for index, t_ms in enumerate((-33, 0)):
        quiet = frame_result(solved(10_000 + 7 * seed + index, QUIET, method), index, t_ms, noise_px=QUIET)
        stage.apply(quiet, SIDE_MM, quiet.detection.pose_cov)
        assert not quiet.ambiguous and quiet.resolved_by == "frame"
    result = frame_result(solved(seed, NOISE, method), 2, dt_ms, text=text, noise_px=NOISE)
    stage.apply(result, SIDE_MM, result.detection.pose_cov)
    return result


def _rms_reprojection(pose: Pose, corners: np.ndarray) -> float:
    from stream_cases import true_corners

    return float(np.sqrt(np.mean(np.sum((true_corners(pose) - corners) ** 2, axis=1))))


@pytest.mark.parametrize("method", ["numerical", "ippe"])
def test_an_ambiguous_frame_on_the_wrong_branch_takes_the_mirror_its_history_points_to(method: str) -> None:
    seeds = wrong_branch_seeds(4, method, NOISE)
    assert len(seeds) == 4
    for seed in seeds:
        frame = solved(seed, NOISE, method)
        result = _history_then(StreamStage(), seed, method=method)
        pose, mark = result.poses[method], result.stream[method]
        assert mark.frame_ambiguous and mark.resolved_by == "history" and mark.flipped
        assert not result.ambiguous and result.reported_status(simulated=False) == Reported.OK
        # The mirror's own numbers, nearer the truth than the frame's answer.
        assert np.allclose(pose.position_mm, frame.alternative.position_mm)
        assert np.allclose(pose.rotation, frame.alternative.rotation)
        assert (
            rotation_angle_deg(pose.rotation, TRUTH.rotation)
            < rotation_angle_deg(frame.rotation, TRUTH.rotation) - 3
        )
        # Consistent: angles of the rotation, reprojection of that pose against the corners (cv2).
        assert np.allclose(Pose(pose.position_mm, pose.angles_deg).rotation, pose.rotation, atol=1e-9)
        reported = Pose(pose.position_mm, pose.angles_deg)
        assert pose.reprojection_px == pytest.approx(_rms_reprojection(reported, frame.corners_px), rel=1e-6)
        assert np.all(np.isfinite(pose.angles_std_deg)) and np.all(np.isfinite(pose.position_std_mm))
        # What the frame alone said is kept beside it.
        assert result.frame_poses[method] is not pose and result.frame_poses[method].ambiguous
        line = json.loads(json.dumps(result.to_json_dict(simulated=False)))
        assert line["resolved_by"] == "history" and line["ambiguous"] is False and line["status"] == "OK"
        assert line["filtered"] is False


def test_without_history_an_ambiguous_frame_stays_ambiguous() -> None:
    seed = wrong_branch_seeds(1)[0]
    result = frame_result(solved(seed, NOISE), 0, 0, noise_px=NOISE)
    StreamStage().apply(result, SIDE_MM, result.detection.pose_cov)
    assert result.ambiguous and result.resolved_by == "frame"
    assert result.reported_status(simulated=False) == Reported.AMBIG
    assert result.poses["numerical"] is result.frame_poses["numerical"]  # reported as the frame made it


FRONTAL = Pose([0.0, 0.0, 250.0], [0.4, -0.3, 15.0])  # nearly square-on: the branches merge
FRONTAL_NOISE = 0.03


@pytest.mark.parametrize("method", ["numerical", "ippe"])
def test_without_history_a_frame_whose_corners_have_one_branch_is_reported_widened_to_its_plane(
    method: str,
) -> None:
    """Nearly square-on, the mirror search from the reflected plane ends at the answer (one minimum)
    while the plane fits about as well: no flip to decide, so the first frame is reported (OK, by
    the frame), its std widened to cover the plane, and within 4 of it from the drawn truth."""
    reported = 0
    for seed in range(12):
        frame = solved(seed, FRONTAL_NOISE, method, pose=FRONTAL)
        if not frame.ambiguous:
            continue
        result = frame_result(frame, 0, 0, noise_px=FRONTAL_NOISE)
        result.truth = FRONTAL
        StreamStage().apply(result, SIDE_MM, result.detection.pose_cov)
        pose = result.poses[method]
        assert not result.ambiguous and result.resolved_by == "frame"
        assert result.reported_status(simulated=False) == Reported.OK
        assert np.array_equal(pose.rotation, frame.rotation)  # its own branch, not moved
        assert np.all(pose.angles_std_deg[:2] >= frame.angles_std_deg[:2] - 1e-12)
        error = np.abs(np.asarray(pose.angles_deg) - np.asarray(FRONTAL.angles_deg))
        assert np.all(error <= 4.0 * np.asarray(pose.angles_std_deg)), (seed, error, pose.angles_std_deg)
        reported += 1
    assert reported >= 6  # the case is common there (every frame but few is ambiguous alone)


@pytest.mark.parametrize(
    ("dt_ms", "text"),
    [(600, TEXT), (33, "another code")],
    ids=["history older than 0.5 s", "another code"],
)
def test_history_too_old_or_of_another_code_does_not_decide(dt_ms: int, text: str) -> None:
    seed = wrong_branch_seeds(1)[0]
    result = _history_then(StreamStage(), seed, dt_ms=dt_ms, text=text)
    assert result.ambiguous and result.resolved_by == "frame"
    assert not result.stream["numerical"].flipped


def test_continuity_off_solves_every_frame_alone() -> None:
    seed = wrong_branch_seeds(1)[0]
    result = _history_then(StreamStage(StreamSettings(continuity=False)), seed)
    frame = solved(seed, NOISE)
    assert result.ambiguous and result.resolved_by == "frame"
    assert np.array_equal(result.poses["numerical"].rotation, frame.rotation)


@pytest.mark.parametrize("method", ["numerical", "ippe"])
def test_an_unambiguous_frame_is_reported_as_it_is(method: str) -> None:
    """Its pose, branch and flag; IPPE's std too, and the first frame's. From the second frame on
    the numerical model's std is at least its own (raised to what the corners' best fit allows:
    qrfield/stream/crosscheck.py, tests/test_stream_crosscheck.py)."""
    stage = StreamStage()
    for index in range(3):
        result = frame_result(solved(20_000 + index, QUIET, method), index, 33 * index, noise_px=QUIET)
        frame = result.poses[method]
        stage.apply(result, SIDE_MM, result.detection.pose_cov)
        reported = result.poses[method]
        assert result.resolved_by == "frame" and not result.filtered and not reported.ambiguous
        if method == "ippe" or index == 0:
            assert reported is frame
            continue
        assert np.array_equal(reported.rotation, frame.rotation)
        assert np.array_equal(reported.position_mm, frame.position_mm)
        assert np.all(reported.angles_std_deg >= frame.angles_std_deg)
        assert np.all(reported.position_std_mm >= frame.position_std_mm)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seeds=st.lists(st.integers(0, 10**6), min_size=2, max_size=8),
    noise=st.floats(0.03, 0.25),
    method=st.sampled_from(["numerical", "ippe"]),
)
def test_a_stream_reports_one_of_each_frames_branches_and_flags_what_it_did_not_decide(
    seeds: list[int], noise: float, method: str
) -> None:
    stage = StreamStage()
    for index, seed in enumerate(seeds):
        result = frame_result(solved(seed, noise, method), index, 33 * index, noise_px=noise)
        frame = result.frame_poses.get(method) or result.poses[method]
        stage.apply(result, SIDE_MM, result.detection.pose_cov)
        if not frame.converged:
            continue
        pose, mark = result.poses[method], result.stream[method]
        branches = [frame.rotation] + ([frame.alternative.rotation] if frame.alternative is not None else [])
        assert min(float(np.abs(pose.rotation - b).max()) for b in branches) < 1e-12
        assert mark.frame_ambiguous == frame.ambiguous
        # still flagged only what the frame left ambiguous and the history did not decide; a frame
        # ambiguous alone reported by the frame has one branch (no distinct mirror): its own pose,
        # its std widened, never narrowed
        assert not pose.ambiguous or (frame.ambiguous and mark.resolved_by == "frame")
        if frame.ambiguous and mark.resolved_by == "frame" and not pose.ambiguous:
            assert np.array_equal(pose.rotation, frame.rotation)
            assert np.all(pose.angles_std_deg >= frame.angles_std_deg - 1e-9)
        assert mark.flipped == (not np.array_equal(pose.rotation, frame.rotation))


def test_the_mirror_chosen_is_widened_towards_the_answer_it_was_confused_with() -> None:
    """The frame was ambiguous: along the turn between its two branches the corners' chi-square
    rises by only d, so the reported std there is at least that turn / sqrt(d)."""
    from qrfield.geometry import rotation_vector
    from qrfield.stream.poses import vector_cov

    for seed in wrong_branch_seeds(3):
        frame = solved(seed, NOISE)
        pose = _history_then(StreamStage(), seed).poses["numerical"]
        turn = rotation_vector(frame.rotation @ pose.rotation.T)
        axis = turn / np.linalg.norm(turn)
        rise = max(abs(pose.mirror_chi2 - pose.chi2), 1.0)
        along = float(axis @ vector_cov(pose)[3:, 3:] @ axis)
        assert along >= 0.999 * float(turn @ turn) / rise


def _near_fold_seeds(count: int, noise: float = 0.03) -> list[tuple[int, str]]:
    """(seed, method) of unambiguous frames of the stream case whose mirror fits within
    NEAR_FOLD_CHI2 of the answer (about 80 % of them at 0.03 px)."""
    from qrfield.stream.continuity import NEAR_FOLD_CHI2

    out = []
    for seed in range(200):
        for method in ("numerical", "ippe"):
            r = solved(seed, noise, method)
            if r.converged and not r.ambiguous and r.mirror_chi2 - r.chi2 < NEAR_FOLD_CHI2:
                out.append((seed, method))
                if len(out) == count:
                    return out
    return out


def test_an_unambiguous_frame_near_the_fold_is_widened_towards_its_mirror() -> None:
    """Its mirror fits within d < NEAR_FOLD_CHI2: the reported variance along the turn to the
    mirror is at least turn^2 / d (computed here from the two branches), the pose itself is the
    frame's, and the flag stays down; with continuity off the frame is reported as it is."""
    from qrfield.geometry import rotation_vector
    from qrfield.stream.poses import vector_cov

    cases = _near_fold_seeds(4)
    assert len(cases) == 4
    for index, (seed, method) in enumerate(cases):
        result = frame_result(solved(seed, 0.03, method), index, 0, noise_px=0.03)
        frame = result.poses[method]
        StreamStage().apply(result, SIDE_MM, result.detection.pose_cov)
        pose = result.poses[method]
        assert np.array_equal(pose.rotation, frame.rotation) and not pose.ambiguous
        turn = rotation_vector(frame.alternative.rotation @ frame.rotation.T)
        axis = turn / np.linalg.norm(turn)
        along = float(axis @ vector_cov(pose)[3:, 3:] @ axis)
        assert along >= 0.999 * float(turn @ turn) / (frame.mirror_chi2 - frame.chi2)
        assert along > 1.5 * float(axis @ vector_cov(frame)[3:, 3:] @ axis)
        alone = frame_result(solved(seed, 0.03, method), index, 0, noise_px=0.03)
        StreamStage(StreamSettings(continuity=False)).apply(alone, SIDE_MM, alone.detection.pose_cov)
        assert np.array_equal(alone.poses[method].angles_std_deg, frame.angles_std_deg)


def test_the_filter_counts_a_frames_widening_as_shared_in_full() -> None:
    """The filter reports rho of the frames' variance as shared and averages the rest: the
    widening's (1 - rho) is added back (rho the angles' mean FRAME_SHARED_SHARE, by hand)."""
    from qrfield.solvers.uncertainty import FRAME_SHARED_SHARE
    from qrfield.stream.continuity import Decision
    from qrfield.stream.stage import shared_widening

    rho = float(np.mean(FRAME_SHARED_SHARE[3:]))
    extra = np.diag([4e-4, 1e-4, 0.0])
    base = np.diag([1.0, 2.0, 3.0, 1e-5, 2e-5, 3e-5])
    decision = Decision(solved(0, 0.03), "frame", False, widening=extra)
    out = shared_widening(base, decision)
    assert np.allclose(out[:3, :3], base[:3, :3]) and np.allclose(out[:3, 3:], 0.0)
    assert np.allclose(out[3:, 3:], base[3:, 3:] + (1.0 - rho) * extra)
    assert shared_widening(base, Decision(solved(0, 0.03), "frame", False)) is base


def _tilt_plane_floor(frame) -> tuple[np.ndarray, float]:
    """(the unit line of sight to the code's centre, the variance turn^2 / max(d, 1) every tilt
    direction must reach), by hand: the turn between the frame's two branches and the rise d of
    the chi-square to the mirror in the units of the answer's own fit (chi2 over its 2 degrees of
    freedom, when above 1)."""
    from qrfield.geometry import rotation_vector

    turn = rotation_vector(frame.alternative.rotation @ frame.rotation.T)
    rise = (frame.mirror_chi2 - frame.chi2) / max(1.0, frame.chi2 / 2.0)
    sight = frame.position_mm / np.linalg.norm(frame.position_mm)
    return sight, float(turn @ turn) / max(rise, 1.0)


def _least_tilt_variance(rotation_cov: np.ndarray, sight: np.ndarray) -> float:
    """The smallest variance of ``rotation_cov`` (3, 3) over the directions perpendicular to ``sight``."""
    a = np.cross(sight, [1.0, 0.0, 0.0] if abs(sight[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    basis = np.column_stack([a, np.cross(sight, a)])
    return float(np.linalg.eigvalsh(basis.T @ rotation_cov @ basis)[0])


def test_near_the_fold_every_direction_of_tilt_is_widened_not_only_the_turn() -> None:
    """Near the fold the tilt is as poorly known across the turn to the mirror as along it: every
    direction of tilt (perpendicular to the line of sight) gets at least turn^2 / d, also where
    the frame's own covariance was thinner than that across the turn; the roll about the line of
    sight keeps the frame's variance."""
    from qrfield.stream.poses import vector_cov

    thin = 0
    for index, (seed, method) in enumerate(_near_fold_seeds(8)):
        result = frame_result(solved(seed, 0.03, method), index, 0, noise_px=0.03)
        frame = result.poses[method]
        StreamStage().apply(result, SIDE_MM, result.detection.pose_cov)
        sight, wanted = _tilt_plane_floor(frame)
        own = vector_cov(frame)[3:, 3:]
        reported = vector_cov(result.poses[method])[3:, 3:]
        thin += _least_tilt_variance(own, sight) < 0.5 * wanted
        assert _least_tilt_variance(reported, sight) >= 0.999 * wanted
        assert float(sight @ reported @ sight) >= float(sight @ own @ sight) * (1.0 - 1e-9)
    assert thin >= 4  # the cases do test the directions the turn alone would have left thin


def test_a_poor_fit_counts_the_rise_to_the_mirror_in_its_own_units() -> None:
    """A frame whose answer fits the corners worse than their covariance allows (chi2 above its 2
    degrees of freedom) has its rise to the mirror divided by chi2 / 2 before the near-fold test:
    a rise of 1.5 NEAR_FOLD_CHI2 is near the fold at chi2 = 10 (rise / 5), not at chi2 = 1."""
    from dataclasses import replace

    from qrfield.stream.continuity import NEAR_FOLD_CHI2

    seed, method = _near_fold_seeds(1)[0]
    frame = solved(seed, 0.03, method)
    for chi2, near in ((10.0, True), (1.0, False)):
        pose = replace(frame, chi2=chi2, mirror_chi2=chi2 + 1.5 * NEAR_FOLD_CHI2)
        result = frame_result(pose, 0, 0, noise_px=0.03)
        StreamStage().apply(result, SIDE_MM, result.detection.pose_cov)
        widened = not np.array_equal(result.poses[method].angles_std_deg, pose.angles_std_deg)
        assert widened == near


def test_near_the_fold_the_position_is_widened_along_the_way_to_the_mirror() -> None:
    """The path to the mirror moves the position by dp while the chi-square rises by only d: the
    reported position variance along dp is at least |dp|^2 / d (by hand from the two branches),
    here for frames whose own position covariance is set far below that (1e-6 mm^2); the
    rotation and the covariance between position and rotation are not touched by it."""
    from dataclasses import replace

    for index, (seed, method) in enumerate(_near_fold_seeds(4)):
        frame = solved(seed, 0.03, method)
        cov = np.array(frame.pose_cov)
        cov[:3, :3] = 1e-6 * np.eye(3)
        frame = replace(frame, pose_cov=cov)
        result = frame_result(frame, index, 0, noise_px=0.03)
        StreamStage().apply(result, SIDE_MM, result.detection.pose_cov)
        reported = result.poses[method].pose_cov
        step = frame.alternative.position_mm - frame.position_mm
        rise = (frame.mirror_chi2 - frame.chi2) / max(1.0, frame.chi2 / 2.0)
        unit = step / np.linalg.norm(step)
        assert float(unit @ reported[:3, :3] @ unit) >= 0.999 * float(step @ step) / max(rise, 1.0)
        assert np.allclose(reported[:3, 3:], cov[:3, 3:])


def test_a_fit_worse_than_its_corners_covariance_allows_has_its_covariance_scaled_by_it() -> None:
    """A frame's chi-square above FIT_CHI2 (9.21, the 0.99 quantile of chi-square with 2 degrees
    of freedom) scales its reported covariance by 1 + (chi2 - 9.21) / 2, far beyond the bar the
    Birge ratio chi2 / 2 (hand-computed: chi2 = 15.21 doubles every std, 39.21 quadruples it);
    at chi2 = 5 the std is the solver's. (chi2 / 9.21 before issue-25u: 1.29 and 2.06 times.)"""
    from dataclasses import replace

    frame = solved(20_000, QUIET)
    for chi2, factor in ((15.21, 2.0), (39.21, 4.0), (5.0, 1.0)):
        pose = replace(frame, chi2=chi2, mirror_chi2=chi2 + 10_000.0)
        result = frame_result(pose, 0, 0, noise_px=QUIET)
        StreamStage().apply(result, SIDE_MM, result.detection.pose_cov)
        out = result.poses["numerical"]
        assert np.allclose(out.angles_std_deg, factor * pose.angles_std_deg, rtol=1e-6)
        assert np.allclose(out.position_std_mm, factor * pose.position_std_mm, rtol=1e-6)
    off = StreamStage(StreamSettings(continuity=False))
    result = frame_result(replace(frame, chi2=36.84, mirror_chi2=10_000.0), 0, 0, noise_px=QUIET)
    off.apply(result, SIDE_MM, result.detection.pose_cov)
    assert np.array_equal(result.poses["numerical"].angles_std_deg, frame.angles_std_deg)


@pytest.mark.slow
def test_the_turn_rate_comes_from_the_earlier_pose_whose_prediction_varies_least() -> None:
    """A still card seen in ten unambiguous frames 33 ms apart (corner noise 0.06 px), then, after a
    gap of 200 ms, a frame ambiguous with its answer on the wrong branch (the mirror nearer the
    truth, TRUTH). A rate from the last two frames, carried over k = 6 of their spacings, multiplies
    their noise by 6 and leaves the history no evidence (none of the four resolved); the rate from
    the frame 300 ms before the last decides at least two, each onto the mirror, and none onto
    the wrong branch."""
    seeds = wrong_branch_seeds(4, "numerical", NOISE)
    resolved = 0
    for seed in seeds:
        stage, t_ms, k, index = StreamStage(), -300, 0, 0
        while t_ms <= 0:
            pose = solved(50_000 + 31 * seed + k, 0.06)
            k += 1
            if pose.ambiguous:
                continue
            quiet = frame_result(pose, index, t_ms, noise_px=0.06)
            stage.apply(quiet, SIDE_MM, quiet.detection.pose_cov)
            index, t_ms = index + 1, t_ms + 33
        result = frame_result(solved(seed, NOISE), index, t_ms - 33 + 200, noise_px=NOISE)
        stage.apply(result, SIDE_MM, result.detection.pose_cov)
        if not result.ambiguous:
            assert result.stream["numerical"].flipped
            resolved += 1
    assert resolved >= 2


def test_at_200_fps_the_history_compares_a_bounded_number_of_earlier_poses() -> None:
    """A still card at 200 fps for 1 s (unambiguous frames 5 ms apart): the earlier resolved poses
    kept for the turn rate are spaced EARLIER_SPACING_S apart within HISTORY_S, at most
    HISTORY_S / EARLIER_SPACING_S + 1 of them (without the spacing: all 100 of the last 0.5 s,
    each compared on every ambiguous frame); at 30 fps every frame is kept."""
    from qrfield.stream.continuity import EARLIER_SPACING_S, HISTORY_S, BranchHistory

    bound = int(HISTORY_S / EARLIER_SPACING_S) + 1
    for step_ms, expected in ((5, None), (33, 15)):
        history, t_ms, k = BranchHistory(), 0, 0
        while t_ms <= 1000:
            pose = solved(60_000 + k, 0.06)
            k += 1
            if pose.ambiguous:
                continue
            history.decide(pose, t_ms, TEXT, lambda p: None)
            t_ms += step_ms
        kept = history._earlier
        gaps = np.diff([r.t_ms for r in kept])
        assert len(kept) <= bound and np.all(gaps >= 1000.0 * EARLIER_SPACING_S)
        if expected is not None:
            assert len(kept) == expected  # 33 ms apart: the last 0.5 s, every frame
