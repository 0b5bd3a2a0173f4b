"""Several codes in one frame: every one found and refined, the largest first under ``max_codes``,
only the selected text refined and followed; against an independent renderer's truth
(tests/scene_truth.py: segno symbols, the hard set's rasteriser, cv2.projectPoints)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("segno", reason="segno (a dev dependency) encodes the test symbols")

import scene_truth

from qrfield.camera import resolve_camera
from qrfield.detect import Detector, DetectorSettings, Tracker

CAMERA = resolve_camera("webcam-60@1280x720")
#: Four cards in the four quadrants, different payloads, sides (so sizes differ) and tilts.
CARDS = (
    ("first code", 40.0, (-80.0, -45.0, 380.0), 15.0, -10.0, 20.0),
    ("https://example.org/second", 50.0, (85.0, -45.0, 400.0), -20.0, 15.0, 110.0),
    ("third, the largest", 60.0, (-85.0, 50.0, 390.0), 10.0, 25.0, -60.0),
    ("4th", 35.0, (80.0, 50.0, 370.0), -25.0, -15.0, 200.0),
)


@pytest.fixture(scope="module")
def frame():
    cards = [
        scene_truth.Card(text, side, scene_truth.facing(position, tx, ty, turn))
        for text, side, position, tx, ty, turn in CARDS
    ]
    return scene_truth.draw(CAMERA, cards, blur_px=0.6, noise=2.0, seed=5)


def _truth(frame, text):
    return frame.corners[[c[0] for c in CARDS].index(text)]


def _area(corners: np.ndarray) -> float:
    """Area of the quadrilateral V1..V4, px^2 (half the cross product of its diagonals)."""
    (ax, ay), (bx, by) = corners[2] - corners[0], corners[3] - corners[1]
    return 0.5 * abs(float(ax * by - ay * bx))


@pytest.mark.slow
def test_four_codes_are_all_found_and_refined(frame):
    found = Detector(camera=CAMERA).detect(frame.image)
    assert sorted(d.text for d in found) == sorted(c[0] for c in CARDS)
    for d in found:
        error = np.linalg.norm(d.corners_px - _truth(frame, d.text), axis=1)
        assert d.refined and d.quality >= 0.85, d.text
        assert error.max() < 0.08, f"{d.text}: {error.max():.3f} px off"


def test_max_codes_keeps_the_largest(frame):
    found = Detector(DetectorSettings(max_codes=2), camera=CAMERA).detect(frame.image)
    areas = {c[0]: _area(_truth(frame, c[0])) for c in CARDS}
    largest = sorted(areas, key=lambda t: -areas[t])[:2]
    assert sorted(d.text for d in found) == sorted(largest)
    assert all(d.refined for d in found)


def test_a_selected_text_is_the_only_code_refined_and_followed(frame):
    chosen = CARDS[1][0]
    settings = DetectorSettings(select_text=chosen)
    found = Detector(settings, camera=CAMERA).detect(frame.image)
    assert sorted(d.text for d in found) == sorted(c[0] for c in CARDS)  # all still reported
    for d in found:
        assert d.refined == (d.text == chosen), d.text
        if d.text != chosen:
            assert d.quality < 0.85 and d.corners_cov is None  # unrefined: no pose from them
    tracker = Tracker(settings, camera=CAMERA)
    tracker.update(frame.image)
    again = tracker.update(frame.image)
    assert tracker.last_mode == "refined"  # the selected code followed by the warm fit alone
    assert [d.text for d in again] == [chosen]
    assert np.linalg.norm(again[0].corners_px - _truth(frame, chosen), axis=1).max() < 0.1
