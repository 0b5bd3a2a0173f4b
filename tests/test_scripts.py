"""run.sh and test.sh from another folder: the caller's relative paths stay the caller's."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parent.parent
VENV = Path(sys.prefix)


@pytest.fixture()
def ready_venv():
    """The venv running these tests, when run.sh's stamp says it is installed (no install here)."""
    stamp = VENV / ".qrfield-installed"
    if not stamp.is_file() or "gui,dev" not in stamp.read_text():
        pytest.skip(f"tests are not running in a venv made by test.sh ({VENV}); run.sh would install one")
    return {**os.environ, "QRFIELD_VENV": str(VENV)}


def test_run_sh_keeps_the_callers_folder(tmp_path, ready_venv):
    # Must show: from a folder outside the checkout, PATH/run.sh marker ... --out card.svg writes
    # ./card.svg, and PATH/run.sh solve ./view.png reads ./view.png.
    run_sh = os.path.relpath(REPO / "run.sh", tmp_path)
    done = subprocess.run(
        [run_sh, "marker", "--text", "x", "--side-mm", "50", "--out", "card.svg"],
        cwd=tmp_path, env=ready_venv, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "card.svg").is_file() and not (REPO / "card.svg").exists()
    render = [run_sh, "render", "--focal-px", "500", "--size", "640x480", "--side-mm", "50",
              "--pose", "-10,5,300,0,0,0", "--out", "view.png"]  # fmt: skip
    assert (
        subprocess.run(render, cwd=tmp_path, env=ready_venv, capture_output=True, timeout=300).returncode == 0
    )
    done = subprocess.run(
        [run_sh, "solve", "./view.png", "--focal-px", "500", "--side-mm", "50", "--method", "ippe", "--json"],
        cwd=tmp_path, env=ready_venv, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    (entry,) = json.loads(done.stdout)  # stdout is the command's alone (no install chatter)
    assert entry["image"] == "./view.png" and abs(entry["position_mm"][0] + 10.0) < 1.0


def test_test_sh_takes_the_callers_paths(tmp_path, ready_venv):
    target = os.path.relpath(REPO / "tests" / "test_files.py", tmp_path)
    done = subprocess.run(
        [str(REPO / "test.sh"), "--collect-only", "-q", f"{target}::test_a_byte_order_mark_is_accepted"],
        cwd=tmp_path, env=ready_venv, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert "test_files.py::test_a_byte_order_mark_is_accepted" in done.stdout
    assert "1 test collected" in done.stdout


SITE_ARM32 = """
import platform, struct
platform.machine = lambda: "armv7l"
_calcsize = struct.calcsize
struct.calcsize = lambda fmt: 4 if fmt == "P" else _calcsize(fmt)
"""


def test_on_32_bit_arm_run_sh_says_the_app_needs_64_bit_and_offers_the_os_packages(tmp_path):
    # The Python that runs qrfield decides (uname says aarch64 under 32-bit Raspberry Pi OS's
    # 64-bit kernel). Faked here; the base Python lacks OpenCV, so run.sh stops at the apt advice.
    base = Path(sys.base_prefix) / "bin" / "python3"
    probe = subprocess.run([str(base), "-c", "import cv2"], capture_output=True)
    if probe.returncode == 0:
        pytest.skip("the base Python has OpenCV: run.sh would go on to install")
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SITE_ARM32)
    env = {**os.environ, "PYTHON": str(base), "PYTHONPATH": str(site), "QRFIELD_VENV": str(tmp_path / "venv")}
    done = subprocess.run(
        [str(REPO / "run.sh"), "run", "--headless"], cwd=tmp_path, env=env, stdin=subprocess.DEVNULL,
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 1 and done.stdout == ""
    assert "the bench app needs 64-bit Raspberry Pi OS" in done.stderr
    assert (
        "sudo apt install python3-numpy python3-opencv python3-zxing-cpp python3-pyqtgraph python3-serial"
        in (done.stderr)
    )
    assert "missing now:" in done.stderr and "python3-opencv" in done.stderr
    assert not (tmp_path / "venv").exists()  # nothing compiled, nothing made
