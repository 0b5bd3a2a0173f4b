"""A one-slot mailbox where the newest item replaces an unread older one: :class:`Mailbox`.

The project's one "newest replaces older" hand-over between threads: the newest camera frame
(:class:`qrfield.sources.LatestFrameReader`), the newest pose waiting for the serial port
(:class:`qrfield.serial.link.SerialLink`), the newest result waiting for the app's redraw
(``ui/worker.py``) and the newest input waiting for a background job (``ui/background.py``).
Whoever reads never sees a queue build up behind a slow step: an item not taken before the next
one arrives is dropped and counted (:attr:`Mailbox.dropped`).

Thread-safe. By default a box has its own lock; an owner that must wait for the box and for other
state of its own at once (the serial link waits for a pose, an answer to write or a stop request)
passes its own :class:`threading.Condition` (over an RLock, the default, since the box takes it
again while the owner holds it): every change of the box then notifies that condition.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")

__all__ = ["Mailbox"]


class Mailbox(Generic[T]):
    """One slot: :meth:`put` replaces an unread item (counted in :attr:`dropped`), :meth:`take`
    empties it, :meth:`wait` waits for an item, :meth:`close` ends the box (see the module doc).

    Attributes:
        dropped: items replaced by a newer one before anyone took them.
        puts: items stored (taken, dropped or still waiting).
    """

    def __init__(self, condition: threading.Condition | None = None) -> None:
        self._cond = condition if condition is not None else threading.Condition()
        self._item: T | None = None
        self._full = False  # the item may itself be falsy (0, an empty tuple), never None's stand-in
        self._closed = False
        self.dropped = 0
        self.puts = 0

    # ---------------------------------------------------------------- producers
    def put(self, item: T) -> bool:
        """Store ``item``, replacing an unread one (counted in :attr:`dropped`); False (``item``
        discarded) once the box is closed."""
        with self._cond:
            if self._closed:
                return False
            if self._full:
                self.dropped += 1
            self._item, self._full = item, True
            self.puts += 1
            self._cond.notify_all()
            return True

    def put_if_empty(self, item: T) -> bool:
        """Store ``item`` only when no newer item is waiting (an item given back, e.g. a pose whose
        write failed: a newer pose wins); True when stored."""
        with self._cond:
            if self._closed or self._full:
                return False
            self._item, self._full = item, True
            self._cond.notify_all()
            return True

    def close(self) -> None:
        """No more items: :meth:`put` discards from now on; an item still waiting can be taken;
        every waiter wakes."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    # ---------------------------------------------------------------- consumers
    def take(self) -> T | None:
        """The waiting item (the box is then empty), or None when there is none; never blocks."""
        with self._cond:
            return self._take()

    def wait(self, timeout: float | None = None) -> T | None:
        """Wait up to ``timeout`` s (None: for ever) for an item and take it; None on timeout, or
        at once when the box is closed and empty."""
        with self._cond:
            if not self._wait_for(lambda: self._full or self._closed, timeout):
                return None
            return self._take()

    def wait_taken(self, timeout: float | None = None) -> bool:
        """Wait up to ``timeout`` s until the slot is empty (a producer that makes one item ahead
        only, like a file read frame by frame); True when empty, False on timeout or when closed
        with the item still waiting."""
        with self._cond:
            self._wait_for(lambda: not self._full or self._closed, timeout)
            return not self._full

    def clear(self) -> T | None:
        """Discard the waiting item without counting it as dropped (the consumer no longer wants
        it: a stream switched off, a replaced source); returns it."""
        with self._cond:
            return self._take()

    # ---------------------------------------------------------------- state
    @property
    def full(self) -> bool:
        """An item is waiting."""
        with self._cond:
            return self._full

    @property
    def closed(self) -> bool:
        with self._cond:
            return self._closed

    def _take(self) -> T | None:
        item, self._item = self._item, None
        was_full, self._full = self._full, False
        if was_full:
            self._cond.notify_all()  # a producer waiting in wait_taken may go on
        return item

    def _wait_for(self, ready: Callable[[], bool], timeout: float | None) -> bool:
        """Wait (the lock held) until ``ready()``; False when ``timeout`` s passed first."""
        return bool(self._cond.wait_for(ready, timeout))
