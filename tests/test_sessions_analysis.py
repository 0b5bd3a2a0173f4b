"""``qrfield analyze`` on a session made here, its figures checked against hand-computed values."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from qrfield.cli import main
from qrfield.sessions import GroundTruth, Session, measure
from qrfield.sessions.analysis import SEED_RESEMBLANCE_PERCENT, analyze, format_report
from qrfield.sessions.plotting import nice_ticks


def one_frame(pos, ang, converged=True):
    return [{"position_mm": pos, "angles_deg": ang, "converged": converged}]


def log(session, truth, pos, ang, converged=True):
    outcome = session.log(measure(one_frame(pos, ang, converged), GroundTruth(*truth)))
    assert outcome.ok
    return outcome.row


@pytest.fixture
def session_dir(tmp_path, camera_vga):
    s = Session.create(tmp_path / "sessions", "analysis", camera=camera_vga, side_mm=60.0, solver="numerical")
    # combo A: row 1 passes (1 mm, 1 deg); row 2 fails (exactly 5 mm, 3 deg); row 3 withdrawn.
    log(s, (0, 0, 300, 10, 0, 0, "A"), [1, 0, 300], [11, 0, 0])
    log(s, (0, 0, 300, 20, 0, 0, "A"), [0, 3, 304], [23, 0, 0])
    log(s, (0, 0, 300, 30, 0, 0, "A"), [100, 0, 300], [30, 0, 0])
    s.undo()
    # combo B: row 4 passes (2 mm, beta -1, gamma +0.5); row 5 has no converged frame;
    # row 6 passes across the wrap (gamma -179 measured, 179 true: +2 deg).
    log(s, (0, 0, 400, 0, 15, -5, "B"), [0, 0, 402], [0, 14, -4.5])
    log(s, (0, 0, 400, 0, -15, 0, "B"), [0, 0, 400], [0, 0, 0], converged=False)
    log(s, (0, 0, 400, 0, 20, 179, "B"), [0, 0, 400], [0, 20, -179])
    s.close()
    return s.path


def test_analyze_json_figures_by_hand(session_dir, tmp_path, capsys):
    out = tmp_path / "figures"
    assert main(["analyze", str(session_dir), "--json", "--out", str(out)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"rows", "pass_rate", "per_combination", "resemblance"} <= set(result)
    assert result["rows"] == 5 and result["withdrawn"] == 1 and result["passed"] == 3
    assert result["pass_rate"] == pytest.approx(3 / 5)
    combos = {c["combo"]: c for c in result["per_combination"]}
    assert list(combos) == ["A", "B"]
    a, b = combos["A"], combos["B"]
    assert (a["rows"], a["passed"], a["no_pose"]) == (2, 1, 0)
    assert a["pass_rate"] == pytest.approx(0.5)
    assert a["mean_abs_error"] == pytest.approx(
        {
            "x_mm": 0.5,
            "y_mm": 1.5,
            "z_mm": 2.0,
            "pos_mm": 3.0,
            "alpha_deg": 2.0,
            "beta_deg": 0.0,
            "gamma_deg": 0.0,
        }
    )
    assert a["max_abs_error"] == pytest.approx(
        {
            "x_mm": 1.0,
            "y_mm": 3.0,
            "z_mm": 4.0,
            "pos_mm": 5.0,
            "alpha_deg": 3.0,
            "beta_deg": 0.0,
            "gamma_deg": 0.0,
        }
    )
    assert (b["rows"], b["passed"], b["no_pose"]) == (3, 2, 1)
    assert b["pass_rate"] == pytest.approx(2 / 3)
    assert b["mean_abs_error"] == pytest.approx(
        {
            "x_mm": 0.0,
            "y_mm": 0.0,
            "z_mm": 1.0,
            "pos_mm": 1.0,
            "alpha_deg": 0.0,
            "beta_deg": 0.5,
            "gamma_deg": 1.25,
        }
    )
    assert b["max_abs_error"]["gamma_deg"] == pytest.approx(2.0)
    # Overall over the 4 rows with a pose: position errors 1, 5, 2, 0.
    assert result["mean_abs_error"]["pos_mm"] == pytest.approx(2.0)
    assert result["max_abs_error"]["pos_mm"] == pytest.approx(5.0)
    for name in ("errors_vs_tilt.png", "measured_vs_truth.png"):
        img = cv2.imread(str(out / name))
        assert img is not None and img.shape[0] > 300 and img.shape[1] > 600
        assert img.std() > 10  # drawn on, not blank


def test_analyze_text_report(session_dir, capsys):
    assert main(["analyze", str(session_dir)]) == 0
    text = capsys.readouterr().out
    assert "pass rate 60.00%" in text
    assert "withdrawn 1 not counted" in text
    assert f"seed: {SEED_RESEMBLANCE_PERCENT:.2f}%" in text
    line_a = next(line for line in text.splitlines() if line.startswith("A "))
    assert "50.00%" in line_a and "3.00 / 5.00" in line_a


def test_analyze_names_a_missing_session(tmp_path, capsys):
    assert main(["analyze", str(tmp_path / "nope")]) == 2
    assert "no such session folder" in capsys.readouterr().err


def test_analyze_says_a_file_is_not_a_session_folder(tmp_path, capsys):
    """A file given for the folder is named a file, not missing (audit-2)."""
    image = tmp_path / "two.png"
    cv2.imwrite(str(image), np.zeros((8, 8), np.uint8))
    assert main(["analyze", str(image)]) == 2
    err = capsys.readouterr().err
    assert "is a file, not a session folder" in err and "no such session folder" not in err


@pytest.mark.parametrize(
    ("lo", "hi", "ticks"),
    [
        (0.0, 10.0, [0, 2, 4, 6, 8, 10]),
        (-0.3, 2.4, [0.0, 0.5, 1.0, 1.5, 2.0]),
        (346.0, 350.4, [346, 347, 348, 349, 350]),
    ],
)
def test_nice_ticks(lo, hi, ticks):
    values, _ = nice_ticks(lo, hi, count=6)
    np.testing.assert_allclose(values, ticks)


def test_resemblance_with_the_solver(tmp_path, camera_vga):
    s = Session.create(tmp_path, "resemblance", camera=camera_vga, side_mm=60.0, solver="numerical")
    easy = (0.0, 0.0, 300.0, 10.0, 5.0, 0.0, "A")  # 105 px card, gentle tilt: whole-pixel corners pass
    outside = (400.0, 0.0, 300.0, 10.0, 5.0, 0.0, "A")  # the card's centre is off the image
    away = (0.0, 0.0, 300.0, 120.0, 0.0, 0.0, "A")  # turned past edge-on: the face looks away
    log(s, easy, easy[:3], easy[3:6])  # pass, simulation pass: agree
    log(s, easy, [0, 0, 310], easy[3:6])  # fail (10 mm), simulation pass: disagree
    log(s, outside, outside[:3], outside[3:6])  # pass, simulation fail: disagree
    log(s, away, [0, 0, 300], [0, 0, 0])  # fail, simulation fail: agree
    s.close()
    result = analyze(s.path)
    res = result["resemblance"]
    assert res is not None, result["resemblance_reason"]
    assert [r["simulation_pass"] for r in res["per_row"]] == [True, True, False, False]
    assert "outside the 640x480 image" in res["per_row"][2]["simulation_reason"]
    assert "turned away" in res["per_row"][3]["simulation_reason"]
    assert (res["matches"], res["compared"]) == (2, 4)
    assert res["percent"] == pytest.approx(50.0)
    assert res["seed_percent"] == 73.15
    # The session's solver (defaults: settled stop, 1 mm) converges on the easy rows: both readings agree.
    assert [r["simulation_pass_converged"] for r in res["per_row"]] == [True, True, False, False]
    assert (res["matches_converged"], res["percent_converged"]) == (2, 50.0)


def test_resemblance_in_both_readings_when_the_solver_settles_above_its_tolerance(tmp_path, camera_vga):
    # The study's numerical-parallelogram (seed stop rule, 0.01 mm): whole-pixel corners fit no
    # four depths to 0.01 mm, so it settles (stalls) above the tolerance, here with a pose within
    # 2 deg / 5 mm. Within criteria, the simulation passes the row; converged and within, it fails.
    from qrfield.solvers import NumericalSettings, solve

    settings = NumericalSettings(initial_guess="parallelogram", stop="seed", tolerance_mm=0.01)
    s = Session.create(tmp_path, "settled", camera=camera_vga, side_mm=60.0, solver="numerical",
                       solver_settings=settings)  # fmt: skip
    pose = (30.0, 20.0, 400.0, -15.0, 10.0, 30.0, "A")
    log(s, pose, pose[:3], pose[3:6])  # logged as a pass
    s.close()
    # Independent check of the premise, by the single solver on the rounded corners.
    from qrfield.geometry import Pose

    corners = np.round(Pose(pose[:3], pose[3:6]).corners_px(camera_vga, 60.0))
    r = solve(corners, camera_vga, 60.0, "numerical", settings)
    assert not r.converged and r.iterations < settings.n_max
    assert np.linalg.norm(r.position_mm - pose[:3]) < 5.0
    res = analyze(s.path)["resemblance"]
    row = res["per_row"][0]
    assert (row["simulation_pass"], row["simulation_pass_converged"]) == (True, False)
    assert "not converged" in row["simulation_reason"]
    assert (res["percent"], res["percent_converged"]) == (100.0, 0.0)
    text = format_report(analyze(s.path))
    assert "within criteria 100.00%" in text and "converged and within criteria 0.00%" in text


@pytest.mark.slow
def test_sessions_pull_in_no_qt():
    import os
    import subprocess
    import sys

    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    code = (
        "import sys, qrfield.sessions, qrfield.sessions.analysis, qrfield.sessions.plots, "
        "qrfield.commands.analyze; "
        "banned = ('PySide6', 'pyqtgraph', 'shiboken6', 'matplotlib'); "
        "bad = [m for m in sys.modules if m.startswith(banned)]; "
        "assert not bad, bad"
    )
    subprocess.run(
        [sys.executable, "-c", code], check=True, env={**os.environ, "PYTHONPATH": repo}, timeout=120
    )


def test_a_row_with_damaged_ground_truth_is_left_out_of_the_resemblance_not_fatal(tmp_path, camera_vga):
    from qrfield.sessions import GroundTruth, Session, measure
    from qrfield.sessions.analysis import analyze, format_report

    session = Session.create(tmp_path, "damaged", camera=camera_vga, side_mm=50.0, solver="numerical")
    frames = [{"position_mm": [0.0, 0.0, 300.0], "angles_deg": [10.0, 0.0, 0.0], "converged": True}]
    session.log(measure(frames, GroundTruth(0.0, 0.0, 300.0, 10.0, 0.0, 0.0, "alpha")))
    session.close()
    with open(session.rows_path, "a", encoding="utf-8") as fh:  # a row edited by hand: gt_x is text
        fh.write("2,now,alpha,abc" + "," * 18 + "1,\n")
    result = analyze(session.path)
    res = result["resemblance"]
    assert (res["compared"], res["not_compared"]) == (1, 1)
    assert isinstance(res["per_row"][0]["match"], bool) and res["per_row"][1]["match"] is None
    assert "ground truth is incomplete" in res["per_row"][1]["simulation_reason"]
    assert "1 row(s) without a complete ground truth not compared" in format_report(result)


def test_analyze_never_overwrites_its_plots_without_force(session_dir, tmp_path, capsys):
    out = tmp_path / "plots"
    out.mkdir()
    (out / "errors_vs_tilt.png").write_bytes(b"mine")
    assert main(["analyze", str(session_dir), "--no-simulation", "--out", str(out)]) == 2
    assert "errors_vs_tilt.png exists; choose another name, or add --force" in capsys.readouterr().err
    assert (out / "errors_vs_tilt.png").read_bytes() == b"mine" and not (
        out / "measured_vs_truth.png"
    ).exists()
    assert main(["analyze", str(session_dir), "--no-simulation", "--out", str(out), "--force"]) == 0
    assert (out / "errors_vs_tilt.png").read_bytes().startswith(b"\x89PNG")
