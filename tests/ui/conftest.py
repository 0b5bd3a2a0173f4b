"""Qt tests run offscreen; the app's config directory is always a temporary one, a dialog the
test did not answer fails the test instead of waiting for a click that never comes, and a test
that leaves a thread running fails (pytest-qt closes the test's widgets first: the window's
closeEvent is the app's own shutdown path, MainWindow.shutdown)."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


import threading
import time
from pathlib import Path

import pytest

#: How long a thread that is ending (a cancelled timer, a job sending its last signal) may take
#: after the test's teardown before it counts as left running, s.
THREAD_GRACE_S = 5.0


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


def _left_running(before: set[threading.Thread]) -> list[threading.Thread]:
    """Python threads started during the test and still alive; a QThread that ran Python code is a
    _DummyThread, alive for ever in threading's view: QThreads are checked by ui.worker."""
    return [
        t
        for t in threading.enumerate()
        if t not in before and t.is_alive() and not isinstance(t, threading._DummyThread)
    ]


@pytest.fixture(autouse=True)
def no_thread_left_running():
    """After the test and its teardown (windows closed and shut down), no worker QThread and no
    thread the test started is still running."""
    from ui.worker import unjoined_workers, wait_for_workers

    before = set(threading.enumerate())
    yield
    workers = unjoined_workers()
    if workers:
        wait_for_workers()  # for the next tests, then fail this one
        pytest.fail(f"{len(workers)} frame-loop worker thread(s) still running after the test")
    deadline = time.monotonic() + THREAD_GRACE_S
    for thread in _left_running(before):
        thread.join(max(0.0, deadline - time.monotonic()))
    left = _left_running(before)
    assert not left, f"threads still running after the test: {sorted(t.name for t in left)}"
