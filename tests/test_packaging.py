"""Packaging: the core and every command but the app need no Qt; the app names its extra and, where
Qt's libraries are missing, the apt package. (A real fresh venv: scripts/check-headless-install.sh.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from qrfield.commands.gui import qt_problem

REPO = Path(__file__).resolve().parent.parent

# Makes PySide6, shiboken6 and pyqtgraph unimportable, as in a venv made by `pip install .`.
NO_QT = """
import importlib.abc, sys
class NoQt(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("PySide6", "shiboken6", "pyqtgraph"):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, NoQt())
"""


def test_every_package_is_listed_in_pyproject():
    # Every package in the source tree is installed (a non-editable install would miss it otherwise).
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    on_disk = {
        ".".join(init.parent.relative_to(REPO).parts)
        for top in ("qrfield", "ui")
        for init in (REPO / top).rglob("__init__.py")
        if "__pycache__" not in init.parts
    }
    assert on_disk - listed == set(), f"add to [tool.setuptools] packages: {sorted(on_disk - listed)}"
    assert config["package-dir"]["qrfield_calib"] == "calib"


def test_the_core_dependencies_have_no_qt_and_the_gui_extra_has_it():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    core = " ".join(project["dependencies"]).lower()
    assert "pyside" not in core and "pyqtgraph" not in core and "qt" not in core
    gui = " ".join(project["optional-dependencies"]["gui"]).lower()
    assert "pyside6-essentials" in gui and "pyqtgraph" in gui
    assert any(d.startswith("hypothesis") for d in project["optional-dependencies"]["dev"])


@pytest.fixture()
def without_qt(tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(NO_QT)
    env = {**os.environ, "PYTHONPATH": f"{site}{os.pathsep}{REPO}", "QT_QPA_PLATFORM": "offscreen"}
    return env


def _qrfield(env, cwd, *args):
    return subprocess.run(
        [sys.executable, "-m", "qrfield", *args],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=180,
    )


@pytest.mark.slow
def test_headless_run_and_solve_work_without_qt(without_qt, tmp_path):
    check = subprocess.run([sys.executable, "-c", "import PySide6"], env=without_qt, capture_output=True)
    assert check.returncode != 0  # the blocker works
    done = _qrfield(
        without_qt, tmp_path, "run", "--headless", "--source", "virtual", "--frames", "3", "--json-lines"
    )
    assert done.returncode == 0, done.stderr
    frames = [json.loads(line) for line in done.stdout.splitlines()]
    assert [f["status"] for f in frames] == ["SIM"] * 3  # the virtual bench: never OK
    assert abs(frames[0]["position_mm"][2] - frames[0]["truth"]["position_mm"][2]) < 5.0
    marker = _qrfield(without_qt, tmp_path, "marker", "--text", "x", "--side-mm", "50", "--out", "card.svg")
    assert marker.returncode == 0 and (tmp_path / "card.svg").is_file(), marker.stderr


@pytest.mark.slow
def test_gui_without_the_extra_names_it(without_qt, tmp_path):
    done = _qrfield(without_qt, tmp_path, "gui")
    assert done.returncode == 3
    assert "needs PySide6, which is not installed" in done.stderr and "qrfield[gui]" in done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_missing_qt_libraries_name_the_apt_package(monkeypatch):
    def no_egl(name):
        raise ImportError("libEGL.so.1: cannot open shared object file: No such file or directory")

    assert qt_problem(no_egl) == "Qt cannot load libEGL.so.1: sudo apt install libegl1"

    def no_xkb(name):
        raise ImportError("libxkbcommon.so.0: cannot open shared object file")

    assert qt_problem(no_xkb).endswith("sudo apt install libxkbcommon0")
    # X11: Qt 6.5+ aborts without libxcb-cursor0 when the window opens; said before that.
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("QT_QPA_PLATFORM", raising=False)
    problem = qt_problem(lambda name: None, lambda lib: lib == "libxcb-cursor.so.0")
    assert problem.endswith("sudo apt install libxcb-cursor0") and "libxcb-cursor.so.0" in problem
    assert qt_problem(lambda name: None, lambda lib: False) == ""


@pytest.mark.slow
def test_a_command_that_needs_the_app_names_the_extra(without_qt, tmp_path):
    done = _qrfield(without_qt, tmp_path, "benchmark", "pipeline", "--seconds", "0.1")
    assert done.returncode == 3 and "qrfield[gui]" in done.stderr and "Traceback" not in done.stderr
