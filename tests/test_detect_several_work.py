"""Several codes in one frame (issue-26m2): every code found at its rendered corners, and the frame's
whole-frame work done once for all of them: one backend pass (zxing-cpp), no locator or fallback,
one cold refinement per code kept, none for a code ``max_codes`` or ``select_text`` leaves out.

Truth: the frames of :func:`qrfield.testing.hardset.multi_view` (segno symbols drawn by the hard
set's rasteriser; true corners by cv2.projectPoints of the poses), at a seed other than the
benchmark's (2024). Counting tests, not timed: they wrap the detector's stages and count calls.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

pytest.importorskip("segno", reason="segno (a dev dependency) encodes the test symbols")

import qrfield.detect.detector as detector_module
import qrfield.detect.finders as finders_module
from qrfield.detect import Detector, DetectorSettings
from qrfield.detect.detection import GOOD_QUALITY
from qrfield.testing.hardset import multi_view

SEED = 7
#: A refined corner of these codes (modules 2.6-5.7 px, blur 0.4-0.9 px, noise up to 3 levels)
#: within this of the truth (measured 0.004-0.032 px on frames 0-2 of seed 7).
CORNER_PX = 0.08


@pytest.fixture(scope="module")
def four():
    return multi_view(0, 4, SEED)


@pytest.fixture(scope="module")
def one():
    return multi_view(0, 1, SEED)


class _Counts:
    """Calls of the detector's stages, by name (the backends by backend name)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls: Counter[str] = Counter()
        find = detector_module.find_candidates

        def counted_find(grey, backend, lens=None):
            self.calls[f"backend {backend}"] += 1
            return find(grey, backend, lens)

        monkeypatch.setattr(detector_module, "find_candidates", counted_find)
        for name in ("refine_cold", "refine", "read"):
            self._wrap(monkeypatch, Detector, name)
        self._wrap(monkeypatch, finders_module, "locate_by_finders")

    def _wrap(self, monkeypatch: pytest.MonkeyPatch, owner, name: str) -> None:
        original = getattr(owner, name)

        def counted(*args, **kwargs):
            self.calls[name] += 1
            return original(*args, **kwargs)

        monkeypatch.setattr(owner, name, counted)

    def frame_work(self) -> dict[str, int]:
        """The calls that work on the whole frame (backends and the locator)."""
        return {k: v for k, v in self.calls.items() if k.startswith("backend") or k == "locate_by_finders"}


@pytest.mark.slow
def test_four_codes_in_one_frame_are_found_at_their_rendered_corners(four):
    found = Detector(camera=four.camera).detect(four.image)
    assert sorted(d.text for d in found) == sorted(four.texts)
    for corners, text in zip(four.corners_px, four.texts, strict=True):
        (d,) = [d for d in found if d.text == text]
        assert d.refined and d.quality >= GOOD_QUALITY, text
        error = float(np.linalg.norm(d.corners_px - corners, axis=1).max())
        assert error < CORNER_PX, f"{text!r}: {error:.3f} px off"


@pytest.mark.slow
def test_four_codes_cost_one_backend_pass_and_one_cold_refinement_each(four, one, monkeypatch):
    detector = Detector(camera=four.camera)
    counts = _Counts(monkeypatch)
    assert len(detector.detect(one.image)) == 1
    single = counts.frame_work()
    assert single == {"backend zxing": 1}  # zxing-cpp read it: no further backend, no locator
    assert counts.calls["refine_cold"] == 1
    counts.calls.clear()
    assert len(detector.detect(four.image)) == 4
    assert counts.frame_work() == single  # the whole-frame work of one code, not four times it
    assert counts.calls["refine_cold"] == 4  # each code refined once, on its own crop
    assert counts.calls["refine"] == 0 and counts.calls["read"] == 0  # no fallback


@pytest.mark.slow
def test_codes_left_out_by_max_codes_or_select_text_are_not_refined(four, monkeypatch):
    counts = _Counts(monkeypatch)
    kept = Detector(DetectorSettings(max_codes=1), camera=four.camera).detect(four.image)
    assert len(kept) == 1 and kept[0].refined
    assert counts.calls["refine_cold"] == 1 and counts.calls["refine"] == 0
    counts.calls.clear()
    chosen = four.texts[2]
    found = Detector(DetectorSettings(select_text=chosen), camera=four.camera).detect(four.image)
    assert sorted(d.text for d in found) == sorted(four.texts)
    assert [d.text for d in found if d.refined] == [chosen]
    assert counts.calls["refine_cold"] == 1 and counts.calls["refine"] == 0
    truth = four.corners_px[2]
    (d,) = [d for d in found if d.text == chosen]
    assert float(np.linalg.norm(d.corners_px - truth, axis=1).max()) < CORNER_PX
