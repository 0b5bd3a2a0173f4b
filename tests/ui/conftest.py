"""Qt tests run offscreen; the app's config directory is always a temporary one."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


from pathlib import Path

import pytest


@pytest.fixture
def make_window(qtbot, tmp_path: Path):
    """Open main windows with their config in tmp_path; each is shut down after the test."""
    from qrfield.runconfig import ConfigStore
    from ui.main_window import MainWindow

    windows: list[MainWindow] = []

    def make(overrides: dict | None = None, **kwargs) -> MainWindow:
        window = MainWindow(ConfigStore(tmp_path / "config"), overrides, **kwargs)
        qtbot.addWidget(window)
        window.show()
        windows.append(window)
        return window

    yield make
    for window in windows:
        window.shutdown()
