"""Screenshots of every tab of the bench app at one screen size, on a real X server (Xvfb).

Run by scripts/screenshots.sh, which starts an Xvfb screen of exactly that size. The app runs on
the virtual bench with a throw-away config, sessions and data folder; a session with a few rows
(one of them a fail, one withdrawn) is logged through the Session tab's own methods, analysed,
and a small simulation study is run, so that each tab shows what an operator sees mid-session.

    python scripts/screenshots.py --size 800x480 --out assets/screenshots

Each picture is the whole X screen (ImageMagick ``import -window root``), so a window larger
than the screen, or a dialog, shows as it would on that display; without ImageMagick the window
grabs itself. Fails (exit 1) when the window does not fit the screen.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

#: (file stem, work tab title, Setup page title or "") in the order they are taken: every tab.
SHOTS = (
    ("session", "Session", ""),
    ("live-plots", "Live plots", ""),
    ("analysis", "Analysis", ""),
    ("simulation", "Simulation", ""),
    ("setup-source", "Setup", "Source"),
)
#: With --all (the smallest screen): the other Setup pages and the two dialogs as well.
MORE_SHOTS = (
    ("setup-detect-solve", "Setup", "Detect & solve"),
    ("setup-camera", "Setup", "Camera"),
    ("setup-virtual-bench", "Setup", "Virtual bench"),
    ("setup-serial", "Setup", "Serial"),
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", required=True, help="screen size WxH, e.g. 800x480")
    parser.add_argument("--out", default=str(REPO / "assets" / "screenshots"), help="folder of the PNGs")
    parser.add_argument(
        "--all",
        action="store_true",
        help="also every Setup page, the New session, calibration and Resume dialogs, and no source",
    )
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix="qrfield-screenshots-"))
    for name in ("QRFIELD_CONFIG_DIR", "QRFIELD_DATA_DIR", "QRFIELD_SESSIONS_DIR"):
        os.environ[name] = str(scratch / name.lower())
    os.environ.pop("QT_QPA_PLATFORM", None)
    try:
        return take(width, height, out, scratch, args.all)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def take(width: int, height: int, out: Path, scratch: Path, everything: bool) -> int:
    import pyqtgraph as pg
    from PySide6 import QtCore, QtWidgets

    app = QtWidgets.QApplication(sys.argv[:1])
    app.setApplicationName("qrfield")
    pg.setConfigOptions(imageAxisOrder="row-major", antialias=True)
    from qrfield.runconfig import ConfigStore
    from ui.main_window import MainWindow

    def wait(seconds: float, until: Callable[[], bool] | None = None) -> bool:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            app.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 50)
            if until is not None and until():
                return True
        return until is None

    window = MainWindow(
        ConfigStore(scratch / "config"),
        {"source": "virtual", "method": "both", "camera": "picam-v2@640x480", "side_mm": 50.0},
    )
    window.resize(width, height)
    window.show()
    wait(20.0, lambda: window.frames_shown >= 10)
    size = window.size()
    print(
        f"screenshots: {width}x{height}: window {size.width()}x{size.height()}, "
        f"minimum {window.minimumSizeHint().width()}x{window.minimumSizeHint().height()}"
    )
    fits = size.width() <= width and size.height() <= height
    log_demo_session(window, wait)
    run_demo_analysis(window, wait)
    run_demo_study(window, wait, scratch)
    for stem, tab, page in SHOTS + (MORE_SHOTS if everything else ()):
        show(window, tab, page)
        wait(1.5)
        save(window, out / f"{width}x{height}-{stem}.png")
    if everything:
        dialog = window.session_panel.show_new_dialog()
        wait(1.0)
        save(window, out / f"{width}x{height}-new-session.png")
        dialog.reject()
        shoot_calibration(window, wait, out / f"{width}x{height}-calibration")
        tab = window.simulation_tab
        show(window, "Simulation", "")
        for k, stem in ((0, "study"), (2, "heatmap")):
            tab.pages.setCurrentIndex(k)
            wait(1.0)
            save(window, out / f"{width}x{height}-simulation-{stem}.png")
        tab.pages.setCurrentIndex(1)
        resume = window.session_panel.show_resume_dialog()
        wait(1.0)
        save(window, out / f"{width}x{height}-resume.png")
        resume.reject()
        show(window, "Session", "")
        window.set_source(str(scratch / "camera-unplugged.avi"))  # a source that cannot open
        wait(10.0, window.banner_row.isVisible)
        wait(1.0)
        save(window, out / f"{width}x{height}-no-source.png")
    window.close()
    window.shutdown()
    if not fits:
        print(f"screenshots: FAIL: the window ({size.width()}x{size.height()}) does not fit {width}x{height}")
        return 1
    return 0


def shoot_calibration(window, wait, stem: Path) -> None:
    """The calibration dialog's three pages: Board (virtual chessboard on), Views after eight
    captured views, Result after Compute."""
    calibration = window.open_calibration()
    calibration.virtual_check.setChecked(True)
    wait(3.0)
    save(window, stem.with_name(stem.name + ".png"))
    for _ in range(8):
        wait(10.0, calibration.capture_button.isEnabled)
        calibration.capture_button.click()
    wait(1.0)
    save(window, stem.with_name(stem.name + "-views.png"))
    calibration.compute_button.click()
    wait(30.0, lambda: calibration.result is not None)
    wait(1.0)
    save(window, stem.with_name(stem.name + "-result.png"))
    calibration.close()


def log_demo_session(window, wait) -> None:
    """A session "demo" with four rows: three passes on the bench's poses, one fail (a typed z
    10 mm off), and the last pass withdrawn."""
    panel = window.session_panel
    panel.show_new_dialog()
    panel.row_settings.widgets["frames_per_row"].setValue(3)
    panel.name_edit.setText("beta-sweep")
    panel.operator_edit.setText("operator")
    panel.create_button.click()
    wait(10.0, lambda: panel.form.follow_box.isEnabled() and panel.log_button.isEnabled())
    bench = window.virtual_form.widgets
    for beta in (-20.0, 30.0):
        bench["beta_deg"].setValue(beta)

        def shown(b: float = beta) -> bool:
            return window.last is not None and abs(window.last.result.truth.angles_deg[1] - b) < 1e-6

        wait(10.0, shown)
        wait(1.0)
        log_one(panel, wait)
    panel.form.follow_box.setChecked(False)
    fields = panel.form.fields()
    panel.form.set_fields({"z": f"{float(fields['z']) + 10:g}"})
    log_one(panel, wait)
    panel.form.follow_box.setChecked(True)
    wait(1.0)
    log_one(panel, wait)
    panel.ask_confirm = lambda title, text: True
    panel.undo_row()
    panel.form.note.setText("card re-taped")


def log_one(panel, wait) -> None:
    logged = []
    panel.rowLogged.connect(logged.append)
    panel.log_row()
    wait(20.0, lambda: bool(logged))
    panel.rowLogged.disconnect(logged.append)


def run_demo_analysis(window, wait) -> None:
    tab = window.analysis_tab
    done = []
    tab.analysisDone.connect(done.append)
    tab.run()
    wait(90.0, lambda: bool(done))
    tab.pages.setCurrentIndex(2)  # the plots


def run_demo_study(window, wait, scratch: Path) -> None:
    tab = window.simulation_tab
    tab.output_dir.setText(str(scratch / "simulations"))
    finished = []
    tab.finished.connect(finished.append)
    tab.start()
    wait(120.0, lambda: bool(finished))


def show(window, tab: str, page: str) -> None:
    tabs = window.work_tabs
    tabs.setCurrentIndex(next(i for i in range(tabs.count()) if tabs.tabText(i) == tab))
    if page:
        setup = window.tabs
        titles = [setup.tabText(i).replace("&&", "&") for i in range(setup.count())]
        setup.setCurrentIndex(titles.index(page))


def save(window, path: Path) -> None:
    """The whole X screen (ImageMagick), else the window; then fewer colours to keep it small."""
    if shutil.which("import") and os.environ.get("DISPLAY"):
        subprocess.run(["import", "-window", "root", str(path)], check=True)
    else:
        window.grab().save(str(path))
    if shutil.which("convert"):
        subprocess.run(
            ["convert", str(path), "-strip", "+dither", "-colors", "128", f"PNG8:{path}"], check=True
        )
    print(f"screenshots: wrote {path} ({path.stat().st_size // 1024} KiB)")


if __name__ == "__main__":
    raise SystemExit(main())
