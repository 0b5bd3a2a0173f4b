"""The app's one background helper (ui/background.py): results and failures arrive as signals on the
GUI thread, one run at a time, "newest replaces older" inputs (the calibration's board finder),
progress and cancellation (the simulation study), and a slot may start the next run at once. The
runs are sequenced by events, so the outcomes do not depend on the machine's load."""

from __future__ import annotations

import threading

import pytest
from PySide6 import QtCore

from ui.background import BackgroundJob, JobControl

pytestmark = pytest.mark.gui
WAIT_MS = 10000


def test_a_result_arrives_on_the_gui_thread_and_a_second_start_is_refused(qtbot) -> None:
    job = BackgroundJob("test-job")
    release = threading.Event()
    ran_on: list[threading.Thread] = []

    def work(x: int) -> int:
        ran_on.append(threading.current_thread())
        release.wait(WAIT_MS / 1000)
        return 2 * x

    got: list[tuple[int, bool]] = []
    job.finished.connect(lambda value: got.append((value, QtCore.QThread.currentThread() is app_thread())))
    assert job.start(work, 21)
    assert job.busy and not job.start(work, 1)  # one run at a time: nothing started
    with qtbot.waitSignal(job.finished, timeout=WAIT_MS):
        release.set()
    assert got == [(42, True)]  # the slot ran on the GUI thread
    assert ran_on[0] is not threading.main_thread() and ran_on[0].name == "test-job"
    assert job.join(1.0) and not job.busy and job.runs == 1


def app_thread() -> QtCore.QThread:
    from PySide6 import QtWidgets

    return QtWidgets.QApplication.instance().thread()


def test_an_exception_becomes_the_failed_signal_and_the_job_can_run_again(qtbot) -> None:
    job = BackgroundJob("failing")

    def broken() -> None:
        raise ValueError("bad board size")

    with qtbot.waitSignal(job.failed, timeout=WAIT_MS) as blocker:
        assert job.start(broken)
    assert blocker.args == ["bad board size"]
    with qtbot.waitSignal(job.failed, timeout=WAIT_MS) as blocker:
        assert job.start(lambda: {}["missing"])
    assert blocker.args == ["'missing'"]
    with qtbot.waitSignal(job.finished, timeout=WAIT_MS) as blocker:
        assert job.start(lambda: "fine")
    assert blocker.args == ["fine"]


def test_submitted_inputs_the_newest_replaces_a_waiting_one(qtbot) -> None:
    job = BackgroundJob("finder")
    release = threading.Event()
    ran: list[str] = []

    def find(frame: str) -> str:
        if frame == "frame 1":
            release.wait(WAIT_MS / 1000)  # busy with the first frame while the others come
        ran.append(frame)
        return frame

    shown: list[str] = []
    job.finished.connect(shown.append)
    job.submit(find, "frame 1")
    for k in (2, 3, 4):
        job.submit(find, f"frame {k}")  # each replaces the one waiting before it
    assert job.busy and job.dropped == 2
    release.set()
    qtbot.waitUntil(lambda: shown == ["frame 1", "frame 4"], timeout=WAIT_MS)
    assert ran == ["frame 1", "frame 4"] and job.runs == 2
    assert job.join(1.0)
    job.submit(find, "frame 5")  # idle again: runs at once
    qtbot.waitUntil(lambda: shown[-1:] == ["frame 5"], timeout=WAIT_MS)
    assert job.dropped == 2


def test_a_controlled_run_reports_progress_and_stops_when_cancelled(qtbot) -> None:
    job = BackgroundJob("study")
    started = threading.Event()

    def study(control: JobControl, steps: int) -> str:
        for k in range(steps):
            control.progress(k)
            if k == 2:
                started.set()
            if control.stop.wait(0.01 if k < 2 else WAIT_MS / 1000):
                return f"stopped after {k + 1} steps"
        return "all done"

    progress: list[int] = []
    job.progressed.connect(progress.append)
    assert job.start_controlled(study, 1000)
    assert started.wait(WAIT_MS / 1000)
    with qtbot.waitSignal(job.finished, timeout=WAIT_MS) as blocker:
        job.cancel()
    assert blocker.args == ["stopped after 3 steps"]
    qtbot.waitUntil(lambda: progress == [0, 1, 2], timeout=WAIT_MS)
    # The next run gets a fresh control: not stopped by the last cancel.
    with qtbot.waitSignal(job.finished, timeout=WAIT_MS) as blocker:
        assert job.start_controlled(lambda control: control.cancelled)
    assert blocker.args == [False]


def test_a_slot_may_start_the_next_run_at_once(qtbot) -> None:
    """When a run's signal arrives the job is no longer busy (the simulation tab starts the
    superseding study from the slot of the superseded one)."""
    job = BackgroundJob("chain")
    results: list[int] = []

    def next_run(value: int) -> None:
        results.append(value)
        if value < 3:
            assert job.start(lambda: value + 1), "busy in the slot of the run that just ended"

    job.finished.connect(next_run)
    assert job.start(lambda: 1)
    qtbot.waitUntil(lambda: results == [1, 2, 3], timeout=WAIT_MS)
    assert job.join(1.0)
