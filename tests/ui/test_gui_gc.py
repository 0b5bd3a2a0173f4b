"""Cyclic garbage is collected on the GUI thread while a window's threads run (ui/gui_gc.py): the
frame loop allocates all the time, so with Python's automatic collection it would run most
collections, and destroy the Qt objects in the garbage (pyqtgraph's menus, parentless QObjects)
on its own thread while the GUI thread uses Qt: the suite's hangs (issue 24)."""

from __future__ import annotations

import gc
import threading

import pytest
from PySide6 import QtCore

from ui import gui_gc

pytestmark = pytest.mark.gui
WAIT_MS = 15000


class Cycle:
    """A parentless QObject in a reference cycle: freed only by the cyclic collector, in the thread
    that runs it (``log`` gets that thread)."""

    def __init__(self, log: list[threading.Thread]) -> None:
        self.log = log
        self.me = self
        self.qobject = QtCore.QObject()

    def __del__(self) -> None:
        self.log.append(threading.current_thread())


def test_garbage_is_collected_on_the_gui_thread_while_frames_are_solved(make_window, qtbot) -> None:
    window = make_window({"source": "virtual", "method": "both"})
    qtbot.waitUntil(lambda: window.frames_shown >= 3, timeout=WAIT_MS)
    collected_by: list[threading.Thread] = []
    for _ in range(40):
        for _ in range(10):
            Cycle(collected_by)
        qtbot.wait(50)  # the frame loop solves meanwhile
    qtbot.waitUntil(lambda: len(collected_by) == 400, timeout=WAIT_MS)
    off_gui = [t.name for t in collected_by if t is not threading.main_thread()]
    assert not off_gui, (
        f"{len(off_gui)} of 400 garbage cycles with a QObject collected on {sorted(set(off_gui))}"
    )
    assert window.worker.frames_processed > 3  # the loop ran all along


def test_automatic_collection_is_back_once_the_last_window_is_shut_down(
    make_window, qtbot, monkeypatch
) -> None:
    # Alone, as in a fresh app: a window of an earlier test whose frame loop was left running
    # (tests/ui/test_app.py's stuck loop) keeps its hold for the rest of the process, by design.
    monkeypatch.setattr(gui_gc, "_holders", set())
    monkeypatch.setattr(gui_gc, "_state", {})
    was_enabled = gc.isenabled()
    gc.enable()
    try:
        first, second = make_window({"source": "virtual"}), make_window({"source": "virtual"})
        assert not gc.isenabled()  # the GUI thread collects
        first.shutdown()
        assert not gc.isenabled()  # one window still runs its threads
        second.shutdown()
        assert gc.isenabled()
    finally:
        if not was_enabled:
            gc.disable()  # as the earlier window's hold left it
