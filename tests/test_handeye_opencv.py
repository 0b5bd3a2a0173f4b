"""The hand-eye solve against OpenCV 4.x's calibrateHandEye on the same pairs, recorded in
tests/data/handeye_opencv4.json by tests/data/make_handeye_opencv4.py (OpenCV 5, installed here,
lacks calibrateHandEye in Python; this test installs nothing)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from qrfield.handeye import Pair, solve_handeye
from qrfield.handeye.rigid import difference
from qrfield.handeye.solve import model_terms, park_martin

DATA = json.loads((Path(__file__).parent / "data" / "handeye_opencv4.json").read_text(encoding="utf-8"))
SETS = {s["setup"]: s for s in DATA["sets"]}


def _pairs(s, exact=False):
    tools = np.array(s["tool_in_base"])
    sigma = np.array(s["code_sigma"])
    if exact:
        x, y = np.array(s["true_transform"]), np.array(s["true_other"])
        m = np.linalg.inv(tools) if s["setup"] == "eye-in-hand" else tools
        codes = np.linalg.inv(x) @ m @ y
    else:
        codes = np.array(s["code_in_camera"])
    return [Pair(t, c, np.diag(sigma**2)) for t, c in zip(tools, codes, strict=True)]


def _error(estimate, truth):
    d = difference(np.asarray(estimate), np.asarray(truth))
    return float(np.linalg.norm(d[:3])), float(np.degrees(np.linalg.norm(d[3:])))


def test_the_recording_is_opencv_4():
    assert DATA["opencv"].startswith("4.")
    assert set(SETS) == {"eye-in-hand", "eye-to-hand"}


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_exact_pairs_every_opencv_method_and_ours_give_the_same_transform(setup):
    s = SETS[setup]
    ours = solve_handeye(_pairs(s, exact=True), setup).transform
    for method, answer in s["opencv_exact"].items():
        mm, deg = _error(ours, answer)
        assert mm < 1e-6 and deg < 1e-7, (method, mm, deg)


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_our_closed_form_is_opencvs_park_martin_on_noisy_pairs(setup):
    s = SETS[setup]
    tools, codes = np.array(s["tool_in_base"]), np.array(s["code_in_camera"])
    mm, deg = _error(park_martin(model_terms(tools, setup), codes), s["opencv"]["park"])
    assert mm < 1e-6 and deg < 1e-8


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_the_refinement_beats_every_opencv_method_and_its_std_covers_its_error(setup):
    s = SETS[setup]
    truth = np.array(s["true_transform"])
    result = solve_handeye(_pairs(s), setup)
    ours_mm, ours_deg = _error(result.transform, truth)
    for method, answer in s["opencv"].items():
        mm, deg = _error(answer, truth)
        assert ours_mm < mm and ours_deg <= deg + 1e-4, (method, ours_mm, mm, ours_deg, deg)
    err = difference(result.transform, truth)
    err[3:] = np.degrees(err[3:])
    assert np.all(np.abs(err) < 4 * np.sqrt(np.diag(result.covariance))), err
