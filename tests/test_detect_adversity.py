"""The detector on the adversity set (qrfield.testing.adversity): what a real bench adds to the hard
set, against the drawn truth (docs/detection.md, "Adversity"). A miss is allowed; a corner set
reported good (quality >= GOOD_QUALITY) that is off by more than 0.5 px is not."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("segno")

from qrfield.detect import Detector
from qrfield.detect.detection import GOOD_QUALITY
from qrfield.testing.adversity import adversity_view, line_kernel
from qrfield.testing.hardset import rasterise


def _good(d) -> bool:
    return bool(d.refined and d.quality >= GOOD_QUALITY)


def _matched(detections, codes):
    """(detection, its code, worst corner error px) for each detection, by the nearest code."""
    out = []
    for d in detections:
        code = min(codes, key=lambda c: float(np.abs(c.corners_px - d.corners_px).max()))
        out.append((d, code, float(np.linalg.norm(d.corners_px - code.corners_px, axis=1).max())))
    return out


def test_motion_kernel_is_centred_and_sums_to_one():
    # The truth of a motion-blurred view is the corners at mid-exposure: the kernel's centroid must
    # be its centre pixel, and its spread along the motion that of a uniform segment (L^2 / 12).
    for length, angle in ((1.0, 0.0), (3.3, 0.7), (6.0, 2.0)):
        k = line_kernel(length, angle).astype(np.float64)
        assert k.sum() == pytest.approx(1.0, abs=1e-6)
        c = (k.shape[0] - 1) / 2
        yy, xx = np.mgrid[0 : k.shape[0], 0 : k.shape[1]]
        assert float((k * xx).sum()) == pytest.approx(c, abs=1e-6)
        assert float((k * yy).sum()) == pytest.approx(c, abs=1e-6)
        along = (xx - c) * math.cos(angle) + (yy - c) * math.sin(angle)
        # bilinear splatting adds a little spread (at most 1/6 px^2 per axis)
        assert float((k * along**2).sum()) == pytest.approx(length**2 / 12, abs=0.17)


@pytest.mark.slow
@pytest.mark.parametrize("condition", ["inverted", "mirrored"])
def test_inverted_and_mirrored_codes_are_found_at_their_drawn_corners(condition):
    # Light modules on dark (ISO/IEC 18004 reflectance reversal) and a mirror-image print (the
    # matrix transposed: the finders where they were, V1 at the finder between the others).
    view = adversity_view(condition, 0)
    found = _matched(Detector(camera=view.camera).detect(view.image), view.codes)
    assert found, f"{condition} code not found"
    d, code, err = found[0]
    assert d.text == code.text
    assert _good(d) and err < 0.1


@pytest.mark.slow
def test_glare_over_a_finder_pattern_is_not_reported_good():
    # Seed 3031, glare view 22: a saturated spot over the V1 finder pattern. The fit extrapolated
    # V1 from the rest of the symbol, 0.77 px off at a std of 0.08 px, and called it good (0.88).
    view = adversity_view("glare", 22, seed=3031)
    found = _matched(Detector(camera=view.camera).detect(view.image), view.codes)
    assert found, "the code is found (its text is read)"
    for d, code, err in found:
        assert not (_good(d) and err > 0.5), f"reported good with a corner {err:.2f} px off"
        # V1, under the glare, within 4 of its own (widened) std: the pose's std covers it. (The
        # other corners are pulled by 0.1-0.25 px, some beyond 4 std: docs/detection.md, Adversity.)
        e = d.corners_px[0] - code.corners_px[0]
        assert float(np.sqrt(e @ np.linalg.solve(d.corners_cov[0], e))) < 4.0


@pytest.mark.slow
def test_a_corner_under_another_card_is_not_reported_good():
    # The first code of twins view 25 of seed 3031 with the second card's whole drawn region
    # (its card and the background box around it) pasted over it: a straight dark edge cuts
    # across the symbol next to V3 and hides that corner. V3 came out 0.59 px off at quality 0.92.
    import cv2

    view = adversity_view("twins", 25, seed=3031)
    first, second = view.codes
    background, light, dark = 45.1, 185.0, 60.0
    scene = rasterise(view.camera, first.pose, first.side_mm, first.matrix, background, light, dark)
    card = rasterise(view.camera, second.pose, second.side_mm, second.matrix, background, light, dark)
    ys, xs = np.nonzero(card != background)  # the rasteriser's region (float32 levels)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    scene[y0:y1, x0:x1] = card[y0:y1, x0:x1]
    image = cv2.GaussianBlur(scene, (0, 0), 0.5)
    noise = np.random.default_rng(5).normal(0.0, 1.5, image.shape)
    image = np.clip(np.round(image + noise), 0, 255).astype(np.uint8)
    found = _matched(Detector(camera=view.camera).detect(image), view.codes)
    assert any(code is first for _, code, _ in found), "the first code is still found"
    for d, _, err in found:
        assert not (_good(d) and err > 0.5), f"reported good with a corner {err:.2f} px off"


@pytest.mark.slow
def test_glare_over_dark_modules_widens_the_corners_std():
    # Seed 3031, glare view 34: a clipped spot over dark modules of the data. The clipped pixels
    # pulled V2 and V3 by 0.18-0.20 px, 4.5-6 times the fit's std, and the code was called good.
    view = adversity_view("glare", 34, seed=3031)
    found = _matched(Detector(camera=view.camera).detect(view.image), view.codes)
    assert found and found[0][0].text == view.code.text
    for d, code, _ in found:
        diff = d.corners_px - code.corners_px
        for k in range(4):
            m = float(np.sqrt(diff[k] @ np.linalg.solve(d.corners_cov[k], diff[k])))
            assert m < 4.0, f"V{k + 1} {np.linalg.norm(diff[k]):.2f} px off, {m:.1f} of its std"
