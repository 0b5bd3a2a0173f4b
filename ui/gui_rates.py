"""The app's own frame rates (worker, window) offscreen, for ``qrfield benchmark pipeline``.

The benchmark lives in the Qt-free core; this is the part of it that needs Qt.
"""

from __future__ import annotations

import tempfile
import time

from PySide6 import QtCore, QtWidgets

from qrfield.runconfig import ConfigStore
from qrfield.sources import VirtualBenchSettings
from ui.main_window import MainWindow


def gui_rates(camera: str, method: str, seconds: float) -> tuple[float, float]:
    """(frames processed per s by the worker, frames drawn per s by the window), offscreen."""
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication([])
    with tempfile.TemporaryDirectory() as config_dir:  # never touch the user's settings
        store = ConfigStore(config_dir)
        store.set_group("virtual", VirtualBenchSettings(fps=0.0))
        window = MainWindow(store, {"source": "virtual", "camera": camera, "side_mm": 50.0, "method": method})
        window.show()
        loop = QtCore.QEventLoop()
        # Start counting once frames flow (the first frame pays for opening and warming up).
        deadline = time.monotonic() + 20.0
        while window.frames_shown == 0 and time.monotonic() < deadline:
            app.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 50)
        processed0, shown0, t0 = window.worker.frames_processed, window.frames_shown, time.perf_counter()
        QtCore.QTimer.singleShot(int(seconds * 1000), loop.quit)
        loop.exec()
        elapsed = time.perf_counter() - t0
        processed, shown = window.worker.frames_processed - processed0, window.frames_shown - shown0
        window.shutdown()
        window.deleteLater()
    return processed / elapsed, shown / elapsed
