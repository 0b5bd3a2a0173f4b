"""The app's one way to run slow work off the GUI thread: :class:`BackgroundJob`.

A job runs a callable on a plain daemon thread and reports by Qt signal, queued into the GUI
thread (the job object lives there), so slots may touch widgets: ``finished(result)``,
``failed(message)``, and ``progressed(value)`` for work that reports progress. Three ways to
start it:

- :meth:`BackgroundJob.start` ``(work, *args)``: one run at a time (False while one is going):
  the analysis, the calibration, listing the cameras, closing a serial link;
- :meth:`BackgroundJob.start_controlled` ``(work, *args)``: the same, ``work`` getting a
  :class:`JobControl` first (its ``stop`` event, set by :meth:`BackgroundJob.cancel`, and
  ``progress(value)``): the simulation study;
- :meth:`BackgroundJob.submit` ``(work, *args)``: newest replaces older: run now, or after the run
  in progress, an input not yet started being replaced by a newer one (counted in
  :attr:`BackgroundJob.dropped`; a :class:`qrfield.mailbox.Mailbox`): the calibration dialog's
  board finder, fed with every frame the window draws.

When a run's signal reaches the GUI thread, :attr:`BackgroundJob.busy` already says whether
another run follows, so a slot may start the next run at once. :meth:`BackgroundJob.join` waits
for the runs (the window closing). The camera's frame loop is not such a job: it is the
long-lived worker of ui/worker.py on its own QThread.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any

from PySide6 import QtCore

from qrfield.mailbox import Mailbox

#: One run: the callable, its arguments, and whether it gets a JobControl first.
Task = tuple[Callable[..., Any], tuple[Any, ...], bool]


class JobControl:
    """Handed to a run started by :meth:`BackgroundJob.start_controlled` (any thread may use it).

    ``stop``: a threading.Event set by :meth:`BackgroundJob.cancel` (work that can stop early
    looks at it, e.g. ``run_study(..., stop=control.stop)``); :meth:`progress` emits the job's
    ``progressed`` signal.
    """

    def __init__(self, job: BackgroundJob) -> None:
        self.stop = threading.Event()
        self._job = job

    @property
    def cancelled(self) -> bool:
        return self.stop.is_set()

    def progress(self, value: Any) -> None:
        self._job._emit(self._job.progressed, value)


class BackgroundJob(QtCore.QObject):
    """Runs work on a daemon thread named ``name``; see the module doc."""

    finished = QtCore.Signal(object)  # what work returned
    failed = QtCore.Signal(str)  # the message of the exception work raised
    progressed = QtCore.Signal(object)  # what work handed to JobControl.progress

    def __init__(self, name: str, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.name = name
        self._cond = threading.Condition()
        self._waiting: Mailbox[Task] = Mailbox(self._cond)  # submit()'s input not yet started
        self._running = False  # a thread is running runs (guarded by _cond)
        self._control: JobControl | None = None  # the current controlled run's
        self._thread: threading.Thread | None = None
        self.runs = 0  # runs ended (finished or failed)

    @property
    def busy(self) -> bool:
        """A run is going or waiting."""
        with self._cond:
            return self._running

    @property
    def dropped(self) -> int:
        """Inputs of :meth:`submit` replaced by a newer one before they ran."""
        return self._waiting.dropped

    def start(self, work: Callable[..., Any], *args: Any) -> bool:
        """Start ``work(*args)``; False (nothing started) while a run is still going."""
        return self._start((work, args, False))

    def start_controlled(self, work: Callable[..., Any], *args: Any) -> bool:
        """Start ``work(control, *args)`` with a new :class:`JobControl`; False while busy."""
        return self._start((work, args, True))

    def submit(self, work: Callable[..., Any], *args: Any) -> None:
        """Run ``work(*args)`` now, or after the run in progress; an input still waiting is
        replaced (newest replaces older, counted in :attr:`dropped`)."""
        with self._cond:
            if self._running:
                self._waiting.put((work, args, False))
                return
            self._launch((work, args, False))

    def cancel(self) -> None:
        """Drop the input waiting, and ask the run in progress to stop (its JobControl.stop; work
        that does not look at it runs to its end)."""
        with self._cond:
            self._waiting.clear()
            if self._control is not None:
                self._control.stop.set()

    def join(self, timeout_s: float = 5.0) -> bool:
        """Wait up to ``timeout_s`` for the runs; True when none is running any more."""
        with self._cond:
            self._cond.wait_for(lambda: not self._running, timeout_s)
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(max(0.0, timeout_s))  # the last run's signal is on its way too
        return not self.busy

    # ---------------------------------------------------------------- the job's thread
    def _start(self, task: Task) -> bool:
        with self._cond:
            if self._running:
                return False
            self._launch(task)
            return True

    def _launch(self, task: Task) -> None:
        """Start a thread for ``task`` (and what is submitted meanwhile); ``_cond`` is held."""
        self._running = True
        self._thread = threading.Thread(target=self._drain, args=(task,), name=self.name, daemon=True)
        self._thread.start()

    def _drain(self, task: Task | None) -> None:
        while task is not None:
            work, args, controlled = task
            control = JobControl(self) if controlled else None
            with self._cond:
                self._control = control
            signal, value = self._call(work, (control, *args) if control is not None else args)
            with self._cond:
                self._control = None
                self.runs += 1
                task = self._waiting.take()
                if task is None:
                    self._running = False  # before the signal: its slot may start the next run
                    self._cond.notify_all()
            self._emit(signal, value)

    def _call(self, work: Callable[..., Any], args: tuple[Any, ...]) -> tuple[Any, Any]:
        try:
            return self.finished, work(*args)
        except Exception as exc:  # reported to the operator; the app keeps running
            return self.failed, str(exc) or type(exc).__name__

    @staticmethod
    def _emit(signal: Any, value: Any) -> None:
        with contextlib.suppress(RuntimeError):  # the owner was deleted meanwhile: nobody to tell
            signal.emit(value)
