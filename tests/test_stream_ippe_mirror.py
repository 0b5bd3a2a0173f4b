"""IPPE's mirror near frontal (qrfield.solvers.mirror.refined_mirror_result, through the stream stage),
against OpenCV's own refinement and the truth of cv2.projectPoints (tests/stream_cases.py).

Near frontal, IPPE's second closed-form solution is no minimum of its own: refined, it slides onto
the answer, and the solver keeps the closed form (qrfield.solvers.ippe), a degree or two from the
answer with a chi-square rise of a few. Such a frame is ambiguous alone; the stream treats its
candidate as no distinct mirror (as the numerical model's search that slides back to its answer)
and resolves the frame when its history agrees with the answer. Whether a candidate is a minimum of
its own is judged here by cv2.solvePnPRefineLM run to convergence from it and from the answer
(pixels unweighted: the chi-square itself for the isotropic corner noise used here).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from stream_cases import CAMERA, SIDE_MM, frame_result, solved

from qrfield.geometry import Pose, angle_difference, marker_vertices, rotation_angle_deg
from qrfield.solvers.mirror import mirror_result, refined_mirror_result
from qrfield.solvers.uncertainty import isotropic_cov
from qrfield.stream import StreamStage

#: A 30 mm code at 450 mm tilted about 1 degree: with 0.02 px of corner noise most frames are
#: ambiguous, nearly all with a candidate that is no minimum of its own.
NEAR_FRONTAL = Pose([10.0, -5.0, 450.0], [1.0, -0.5, 20.0])
TILTED = Pose([10.0, -5.0, 700.0], [6.0, -4.0, 20.0])  # stream_cases' card: distinct mirrors
NOISE = 0.02
TIGHT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-14)


def _cv2_minimum(start, corners: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) cv2.solvePnPRefineLM reaches from ``start`` (a PoseResult)."""
    obj = np.ascontiguousarray(marker_vertices(SIDE_MM).reshape(4, 1, 3))
    rvec, _ = cv2.solvePnPRefineLM(
        obj,
        np.ascontiguousarray(corners.reshape(4, 1, 2), dtype=float),
        CAMERA.K,
        CAMERA.dist,
        cv2.Rodrigues(start.rotation)[0],
        start.position_mm.reshape(3, 1).copy(),
        TIGHT,
    )
    return cv2.Rodrigues(rvec)[0]


def _one_minimum(frame) -> bool:
    """cv2's refinement from the frame's second candidate ends on its refinement from the answer."""
    ends = [_cv2_minimum(p, frame.corners_px) for p in (frame, frame.alternative)]
    return rotation_angle_deg(ends[0], ends[1]) < 0.05


def test_a_second_candidate_that_cv2_refines_onto_the_answer_is_no_mirror() -> None:
    merged = distinct = 0
    for seed in range(40):
        frame = solved(seed, NOISE, "ippe", NEAR_FRONTAL)
        if not frame.ambiguous:
            continue
        refined = refined_mirror_result(frame, CAMERA, SIDE_MM, isotropic_cov(NOISE))
        if _one_minimum(frame):
            merged += 1
            assert rotation_angle_deg(frame.alternative.rotation, frame.rotation) > 0.5  # a candidate apart
            assert refined is None
        else:
            distinct += 1
            assert refined is not None
    assert merged >= 10
    # Tilted by 7 degrees the two candidates are two minima (cv2 keeps them apart): the mirror as before.
    for seed in range(10):
        frame = solved(seed, NOISE, "ippe", TILTED)
        assert not _one_minimum(frame)
        refined = refined_mirror_result(frame, CAMERA, SIDE_MM, isotropic_cov(NOISE))
        before = mirror_result(frame, CAMERA, SIDE_MM, isotropic_cov(NOISE))
        assert refined is not None and before is not None
        assert np.array_equal(refined.rotation, before.rotation) and refined.chi2 == before.chi2


def _after_history(seed: int, history: list[int]):
    """Two unambiguous frames of the near-frontal card (seeds ``history``, at -33 and 0 ms), then
    the frame of ``seed`` at 33 ms; its result (IPPE)."""
    stage = StreamStage()
    for index, (t_ms, quiet) in enumerate(zip((-33, 0), history, strict=True)):
        result = frame_result(solved(quiet, NOISE, "ippe", NEAR_FRONTAL), index, t_ms, noise_px=NOISE)
        stage.apply(result, SIDE_MM, result.detection.pose_cov)
        assert not result.ambiguous
    result = frame_result(solved(seed, NOISE, "ippe", NEAR_FRONTAL), 2, 33, noise_px=NOISE)
    stage.apply(result, SIDE_MM, result.detection.pose_cov)
    return result


@pytest.mark.slow
def test_near_frontal_ippe_frames_whose_history_agrees_are_resolved_to_their_answer() -> None:
    history = [s for s in range(5000, 5100) if not solved(s, NOISE, "ippe", NEAR_FRONTAL).ambiguous][:2]
    checked = 0
    for seed in range(150):
        frame = solved(seed, NOISE, "ippe", NEAR_FRONTAL)
        if not (frame.ambiguous and _one_minimum(frame)):
            continue
        # The answer is nearer the truth than its candidate, by half a degree or more: the history
        # (frames of the same still card) points at the answer.
        off = rotation_angle_deg(frame.rotation, NEAR_FRONTAL.rotation)
        if rotation_angle_deg(frame.alternative.rotation, NEAR_FRONTAL.rotation) < off + 0.5:
            continue
        checked += 1
        result = _after_history(seed, history)
        pose, mark = result.poses["ippe"], result.stream["ippe"]
        assert not result.ambiguous and mark.resolved_by == "history" and not mark.flipped, seed
        assert np.array_equal(pose.rotation, frame.rotation)  # the frame's own answer
        # Not confidently wrong: within 2 degrees of the truth or 4 of its (widened) std.
        error = np.abs(angle_difference(pose.angles_deg, NEAR_FRONTAL.angles_deg))
        assert np.all((error <= 2.0) | (error <= 4.0 * pose.angles_std_deg)), seed
    assert checked >= 50
