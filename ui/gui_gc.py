"""Cyclic garbage is collected on the GUI thread only, while a window's threads run.

Python's automatic collector runs in whichever thread happens to allocate when a threshold is
crossed: with the frame loop running, that is nearly always the worker. Garbage cycles often hold
Qt objects (pyqtgraph's menus and widget groups, parentless QObjects, wrappers of live widgets),
whose destructors would then run on the worker while the GUI thread delivers events, which Qt
forbids and which hung the UI tests (issue 24: the GUI thread waiting for the GIL at the entry of
an event filter, the worker inside a collection). So while any :func:`hold` is active, automatic
collection is off and pyqtgraph's :class:`~pyqtgraph.util.garbage_collector.GarbageCollector`
collects on a GUI-thread timer, with the thresholds that were set; the last :func:`release`
collects once more and gives automatic collection back (a process that closed its windows, such
as the test suite, runs on as before).
"""

from __future__ import annotations

import gc

from pyqtgraph.util.garbage_collector import GarbageCollector

#: How often the GUI thread looks at the collector's counts, s (pyqtgraph's default).
COLLECT_EVERY_S = 1.0

_holders: set[int] = set()
_state: dict[str, object] = {}


def hold(owner: object) -> None:
    """From now until ``release(owner)``, collect cyclic garbage on the GUI thread only (call it on
    the GUI thread, before ``owner`` starts threads)."""
    if not _holders:
        _state["was_enabled"] = gc.isenabled()
        _state["collector"] = GarbageCollector(interval=COLLECT_EVERY_S)  # disables automatic collection
    _holders.add(id(owner))


def release(owner: object) -> None:
    """``owner``'s threads have ended; the last owner gives automatic collection back. Idempotent."""
    if id(owner) not in _holders:
        return
    _holders.discard(id(owner))
    if _holders:
        return
    collector = _state.pop("collector")
    collector.timer.stop()  # type: ignore[attr-defined]
    gc.collect()  # here, on the GUI thread, what accumulated since the last tick
    if _state.pop("was_enabled", True):
        gc.enable()


def holding() -> bool:
    """Automatic collection is held off by at least one owner."""
    return bool(_holders)
