"""The app's one way to run slow work off the GUI thread: :class:`BackgroundJob`.

A job runs one callable on a plain daemon thread and reports by Qt signal: ``finished(result)``
or ``failed(message)``, queued into the GUI thread (the job object lives there), so slots may
touch widgets. One run at a time per job; :meth:`BackgroundJob.join` waits for the run (the
window closing). The camera's frame loop is not such a job: it is the long-lived worker of
ui/worker.py on its own QThread.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any

from PySide6 import QtCore


class BackgroundJob(QtCore.QObject):
    """Runs ``work(*args)`` on a daemon thread named ``name``; see the module doc."""

    finished = QtCore.Signal(object)  # what work returned
    failed = QtCore.Signal(str)  # the message of the exception work raised

    def __init__(self, name: str, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.name = name
        self._thread: threading.Thread | None = None

    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self, work: Callable[..., Any], *args: Any) -> bool:
        """Start ``work(*args)``; False (nothing started) while a run is still going."""
        if self.busy:
            return False
        self._thread = threading.Thread(target=self._run, args=(work, args), name=self.name, daemon=True)
        self._thread.start()
        return True

    def join(self, timeout_s: float = 5.0) -> bool:
        """Wait up to ``timeout_s`` for the run; True when none is running any more."""
        if self._thread is not None:
            self._thread.join(timeout_s)
        return not self.busy

    def _run(self, work: Callable[..., Any], args: tuple[Any, ...]) -> None:
        try:
            result = work(*args)
        except Exception as exc:  # reported to the operator; the app keeps running
            self._emit(self.failed, str(exc) or type(exc).__name__)
            return
        self._emit(self.finished, result)

    @staticmethod
    def _emit(signal: Any, value: Any) -> None:
        with contextlib.suppress(RuntimeError):  # the owner was deleted meanwhile: nobody to tell
            signal.emit(value)
