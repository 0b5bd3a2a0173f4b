"""The qrfield command line: subcommand discovery, render, clear errors, no Qt in the core."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from qrfield.cli import main

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _run(*args, env=None):
    full_env = {**os.environ, "PYTHONPATH": REPO, **(env or {})}
    return subprocess.run(
        [sys.executable, "-m", "qrfield", *args], capture_output=True, text=True, env=full_env, timeout=120
    )


@pytest.mark.slow
def test_help_lists_subcommands():
    out = _run("--help")
    assert out.returncode == 0
    for name in ("render", "benchmark", "gui"):
        assert name in out.stdout
    assert "benchmark (bench)" in out.stdout  # the old name is still listed as an alias


@pytest.mark.slow
def test_core_import_pulls_in_no_qt():
    # Import every module of the core, then look for Qt in what got loaded.
    code = (
        "import importlib, pkgutil, sys, qrfield\n"
        "for m in pkgutil.walk_packages(qrfield.__path__, 'qrfield.'):\n"
        "    if not m.name.endswith('__main__'): importlib.import_module(m.name)\n"
        "import qrfield.cli; qrfield.cli.build_parser()\n"
        "bad = [m for m in sys.modules if m.startswith(('PySide6', 'pyqtgraph', 'shiboken6'))]\n"
        "assert not bad, bad\n"
    )
    subprocess.run(
        [sys.executable, "-c", code], check=True, env={**os.environ, "PYTHONPATH": REPO}, timeout=120
    )


def test_core_has_no_qt_import_even_inside_functions():
    # The app is reached only through ui/ (qrfield gui -> ui.app, benchmark pipeline -> ui.gui_rates).
    pattern = re.compile(r"^\s*(from|import)\s+(PySide6|pyqtgraph|shiboken6)\b", re.M)
    core = Path(REPO) / "qrfield"
    offenders = [str(p.relative_to(REPO)) for p in core.rglob("*.py") if pattern.search(p.read_text())]
    assert offenders == []


def test_render_json_corners_by_hand(tmp_path, capsys):
    out = tmp_path / "view.png"
    # fx = fy = 500, 640x480: a 60 mm code square-on at 300 mm spans 100 px about (319.5, 239.5).
    code = main(
        [
            "render",
            "--focal-px",
            "500",
            "--size",
            "640x480",
            "--side-mm",
            "60",
            "--pose",
            "0,0,300,0,0,0",
            "--out",
            str(out),
            "--json",
        ]
    )
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["corners"] == [[269.5, 189.5], [369.5, 189.5], [369.5, 289.5], [269.5, 289.5]]
    image = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert image.shape == (480, 640)
    assert image[239, 319] in (0, 255)  # the symbol is drawn where the corners say


@pytest.mark.slow
def test_render_out_of_view_is_one_clear_line(tmp_path):
    out = _run(
        "render",
        "--camera",
        "picam-v2@640x480",
        "--side-mm",
        "50",
        "--pose",
        "500,0,300,0,0,0",
        "--out",
        str(tmp_path / "x.png"),
    )
    assert out.returncode == 2
    assert "out of view" in out.stderr and "Traceback" not in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_bad_camera_file_is_one_clear_line(tmp_path):
    bad = tmp_path / "cam.json"
    bad.write_text('{"width": 640}')
    out = _run(
        "render",
        "--camera",
        str(bad),
        "--side-mm",
        "50",
        "--pose",
        "0,0,300,0,0,0",
        "--out",
        str(tmp_path / "x.png"),
    )
    assert out.returncode == 2 and "missing field" in out.stderr and str(bad) in out.stderr


@pytest.mark.slow
@pytest.mark.parametrize("command", ["marker", "render"])
def test_qr_text_too_long_to_encode_is_one_clear_line(tmp_path, command):
    # 3000 letters exceed a QR code's capacity (2953 bytes at level L): OpenCV raises cv2.error.
    text = "x" * 3000
    if command == "marker":
        args = ["marker", "--text", text, "--side-mm", "50", "--out", str(tmp_path / "m.svg")]
    else:
        args = ["render", "--focal-px", "500", "--size", "640x480", "--side-mm", "50"]
        args += ["--pose", "0,0,300,0,0,0", "--text", text, "--out", str(tmp_path / "r.png")]
    out = _run(*args)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr and "maximum capacity" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.parametrize(
    ("option", "value", "named"),
    [
        ("--side-mm", "-1", "--side-mm"),
        ("--camera", "nosuch", "nosuch"),
        ("--quit-after", "-1", "--quit-after"),
    ],
)
def test_gui_bad_option_is_one_clear_line_before_any_window(option, value, named):
    out = _run("gui", option, value, env={"QT_QPA_PLATFORM": "offscreen"})
    assert out.returncode == 2
    assert named in out.stderr and "Traceback" not in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_no_display_says_how_to_run_headless():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    env["PYTHONPATH"] = REPO
    out = subprocess.run(
        [sys.executable, "-m", "qrfield"], capture_output=True, text=True, env=env, timeout=120
    )
    assert out.returncode != 0
    assert "no display" in out.stderr and "--headless" in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.slow
@pytest.mark.parametrize("command", ["benchmark", "bench"])
def test_benchmark_runs_under_its_name_and_its_old_alias(command):
    # `qrfield bench NAME` was the command's name before: users' scripts type it and it must work the same.
    out = _run(command, "render", "--views", "3")
    assert out.returncode == 0, out.stderr
    assert "ratio" in out.stdout
    assert out.stdout.startswith("qrfield benchmark render:")


def test_benchmark_alias_lists_the_same_benchmarks(capsys):
    for command in ("benchmark", "bench"):
        assert main([command, "--help"]) == 0
    first, second = capsys.readouterr().out.split("usage:")[1:]
    names = re.compile(r"^\s{4}(\w[\w-]*)\s", re.M)
    assert names.findall(first) == names.findall(second)
    assert {"detect", "pose", "render", "solvers", "pipeline", "serial"} <= set(names.findall(first))


@pytest.mark.parametrize(
    "argv",
    [
        ["serial-monitor", "loop://", "--seconds", "nan"],  # would never stop
        ["serial-monitor", "loop://", "--seconds", "-1"],
        ["serial-demo", "loop://", "--seconds", "-1"],
        ["serial-demo", "loop://", "--seconds", "1", "--fps", "inf"],  # would publish in a busy loop
        ["run", "--source", "virtual", "--frames", "1", "--retry-s", "nan"],  # would retry in a busy loop
        ["run", "--source", "virtual", "--frames", "1", "--retry-s", "-1"],
    ],
)
def test_bad_durations_and_rates_are_one_line(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and argv[-2] in err


def test_simulate_checks_its_output_folder_before_running_the_study(tmp_path, capsys, monkeypatch):
    import qrfield.simulation

    def must_not_run(*args, **kwargs):
        raise AssertionError("the study ran although its results could not be written")

    monkeypatch.setattr(qrfield.simulation, "run_study", must_not_run)
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert main(["simulate", "--quiet", "--out", str(blocker / "out")]) == 2
    err = capsys.readouterr().err
    assert "cannot create the folder" in err and len(err.strip().splitlines()) == 1


def _one_line_error(argv, capsys, code=2):
    assert main(argv) == code
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line or "cannot" in line]
    assert len(err) == 1, err
    return err[0]


def test_errors_of_the_prober_are_one_line_with_their_cause(tmp_path, capsys, monkeypatch):
    """Each was several lines or the wrong cause: seven lines of OpenCV's overloads, numpy's
    overflow warnings then "faces away", "no such file" for a FIFO, a week-long limit missing."""
    monkeypatch.chdir(tmp_path)
    run = ["run", "--camera", "picam-v2@640x480", "--side-mm", "50", "--frames", "1", "--retry-s", "0"]
    main([*run, "--source", "usb:99999999999999999999"])
    err = capsys.readouterr().err
    assert "USB camera index 999999999999... is above the largest, 255" in err
    assert "Overload" not in err and err.count("usb:9999") == 1
    os.mkfifo(tmp_path / "pipe")
    main([*run, "--source", "pipe"])
    err = capsys.readouterr().err
    assert "source 'pipe': a FIFO (named pipe), not a regular file" in err and "no such file" not in err
    line = _one_line_error(
        ["render", "--side-mm", "30", "--pose", "0,0,1e308,0,0,0", "--out", "x.png"], capsys
    )
    assert "--pose: Z: position 1e+308 mm is above the largest accepted" in line
    line = _one_line_error(["serial-demo", "loop://", "--seconds", "1e308"], capsys)
    assert "--seconds: duration 1e+308 s is above the largest accepted, 604800 s" in line


def test_an_output_name_as_long_as_the_file_system_allows_is_written(tmp_path, capsys):
    """A 255-byte name failed with the error of the temporary file's longer name."""
    name = "a" * 251 + ".png"
    argv = ["render", "--side-mm", "30", "--pose", "0,0,300,0,0,0", "--out", str(tmp_path / name)]
    assert main(argv) == 0 and (tmp_path / name).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no temporary file left
    capsys.readouterr()
    line = _one_line_error([*argv[:-1], str(tmp_path / ("b" + name))], capsys)
    assert "a name in it is 256 bytes long, more than the 255 the file system allows" in line


@pytest.mark.slow
def test_a_name_too_long_is_said_in_words_with_the_name_as_typed(tmp_path, capsys):
    """``session new ROOT`` with a 256-byte ROOT said "[Errno 36] File name too long: '...'" (its
    is_dir() raised before the name was measured), and the words of a too-long --out were
    lower-cased, its name with them ("cannot write --out MyScan.png" became "myscan.png")."""
    folder = tmp_path / "Bench"
    folder.mkdir()
    name = "Scan" + "B" * 252 + ".png"
    argv = ["render", "--side-mm", "30", "--pose", "0,0,300,0,0,0", "--out", str(folder / name)]
    line = _one_line_error(argv, capsys)
    assert f"cannot write --out {folder / name}: a name in it is 260 bytes long" in line
    root = tmp_path / ("Root" + "R" * 252)
    line = _one_line_error(["session", "new", str(root), "--name", "x", "--camera", "picam-v2"], capsys)
    assert "[Errno" not in line
    assert f"sessions folder {root}: cannot create the folder: a name in it is 256 bytes long" in line


def test_render_never_overwrites_a_file_without_force(tmp_path, capsys):
    """Issue 23: render --out replaced an existing file silently."""
    out = tmp_path / "view.png"
    out.write_bytes(b"my photo")
    argv = ["render", "--side-mm", "30", "--pose", "0,0,300,0,0,0", "--out", str(out)]
    assert main(argv) == 2
    assert f"--out {out} exists; choose another name, or add --force" in capsys.readouterr().err
    assert out.read_bytes() == b"my photo"
    assert main([*argv, "--force"]) == 0 and cv2.imread(str(out)).shape == (480, 640, 3)
