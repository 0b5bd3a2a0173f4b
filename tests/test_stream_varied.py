"""The stream on drawn sequences under conditions the clean ones do not hold
(qrfield/testing/varied_sequences.py): a code covered and back with its tilt flipped meanwhile,
dropped frames, JPEG compression with motion blur. Truth: the drawn pose of every frame.

Confidently wrong, as issue 25 states it: not flagged ambiguous, and an angle more than 2 degrees
and more than 4 of its stated std from the drawn truth (or the position more than 5 mm and a
coordinate 4 std off). None of these found a confidently wrong frame in a stream mode on the
diagnosis seeds 301-303 (docs/uncertainty.md, "Varied sequences (varied)"): they hold what was
seen there.
"""

from __future__ import annotations

import numpy as np
import pytest

from qrfield.methods import METHODS
from qrfield.status import usable_pose
from qrfield.stream import StreamSettings
from qrfield.stream.kalman import GAP_S
from qrfield.stream.replay import replay, solve_sequence
from qrfield.testing.scoring import confidently_wrong
from qrfield.testing.sequences import FPS
from qrfield.testing.varied_sequences import make_varied

MODES = [StreamSettings(), StreamSettings(filter_s=0.2), StreamSettings(filter_s=0.5)]
MODE_IDS = ["continuity", "filter 0.2 s", "filter 0.5 s"]


def _wrong(results: list, side: float, settings: StreamSettings) -> list:
    """(frame index, method) of every usable pose the stage with ``settings`` reports that is
    confidently wrong against the frame's drawn truth."""
    out = []
    for again in replay(results, settings, side):
        for method in METHODS:
            pose = again.poses.get(method)
            if usable_pose(pose) and confidently_wrong(pose, again.truth):
                out.append((again.index, method))
    return out


def _solved(name: str, seed: int, count: int) -> tuple:
    """The varied sequence ``name`` (seed, frames) and its frames solved with the stream off."""
    sequence = make_varied(name, seed, count)
    return sequence, solve_sequence(sequence)


COVERED = "briefly covered, flipped far 1.4 px"


@pytest.fixture(scope="module")
def covered() -> tuple:
    """Seed 302's first 90 frames: a far card (modules of 1.4 px) 2-4 degrees from frontal, covered
    for 0.3 s (frames 54-62) while its tilt changes sign."""
    return _solved(COVERED, 302, 90)


@pytest.mark.slow
def test_a_covered_code_gives_no_pose_and_comes_back_on_its_new_tilt(covered) -> None:
    sequence, results = covered
    assert sequence.hidden  # the window holds the cover
    before = sequence.pose_at(sequence.hidden[0] / FPS - 0.1).angles_deg
    after = sequence.pose_at(sequence.hidden[-1] / FPS + 0.1).angles_deg
    tilted = int(np.argmax(np.abs(before[:2] - after[:2])))
    assert before[tilted] * after[tilted] < 0  # the drawn tilt changed sign under the cover
    by_index = {r.index: r for r in replay(results, StreamSettings(), sequence.side_mm)}
    for index in sequence.hidden:  # nothing of the code is in the picture: no pose
        assert not any(usable_pose(p) for p in by_index[index].poses.values())
    back = [by_index[i] for i in range(sequence.hidden[-1] + 1, sequence.hidden[-1] + 11)]
    for result in back:  # what is reported unflagged after the cover is nearer the new tilt
        truth = result.truth.angles_deg[tilted]
        old = truth - 2.0 * truth  # where the tilt was before the cover (its sign changed)
        for method in METHODS:
            pose = result.poses[method]
            if usable_pose(pose) and not pose.ambiguous:
                assert abs(pose.angles_deg[tilted] - truth) < abs(pose.angles_deg[tilted] - old)


@pytest.mark.slow
@pytest.mark.parametrize("settings", MODES, ids=MODE_IDS)
def test_no_frame_of_a_card_covered_and_flipped_is_confidently_wrong(covered, settings) -> None:
    sequence, results = covered
    assert _wrong(results, sequence.side_mm, settings) == []


DROPPED = "dropped frames far 1.4 px"


@pytest.fixture(scope="module")
def dropped() -> tuple:
    """Seed 303's 150 frames of a far card near frontal (modules of 1.4 px) with three runs of
    dropped frames (there: one gap of 0.6 s, the runs overlap) and capture times jittered by 2 ms."""
    return _solved(DROPPED, 303, 150)


@pytest.mark.slow
def test_the_filter_starts_again_after_each_gap_longer_than_half_a_second(dropped) -> None:
    sequence, results = dropped
    gaps = np.diff(sequence.times_s)
    assert np.any(gaps > 0.1) and np.all(gaps < 0.75)
    long_gap_after = {sequence.indices[k + 1] for k in np.nonzero(gaps > GAP_S + 0.01)[0]}
    assert long_gap_after  # the draw holds a gap the filter must not bridge
    for again in replay(results, StreamSettings(filter_s=0.5), sequence.side_mm):
        for method in METHODS:
            mark = again.stream.get(method)
            if again.index in long_gap_after and mark is not None:
                assert not mark.filtered and "gap" in mark.reset


@pytest.mark.slow
@pytest.mark.parametrize("settings", MODES, ids=MODE_IDS)
def test_no_frame_of_a_far_card_with_dropped_frames_is_confidently_wrong(dropped, settings) -> None:
    sequence, results = dropped
    assert _wrong(results, sequence.side_mm, settings) == []


BLURRED = "jpeg, blurred swing far 1.4 px"


@pytest.fixture(scope="module")
def blurred() -> tuple:
    """Seed 303's first 46 frames of a fast swing of a far card (modules of 1.4 px), a 12 ms
    exposure's motion blur, every frame JPEG-compressed at quality 50-70. On frame 44 the far
    corner V3 is 0.66 px off (its std 0.28); IPPE's answer, unambiguous near the fold (its mirror
    23 worse), is 7.5 degrees off in tilt and 7.7 mm in depth: the tilt's std widened to 4.1
    degrees, the depth's linearised 1.2 mm (docs/uncertainty.md, "Varied sequences (varied)")."""
    return _solved(BLURRED, 303, 46)


@pytest.mark.slow
@pytest.mark.parametrize("settings", MODES, ids=MODE_IDS)
def test_no_frame_of_a_blurred_compressed_fast_swing_is_confidently_wrong(blurred, settings) -> None:
    sequence, results = blurred
    assert len([r for r in results if r.detection is not None]) >= len(results) // 2
    frame = results[44].poses["ippe"]  # the window still holds the frame far off in depth
    assert usable_pose(frame) and not frame.ambiguous
    assert abs(frame.position_mm[2] - results[44].truth.position_mm[2]) > 5.0
    assert _wrong(results, sequence.side_mm, settings) == []
