"""SIGTERM stops a command as Ctrl-C does: the handler that raises KeyboardInterrupt, set for the
length of a command and put back after (``serial-demo``, ``serial-monitor``, ``session log``)."""

from __future__ import annotations

import signal
from typing import Any


def interrupt(signum: int, frame: Any) -> None:
    """A signal handler: raise KeyboardInterrupt, so that the command's Ctrl-C path ends it cleanly."""
    raise KeyboardInterrupt


def sigterm_as_interrupt() -> Any:
    """Make SIGTERM raise KeyboardInterrupt; the handler it replaces (for :func:`restore_sigterm`),
    or None off the main thread (a test, an embedding program), where no handler can be set and
    only Ctrl-C stops the command."""
    try:
        return signal.signal(signal.SIGTERM, interrupt)
    except ValueError:  # not the main thread
        return None


def restore_sigterm(previous: Any) -> None:
    """Put back the SIGTERM handler :func:`sigterm_as_interrupt` replaced (nothing for None)."""
    if previous is not None:
        signal.signal(signal.SIGTERM, previous)
