"""Heatmap pixels, the progress bar, and the ``qrfield simulate`` command end to end."""

from __future__ import annotations

import csv
import io
import json
import re

import cv2
import numpy as np
import pytest

from qrfield.cli import main
from qrfield.simulation import heatmap
from qrfield.simulation.progress import TerminalProgress
from qrfield.simulation.runner import OUT_OF_VIEW, PASSED, Progress


def test_heatmap_cells_carry_the_viridis_colour_of_their_angle():
    values = np.array([[0.0, 45.0, 90.0], [np.nan, np.nan, 30.0]])
    kinds = np.array([["", "", ""], [heatmap.CELL_OUT_OF_VIEW, heatmap.CELL_NONE, ""]], dtype=object)
    x, y = np.array([-50.0, 0.0, 50.0]), np.array([-20.0, 20.0])
    img = heatmap.draw_heatmap([values], [kinds], ["numerical"], x, y, 90.0, "title", "subtitle")
    assert img.ndim == 3 and img.dtype == np.uint8
    # Locate the panel from its drawn frame: the first row of grey frame pixels below the title.
    cell = int(np.clip(400 // 3, 22, 72))
    left, top = 78, 92
    for iy in range(2):
        for ix in range(3):
            pixel = img[top + iy * cell + 3, left + ix * cell + 3]  # a cell corner, away from its label
            if kinds[iy, ix] == "":
                grey = np.uint8(round(values[iy, ix] / 90.0 * 255))
                expected = cv2.applyColorMap(np.array([[grey]], np.uint8), cv2.COLORMAP_VIRIDIS)[0, 0]
            elif kinds[iy, ix] == heatmap.CELL_OUT_OF_VIEW:
                expected = heatmap.OUT_COLOUR
            else:
                expected = heatmap.NONE_COLOUR
            np.testing.assert_array_equal(pixel, expected, err_msg=f"cell {iy}, {ix}")


def test_progress_bar_prints_share_and_rate_to_a_log():
    stream = io.StringIO()
    bar = TerminalProgress(stream=stream)
    for done in (0, 50, 100, 150, 200):
        bar(Progress(done, 200, "alpha", seconds=done / 100 + 0.01))
    bar.finish()
    lines = stream.getvalue().splitlines()
    assert 3 <= len(lines) <= 5  # one line per tenth when not a terminal
    assert "100.0 %" in lines[-1] and "200/200 poses" in lines[-1] and "poses/s" in lines[-1]


@pytest.mark.slow
def test_simulate_command_writes_every_output(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        [
            "simulate", "--quiet", "--out", str(out), "--csv",
            "--set", "x_range=-40,40,40", "--set", "y_range=0", "--set", "z_range=250,350,100",
            "--set", "sweep_limit_deg=60", "--set", "sweep_step_deg=20",
            "--set", "solvers=numerical,numerical-parallelogram",
        ]
    )  # fmt: skip
    assert code == 0
    printed = capsys.readouterr()
    assert "77.28" in printed.out and "mean" in printed.out
    assert "poses/s" in printed.err
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["samples"] == 3 * 2 * 12 * 4 and summary["partial"] is False
    for name in ("summary.md", "study.toml", "samples.npz", "samples.csv", "max_angles.csv"):
        assert (out / name).is_file(), name
    with np.load(out / "samples.npz") as npz:
        status = npz["status"]
        position = npz["position_mm"]
    with (out / "samples.csv").open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == status.size  # one row per solver and sample
    assert sum(r["status"] == "passed" for r in rows) == np.count_nonzero(status == PASSED)
    assert sum(r["status"] == "out of view" for r in rows) == np.count_nonzero(status == OUT_OF_VIEW)
    first = rows[1]  # numerical, first combination, first grid point, t = 20
    assert [first[k] for k in ("solver", "x_mm", "z_mm", "t_deg")] == ["numerical", "-40", "250", "20"]
    assert float(first["x"]) == pytest.approx(position[0, 0, 0, 1, 0], abs=1e-4)
    pngs = sorted((out / "heatmaps").glob("*.png"))
    assert len(pngs) == 12 * 2  # per combination and z
    assert cv2.imread(str(pngs[0])) is not None
    # The written study reruns the same study.
    assert main(["simulate", str(out / "study.toml"), "--show"]) == 0
    assert "x_range = [-40.0, 40.0, 40.0]" in capsys.readouterr().out
    # A non-empty output folder is refused unless --force.
    assert main(["simulate", "--quiet", "--out", str(out), "--set", "z_range=300"]) == 2
    assert "not empty" in capsys.readouterr().err


def test_simulate_command_names_the_bad_field(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[criteria]\nangle_degs = 1\n", encoding="utf-8")
    assert main(["simulate", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "criteria.angle_degs" in err and "angle_deg" in err and "Traceback" not in err
    assert main(["simulate", "--set", "z_range=400,200,100", "--show"]) == 2
    assert "z_range" in capsys.readouterr().err


SMALL_STUDY = [
    "--set",
    "x_range=0",
    "--set",
    "y_range=0",
    "--set",
    "z_range=300",
    "--set",
    "sweep_step_deg=45",
]


def test_without_out_the_run_goes_to_a_new_folder_in_the_current_folder(tmp_path, monkeypatch, capsys):
    """Issue 23: a command writes in the current folder or the folder named, never elsewhere
    (it wrote under ~/.local/share/qrfield/simulations)."""
    data, work = tmp_path / "data", tmp_path / "work"
    work.mkdir()
    monkeypatch.setenv("QRFIELD_DATA_DIR", str(data))
    monkeypatch.chdir(work)
    assert main(["simulate", "--quiet", "--no-heatmaps", *SMALL_STUDY]) == 0
    assert main(["simulate", "--quiet", "--no-heatmaps", *SMALL_STUDY]) == 0  # the same second, maybe
    runs = sorted(work.iterdir())
    assert len(runs) == 2 and all(re.fullmatch(r"simulation-\d{8}-\d{6}(-\d+)?", r.name) for r in runs)
    assert not data.exists()  # nothing outside the current folder
    err = capsys.readouterr().err
    assert str(runs[0].resolve()) in err and str(runs[1].resolve()) in err
    # Samples are stored compactly by default: npz (poses as float32), no CSV.
    names = {p.name for p in runs[0].iterdir()}
    assert names == {"study.toml", "summary.json", "summary.md", "samples.npz", "max_angles.csv"}
    with np.load(runs[0] / "samples.npz") as npz:
        assert npz["position_mm"].dtype == np.float32 and npz["angles_deg"].dtype == np.float32
        assert npz["status"].dtype == np.int8
    summary = json.loads((runs[0] / "summary.json").read_text(encoding="utf-8"))
    assert set(summary["mean_coverage_converged"]) == set(summary["mean_coverage"])


def test_a_relative_out_is_the_callers_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "runs").mkdir()  # qrfield makes the folder named, never the ones above it (docs/cli.md)
    assert main(["simulate", "--quiet", "--no-heatmaps", "--out", "runs/first", *SMALL_STUDY]) == 0
    assert (tmp_path / "runs" / "first" / "summary.json").is_file()
    assert str((tmp_path / "runs" / "first").resolve()) in capsys.readouterr().err
    assert main(["simulate", "--quiet", "--no-heatmaps", "--out", "nowhere/first", *SMALL_STUDY]) == 2
    assert "nowhere does not exist" in capsys.readouterr().err and not (tmp_path / "nowhere").exists()


@pytest.mark.slow
def test_run_sh_keeps_the_callers_folder(tmp_path):
    # ./run.sh makes the venv in the checkout, then runs the command where the caller is.
    import os
    import subprocess
    from pathlib import Path

    repo = Path(__file__).resolve().parent.parent
    venv = repo / ".venv" / "bin" / "qrfield"
    if not venv.exists():
        pytest.skip("no .venv with qrfield installed beside run.sh")
    out = subprocess.run(
        [str(repo / "run.sh"), "simulate", "--quiet", "--no-heatmaps", "--out", "here", *SMALL_STUDY],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
        env={**os.environ, "QRFIELD_VENV": str(repo / ".venv")},
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "here" / "summary.json").is_file()


def test_the_terminal_table_shows_both_readings(tmp_path, capsys):
    assert main(["simulate", "--quiet", "--no-heatmaps", "--out", str(tmp_path / "o"), *SMALL_STUDY]) == 0
    out = capsys.readouterr().out
    header = out.splitlines()[1]
    assert header.count("within") == 6 and header.count("conv+within") == 3
    mean = next(line for line in out.splitlines() if line.startswith("mean"))
    assert mean.count("%") == 6
