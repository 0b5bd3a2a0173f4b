"""handeye.json (qrfield.handeye.store): the conventions' fields, a round trip, a file written by
hand with rounded numbers, and one clear line for every damaged file."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from qrfield.handeye import HandEyeCalibration, HandEyeError, Pair, solve_handeye
from qrfield.handeye.rigid import transform_from_pose

CONVENTION_KEYS = {"setup", "residual_mm", "residual_deg", "n_pairs", "method"}


def _solved(setup):
    rng = np.random.default_rng(0)
    x = transform_from_pose([50.0, -10.0, 30.0], [5.0, -4.0, 80.0])
    y = transform_from_pose([400.0, 20.0, 10.0], [170.0, 5.0, 0.0])
    pairs = []
    for k in range(8):
        tool = transform_from_pose(rng.normal(size=3) * 100, rng.uniform(-30, 30, 3))
        m = np.linalg.inv(tool) if setup == "eye-in-hand" else tool
        pairs.append(Pair(tool, np.linalg.inv(x) @ m @ y, np.eye(6) * 0.01, f"img{k}.png"))
    return solve_handeye(pairs, setup), x


@pytest.mark.parametrize(
    ("setup", "key"), [("eye-in-hand", "camera_to_tool"), ("eye-to-hand", "camera_to_base")]
)
def test_the_file_has_the_conventions_fields_and_round_trips(tmp_path, setup, key):
    result, x = _solved(setup)
    path = HandEyeCalibration.from_result(result, camera="picam-v2@640x480", side_mm=50.0).save(
        tmp_path / "he.json"
    )
    data = json.loads(path.read_text(encoding="utf-8"))
    assert CONVENTION_KEYS | {key} <= set(data)
    assert data["setup"] == setup and data["n_pairs"] == 8
    np.testing.assert_allclose(np.array(data[key]), x, atol=1e-6)  # 4x4 row-major, mm
    assert [p["label"] for p in data["pairs"]] == [f"img{k}.png" for k in range(8)]
    assert data["camera"] == "picam-v2@640x480" and len(data["covariance"]) == 6
    back = HandEyeCalibration.load(path)
    np.testing.assert_allclose(back.transform, result.transform, atol=1e-12)
    np.testing.assert_allclose(back.covariance, result.covariance)
    assert back.target_frame == ("tool" if setup == "eye-in-hand" else "base")
    assert back.extra["camera"] == "picam-v2@640x480" and back.path == path


def test_a_file_written_by_hand_with_rounded_numbers_is_read(tmp_path):
    # Rz(30 deg) rounded to 4 decimals, no covariance, only the conventions' fields.
    path = tmp_path / "handeye.json"
    matrix = [[0.866, -0.5, 0.0, 12.5], [0.5, 0.866, 0.0, -3.0], [0.0, 0.0, 1.0, 40.0], [0, 0, 0, 1]]
    path.write_text(json.dumps({"setup": "eye-in-hand", "camera_to_tool": matrix, "residual_mm": 0.5,
                                "residual_deg": 0.1, "n_pairs": 12, "method": "by hand"}))  # fmt: skip
    calibration = HandEyeCalibration.load(path)
    r = calibration.transform[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(r, np.array(matrix)[:3, :3], atol=1e-4)
    assert calibration.covariance is None and calibration.method == "by hand"


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("not json", "not valid JSON|JSON"),
        ('{"setup": "eye-on-hand"}', "field 'setup' must be one of eye-in-hand, eye-to-hand"),
        ('{"setup": "eye-in-hand", "residual_mm": 1}', "missing field 'camera_to_tool'"),
        ('{"setup": "eye-in-hand", "camera_to_tool": [[1, 0, 0]]}', "must be 4 rows of 4 numbers"),
        (
            '{"setup": "eye-to-hand", "camera_to_base": [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], '
            '"residual_mm": 1, "residual_deg": 1, "n_pairs": 5}',
            "not a rotation",
        ),
        (
            '{"setup": "eye-to-hand", "camera_to_base": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], '
            '"residual_mm": "small", "residual_deg": 1, "n_pairs": 5}',
            "field 'residual_mm' must be a number",
        ),
    ],
)
def test_a_damaged_file_is_one_clear_line_naming_the_file(tmp_path, content, message):
    path = tmp_path / "handeye.json"
    path.write_text(content)
    with pytest.raises(HandEyeError, match=message) as caught:
        HandEyeCalibration.load(path)
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


def test_a_missing_file_says_how_to_make_one(tmp_path):
    with pytest.raises(HandEyeError, match=r"qrfield handeye PAIRS.csv"):
        HandEyeCalibration.load(tmp_path / "none.json")


json_values = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5),
    max_leaves=30,
)


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.fixed_dictionaries(
        {"setup": st.sampled_from(["eye-in-hand", "eye-to-hand", "x"])},
        optional={
            "camera_to_tool": json_values,
            "camera_to_base": json_values,
            "residual_mm": json_values,
            "residual_deg": json_values,
            "n_pairs": json_values,
            "covariance": json_values,
        },
    )
)
def test_any_json_object_is_a_calibration_or_one_clear_error(tmp_path, data):
    path = tmp_path / "handeye.json"
    path.write_text(json.dumps(data), encoding="utf-8")
    try:
        calibration = HandEyeCalibration.load(path)
    except HandEyeError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)
        return
    r = calibration.transform[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
