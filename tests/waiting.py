"""Waiting in the tests that run threads: poll a condition with a generous bound (a margin, not a
timing test: the machine may be loaded)."""

from __future__ import annotations

import time
from collections.abc import Callable


def wait_until(predicate: Callable[[], object], timeout: float = 5.0, what: str = "condition") -> None:
    """Return once ``predicate()`` is true (polled every 10 ms); AssertionError naming ``what`` when
    ``timeout`` seconds pass first."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)
