"""pairs.csv (qrfield.handeye.pairs.read_pairs_csv) and the PairCollector's rules: which results
make a pair, and that a result captured before the tool pose was given never does."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from qrfield.geometry import Pose, rotation_matrix
from qrfield.handeye import HandEyeError, PairCollector, read_pairs_csv
from qrfield.handeye.rigid import transform_from_pose
from qrfield.pipeline import OK, FrameResult
from qrfield.solvers import solve
from qrfield.solvers.uncertainty import isotropic_cov


def test_rows_are_read_with_quaternions_and_paths_relative_to_the_csv(tmp_path):
    folder = tmp_path / "shots"
    folder.mkdir()
    s = math.sqrt(0.5)
    (folder / "pairs.csv").write_text(
        "\ufeffimage,x,y,z,qw,qx,qy,qz,note\n"  # any column order, a BOM, an extra column
        f"a.png,100,-20.5,300,1,0,0,0,first\n"
        "\n# a comment line\n"
        f"sub/b.png,0,0,0,{s},0,0,{s},\n",
        encoding="utf-8",
    )
    rows = read_pairs_csv(folder / "pairs.csv")
    assert [r.label for r in rows] == ["a.png", "sub/b.png"] and [r.line for r in rows] == [2, 5]
    assert rows[0].image == folder / "a.png" and rows[1].image == folder / "sub" / "b.png"
    np.testing.assert_allclose(rows[0].tool_in_base[:3, 3], [100, -20.5, 300])
    np.testing.assert_allclose(rows[1].tool_in_base[:3, :3], rotation_matrix([0, 0, 90]), atol=1e-12)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty; expected a header row x,y,z,qw,qx,qy,qz,image"),
        ("x,y,z,qw,image\n", r"line 1: the header lacks the column\(s\) qx, qy, qz"),
        ("x,y,z,qw,qx,qy,qz,image\n", "a header and no rows"),
        ("x,y,z,qw,qx,qy,qz,image\n1,2,3,1,0,0,0\n", "line 2: 7 values, the header has 8 columns"),
        (
            "x,y,z,qw,qx,qy,qz,image\n1,2,abc,1,0,0,0,a.png\n",
            "line 2: column z: expected a number, got 'abc'",
        ),
        ("x,y,z,qw,qx,qy,qz,image\n1,2,3,1,1,0,0,a.png\n", r"line 2: qw,qx,qy,qz: .*unit quaternion.*1\.414"),
        (
            "x,y,z,qw,qx,qy,qz,image\n1,2,3e9,1,0,0,0,a.png\n",
            "line 2: column z: tool position 3e\\+09 mm is above",
        ),
        ("x,y,z,qw,qx,qy,qz,image\n1,2,3,1,0,0,0,\n", "line 2: column image is empty"),
    ],
)
def test_a_bad_file_is_one_line_naming_the_line_and_column(tmp_path, text, message):
    path = tmp_path / "pairs.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(HandEyeError, match=message) as caught:
        read_pairs_csv(path)
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


def _result(camera, pose, index=0, latency_ms=5.0):
    corners = pose.corners_px(camera, 50.0)
    p = solve(corners, camera, 50.0, "ippe", corners_cov=isotropic_cov(0.05))
    return FrameResult(index, 0, OK, poses={"ippe": p}, latency_ms=latency_ms)


def test_the_collector_takes_the_next_converged_unambiguous_result_after_the_tool_pose(camera_vga):
    collector = PairCollector()
    tilted = Pose([10.0, 5.0, 300.0], [25.0, -20.0, 30.0])
    squarely = Pose([0.0, 0.0, 600.0], [0.0, 0.0, 0.0])  # facing the camera far away: ambiguous
    collector.on_result(_result(camera_vga, tilted), True)  # nothing expected: ignored
    assert len(collector) == 0
    tool = transform_from_pose([1.0, 2.0, 3.0], [0.0, 10.0, 0.0])
    collector.expect(tool, "T1")
    time.sleep(0.01)
    collector.on_result(_result(camera_vga, tilted, 1, latency_ms=1000.0), True)  # captured before
    ambiguous = _result(camera_vga, squarely, 2)
    assert ambiguous.primary.ambiguous
    collector.on_result(ambiguous, True)
    assert not collector.wait(0.0) and "ambiguous" in collector.passed_over[-1]
    failed = _result(camera_vga, tilted, 3)
    failed.poses["ippe"] = failed.primary.failed("ippe", failed.primary.corners_px, "no convergence")
    collector.on_result(failed, True)
    assert "not converged" in collector.passed_over[-1]
    collector.on_result(_result(camera_vga, tilted, 4), True)
    assert collector.wait(0.0) and len(collector) == 1
    pair = collector.pairs[0]
    assert pair.label == "T1" and np.allclose(pair.tool_in_base, tool)
    np.testing.assert_allclose(pair.code_in_camera[:3, 3], tilted.position_mm, atol=1e-6)
    assert pair.code_cov is not None and pair.code_cov.shape == (6, 6)
    collector.on_result(_result(camera_vga, tilted, 5), True)  # one pair per expect
    assert len(collector) == 1
    with pytest.raises(HandEyeError, match="1 usable pairs"):
        collector.solve("eye-in-hand")
    # record(): expect + wait, and a timeout is one line saying why.
    with pytest.raises(HandEyeError, match=r"no pair within 0\.01 s: no frame measured"):
        collector.record(tool, 0.01)
    assert len(collector) == 1


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.text(alphabet=st.sampled_from(list('xyzqwimage,.-+e0123456789 \n#"\tn\u00e9')), max_size=200))
def test_any_pairs_text_is_rows_or_one_clear_error(tmp_path, text):
    path = tmp_path / "pairs.csv"
    path.write_text("x,y,z,qw,qx,qy,qz,image\n" + text, encoding="utf-8")
    try:
        rows = read_pairs_csv(path)
    except HandEyeError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)
        return
    for row in rows:
        r = row.tool_in_base[:3, :3]
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
