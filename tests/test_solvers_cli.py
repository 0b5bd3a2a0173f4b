"""``qrfield solve``: JSON and table output checked against a rendered view's truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from qrfield.camera import resolve_camera
from qrfield.cli import main
from qrfield.geometry import Pose, angle_difference
from qrfield.render import render_view

SIDE = 40.0


def _corner_text(corners) -> str:
    return " ".join(f"{float(u)!r},{float(v)!r}" for u, v in corners)


@pytest.fixture(scope="module")
def view():
    camera = resolve_camera("picam-v2@640x480")
    return render_view(camera, SIDE, Pose([-25.0, 15.0, 350.0], [20.0, -30.0, 75.0]))


def test_json_output_matches_the_rendered_truth(view, capsys):
    code = main(
        [
            "solve",
            "--corners",
            _corner_text(view.corners_px),
            "--camera",
            "picam-v2@640x480",
            "--side-mm",
            str(SIDE),
            "--method",
            "both",
            "--json",
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert [entry["method"] for entry in out] == ["numerical", "ippe"]
    for entry in out:
        assert entry["converged"] is True
        assert np.allclose(entry["position_mm"], view.pose.position_mm, atol=1e-6)
        assert np.all(np.abs(angle_difference(entry["angles_deg"], view.pose.angles_deg)) < 1e-6)
        assert np.allclose(entry["corners"], view.corners_px, atol=0)
        assert entry["reprojection_px"] < 1e-6 and isinstance(entry["iterations"], int)
        assert {"reason", "ambiguity", "residual_mm"} <= set(entry)


def test_settings_options_reach_the_solver(view, capsys):
    args = [
        "solve",
        "--corners",
        _corner_text(view.corners_px),
        "--focal-px",
        "529.6167804878049",
        "--size",
        "640x480",
        "--side-mm",
        str(SIDE),
        "--method",
        "numerical",
        "--json",
    ]
    assert (
        main([*args, "--initial-guess", "seed", "--stop", "seed", "--tolerance-mm", "1e-9", "--n-max", "2"])
        == 1
    )
    entry = json.loads(capsys.readouterr().out)[0]
    assert entry["converged"] is False and entry["iterations"] == 2 and "n_max = 2" in entry["reason"]
    assert main([*args, "--tf", "7"]) == 2
    assert "tf" in capsys.readouterr().err


def test_table_output(view, capsys):
    code = main(
        [
            "solve",
            "--corners",
            _corner_text(view.corners_px),
            "--camera",
            "picam-v2@640x480",
            "--side-mm",
            str(SIDE),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    lines = out.splitlines()
    assert lines[1].split()[:4] == ["method", "x", "mm", "y"]
    row = next(line for line in lines if line.startswith("numerical "))
    x, y, z, a, b, g = (float(v) for v in row.split()[1:7])
    assert (x, y, z) == pytest.approx(tuple(view.pose.position_mm), abs=0.05)
    assert (a, b, g) == pytest.approx(tuple(view.pose.angles_deg), abs=0.005)
    assert any(line.startswith("ippe ") for line in lines)


@pytest.mark.parametrize(
    ("corners", "message"),
    [
        ("1,2 3,4 5,6", "4 pixel pairs"),
        ("1,2 3,4 5,6 7;8", "4 pixel pairs"),
        ("1,2 3,4 5,x 7,8", "V3"),
        ("100,100 200,100 200,200 100,200 ", ""),
        ("100,100 100,200 200,200 200,100", "counter-clockwise"),
    ],
)
def test_bad_corners_exit_2_with_one_line(corners, message, capsys):
    code = main(["solve", "--corners", corners, "--camera", "picam-v2@640x480", "--side-mm", "50"])
    err = capsys.readouterr().err
    if message:
        assert code == 2 and message in err and "Traceback" not in err
    else:
        assert code == 0  # trailing space is fine


def test_missing_camera_is_named(capsys):
    assert main(["solve", "--corners", "100,100 200,100 200,200 100,200", "--side-mm", "50"]) == 2
    assert "--camera" in capsys.readouterr().err


def test_corner_std_gives_the_pose_its_std_and_nulls_without_it(view, capsys):
    base = ["solve", "--corners", _corner_text(view.corners_px), "--camera", "picam-v2@640x480"]
    base += ["--side-mm", str(SIDE), "--json"]
    assert main(base) == 0
    for entry in json.loads(capsys.readouterr().out):
        assert entry["position_std_mm"] == [None] * 3 and entry["angles_std_deg"] == [None] * 3
        assert entry["ambiguous"] is False
    stds = {}
    for s in ("0.1", "0.2"):
        assert main([*base, "--corner-std-px", s]) == 0
        for entry in json.loads(capsys.readouterr().out):
            assert entry["corners_std_px"] == pytest.approx([float(s) * 2**0.5] * 4)
            stds[entry["method"], s] = np.array(entry["position_std_mm"] + entry["angles_std_deg"])
    for method in ("numerical", "ippe"):
        assert np.all(stds[method, "0.1"] > 0)
        np.testing.assert_allclose(stds[method, "0.2"], 2 * stds[method, "0.1"], rtol=1e-9)  # linear
    assert main([*base, "--corner-std-px", "-0.5"]) == 2
    # Refused by the option's limits (qrfield.limits, issue 15), naming the option.
    err = capsys.readouterr().err
    assert "--corner-std-px" in err and "below the smallest accepted, 0 px" in err


def test_corner_std_is_refused_with_images(tmp_path, capsys):
    image = tmp_path / "view.png"
    image.write_bytes(b"not read")
    code = main(
        ["solve", str(image), "--camera", "picam-v2@640x480", "--side-mm", "40", "--corner-std-px", "1"]
    )
    assert code == 2 and "--corner-std-px goes with --corners" in capsys.readouterr().err


def test_table_shows_the_std_under_each_pose_and_the_flip_column(view, capsys):
    args = ["solve", "--corners", _corner_text(view.corners_px), "--camera", "picam-v2@640x480"]
    assert main([*args, "--side-mm", str(SIDE), "--corner-std-px", "0.1"]) == 0
    out = capsys.readouterr().out
    assert "flip?" in out.splitlines()[1]
    std_lines = [line for line in out.splitlines() if line.startswith("  std")]
    assert len(std_lines) == 2 and all(line.count("+-") == 6 for line in std_lines)


@pytest.mark.slow
def test_corners_off_their_std_warn_of_a_misfit_in_the_table_and_json(view, capsys):
    """The rendered view's exact corners fit (no warning); V3 moved 2 px right and 1.5 px up
    under --corner-std-px 0.1 cannot be fitted by a square's pose (chi-square far above 9.21):
    each method warns in the table and says ``"misfit": true`` in JSON; the exit code stays 0."""
    moved = np.array(view.corners_px, dtype=float)
    moved[2] += (2.0, -1.5)
    base = ["solve", "--camera", "picam-v2@640x480", "--side-mm", str(SIDE), "--corner-std-px", "0.1"]
    for corners, misfit in ((view.corners_px, False), (moved, True)):
        assert main([*base, "--corners", _corner_text(corners), "--json"]) == 0
        entries = json.loads(capsys.readouterr().out)
        assert [e["misfit"] for e in entries] == [misfit, misfit]
        assert main([*base, "--corners", _corner_text(corners)]) == 0
        out = capsys.readouterr().out
        for method in ("numerical", "ippe"):
            assert (f"WARNING {method}: the corners do not fit the pose" in out) is misfit
