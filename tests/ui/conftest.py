"""Qt tests run offscreen; the app's config directory is always a temporary one, and a dialog the
test did not answer fails the test instead of waiting for a click that never comes."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def no_unanswered_dialogs(monkeypatch, tmp_path: Path):
    """The Session tab's questions (and the Analysis tab's browser) raise unless a test answers
    them (monkeypatch the method); the user's config folder (calibrations) is a temporary one."""
    from ui.analysis_tab import AnalysisTab
    from ui.sessions_panel import SessionPanel

    def unanswered_method(name: str):
        def unanswered(self, *args, **kwargs):
            raise AssertionError(f"the test did not answer {name}{args}")

        return unanswered

    for name in (
        "ask_confirm",
        "ask_pending_choice",
        "ask_combo_choice",
        "ask_save_path",
        "ask_export_path",
        "ask_plan_path",
    ):
        monkeypatch.setattr(SessionPanel, name, unanswered_method(name))
    monkeypatch.setattr(AnalysisTab, "open_url", unanswered_method("open_url"))  # never a real browser
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path / "user-config"))
    monkeypatch.setenv("QRFIELD_DATA_DIR", str(tmp_path / "user-data"))


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
