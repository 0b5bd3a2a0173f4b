"""Several codes in view: all are returned; the selection rule picks one."""

from __future__ import annotations

import numpy as np
import pytest

from qrfield.detect import Detector, select_code
from qrfield.geometry import Pose
from qrfield.render import render_view


@pytest.fixture(scope="module")
def two_codes(camera_vga):
    """ "alpha" (small, far, left) then "bravo" (larger, nearer, right) rendered over it."""
    far = render_view(camera_vga, 60.0, Pose([-90.0, 0.0, 500.0], [0.0, 10.0, 5.0]), text="alpha")
    near = render_view(
        camera_vga,
        60.0,
        Pose([55.0, 10.0, 330.0], [-10.0, 0.0, -20.0]),
        text="bravo",
        background=far.image,
        noise_sigma=2.0,
        seed=2,
    )
    return near.image, {"alpha": far.corners_px, "bravo": near.corners_px}


def test_all_codes_are_returned_with_their_own_corners(two_codes):
    image, truth = two_codes
    detections = Detector().detect(image)
    assert sorted(d.text for d in detections) == ["alpha", "bravo"]
    for d in detections:
        assert np.abs(d.corners_px - truth[d.text]).max() < 0.3


def test_selection_rule(two_codes):
    image, _ = two_codes
    detections = Detector().detect(image)
    assert select_code(detections).text == "bravo"  # the largest
    assert select_code(detections, select_text="alpha").text == "alpha"
    assert select_code(detections, select_text="charlie") is None
    assert select_code([]) is None
    assert select_code([], select_text="alpha") is None
