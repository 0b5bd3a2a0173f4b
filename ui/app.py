"""Bench app entry point (``qrfield`` or ``qrfield gui``): builds the QApplication and the window."""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
from pathlib import Path
from typing import Any, NoReturn


def close_on_signals(
    window: Any, signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)
) -> dict[int, Any]:
    """Ctrl+C or SIGTERM closes ``window`` as its close button does (settings saved, worker joined,
    pending session rows offered), instead of a KeyboardInterrupt traceback inside a Qt slot or
    an exit that saves nothing. Returns the previous handlers (to restore them)."""
    from PySide6 import QtCore

    def handler(_signum: int, _frame: Any) -> None:
        # Python runs this between two bytecodes, perhaps inside a slot: close from the event loop.
        QtCore.QTimer.singleShot(0, window.close)

    return {number: signal.signal(number, handler) for number in signals}


def main(args: argparse.Namespace) -> int:
    import pyqtgraph as pg
    from PySide6 import QtCore, QtWidgets

    from qrfield.runconfig import ConfigStore, RunSettings
    from qrfield.settings import SettingError, validated
    from ui.main_window import MainWindow

    overrides = {
        "source": getattr(args, "source", None),
        "camera": getattr(args, "camera", None),
        "side_mm": getattr(args, "side_mm", None),
        "method": getattr(args, "method", None),
    }
    try:  # e.g. --side-mm -5: say so, rather than open a window that measures nothing
        validated(dataclasses.replace(RunSettings(), **{k: v for k, v in overrides.items() if v is not None}))
    except SettingError as exc:
        print(f"qrfield gui: {exc}", file=sys.stderr)
        return 2
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    app.setApplicationName("qrfield")
    pg.setConfigOptions(imageAxisOrder="row-major", antialias=True)
    store = ConfigStore(getattr(args, "config_dir", None))
    window = MainWindow(store, overrides)
    window.show()
    close_on_signals(window)
    quit_after = getattr(args, "quit_after", None)
    screenshot = getattr(args, "screenshot", None)
    if quit_after:

        def finish() -> None:
            if screenshot:
                path = Path(screenshot)
                path.parent.mkdir(parents=True, exist_ok=True)
                if window.grab().save(str(path)):
                    print(
                        f"qrfield: screenshot {path} ({window.width()}x{window.height()}, "
                        f"platform {app.platformName()}, {window.frames_shown} frames shown)",
                        file=sys.stderr,
                    )
                else:
                    print(f"qrfield: could not write the screenshot {path}", file=sys.stderr)
            window.close()

        QtCore.QTimer.singleShot(int(quit_after * 1000), finish)
    code = app.exec()
    window.shutdown()
    return int(code) if worker_threads_ended() else leave_now(int(code))


def worker_threads_ended(timeout_ms: int = 5000) -> bool:
    """Wait up to ``timeout_ms`` more for frame loops still ending after the window closed."""
    from ui.worker import wait_for_workers

    return wait_for_workers(timeout_ms)


def leave_now(code: int) -> NoReturn:
    """A frame loop still runs (a camera driver stuck in a read or close): settings and rows are
    saved by now, and Qt would abort on destroying a running QThread, so exit at once."""
    import os

    print("qrfield: the camera's frame loop did not end; exiting without waiting for it", file=sys.stderr)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code or 1)
