"""Small codes (modules of 1.2-2 px under a blur of about a module): the small backend
(qrfield.detect.small) and reading located codes from their fitted patterns (qrfield.detect.reading),
against the hard set's truth (segno's symbols, cv2.projectPoints' corners)."""

from __future__ import annotations

import numpy as np
import pytest

segno = pytest.importorskip("segno", reason="segno (a dev dependency) encodes the hard set's symbols")

from view_checks import drawn_agreement, found_once  # noqa: E402

from qrfield.detect.backends import find_candidates  # noqa: E402
from qrfield.detect.lens import Lens  # noqa: E402
from qrfield.detect.reading import read_symbol  # noqa: E402
from qrfield.detect.small import busy_regions  # noqa: E402
from qrfield.testing.hardset import hard_view  # noqa: E402

#: Hard-set views (seed 2024) with modules of 1.21-1.73 px that zxing-cpp, zxing-x2 and the contour
#: locator did not read (versions 3-9, pinhole and distorted): the small backend finds 54, 71 and
#: 328; the contour locator finds 82 but cannot read it, the reading does.
VIEWS = (54, 71, 82, 328)


@pytest.fixture(scope="module")
def views():
    return [hard_view(index) for index in VIEWS]


@pytest.mark.slow
def test_small_blurred_codes_are_found_read_and_refined(views):
    for view in views:
        assert 1.2 <= view.module_px < 2.0
        for backend in ("zxing", "zxing-x2"):  # what the default pipeline had before
            assert not any(c.text == view.text for c in find_candidates(view.image, backend)), view.index
        d = found_once(view)
        assert d.corners_cov is not None
        error = np.linalg.norm(d.corners_px - view.corners_px, axis=1)
        assert np.all(error < 4.0 * d.corners_std_px + 0.02), f"view {view.index}: error beyond its std"


@pytest.mark.slow
def test_reading_a_located_code_from_its_corners(views):
    """The least-squares reading gives the payload from the true corners; a module off, nothing."""
    view = views[2]  # 82: the one only the reading reads
    lens = Lens(view.camera)
    text, matrix = read_symbol(view.image, view.corners_px, view.modules, view.blur_px, lens)
    assert text == view.text
    # The module matrix is what was read: the symbol segno drew (at the view's error level, one of
    # L, M, Q, H) but for the few modules the error correction put right (9 of 1089 here).
    assert drawn_agreement(matrix, view.text) > 0.98
    step = (view.corners_px[1] - view.corners_px[0]) / view.modules
    assert read_symbol(view.image, view.corners_px + step, view.modules, view.blur_px, lens) == (None, None)


def test_busy_regions_hold_the_code_and_nothing_on_a_flat_image(views):
    for view in views:
        c = view.corners_px
        boxes = busy_regions(view.image)
        assert any(
            x0 - 6 <= c[:, 0].min()
            and c[:, 0].max() <= x1 + 6
            and y0 - 6 <= c[:, 1].min()
            and c[:, 1].max() <= y1 + 6
            for x0, y0, x1, y1 in boxes
        ), view.index
    assert busy_regions(np.full((480, 640), 120, np.uint8)) == []
    assert find_candidates(np.full((480, 640), 120, np.uint8), "small") == []
