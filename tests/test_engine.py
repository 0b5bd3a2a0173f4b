"""The core's frame loop (qrfield.engine.FrameLoop), which ``qrfield run``, ``qrfield session log``
and the app's worker all run: sources that fail, retry, stall and end; sinks told when the source
is down; only a live camera's results marked not simulated."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from waiting import wait_until

from qrfield.camera import resolve_camera
from qrfield.engine import DONE, ENDED, FAILED, STOPPED, FrameLoop
from qrfield.runconfig import RunConfig
from qrfield.seams import LoopEventsBase
from qrfield.sources import EndOfStream, Frame, FrameSource, SourceError, VirtualBenchSettings

pytestmark = pytest.mark.timeout(60)
CAMERA = resolve_camera("picam-v2@640x480")


class FakeSource(FrameSource):
    """Blank frames; ``fail_at``: read raises SourceError there; ``end_at``: EndOfStream; ``stall_at``:
    read blocks (a camera that stops delivering) until ``release`` is set."""

    def __init__(
        self, name: str = "fake", live: bool = False, fail_at=None, end_at=None, stall_at=None
    ) -> None:
        super().__init__()
        self.name, self.live = name, live
        self.fail_at, self.end_at, self.stall_at = fail_at, end_at, stall_at
        self.release = threading.Event()

    def _open_impl(self) -> None:
        pass

    def _read_impl(self, index: int) -> Frame:
        if index == self.fail_at:
            raise SourceError("unplugged")
        if index == self.end_at:
            raise EndOfStream("no more frames")
        if index == self.stall_at:
            self.release.wait(30)
        time.sleep(0.005)
        return Frame(np.full((480, 640), 128, np.uint8), time.monotonic(), index)

    def _close_impl(self) -> None:
        pass


class Recorder(LoopEventsBase):
    """Events and sink calls, in order, with the simulated flag of each result."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []
        self.lock = threading.Lock()

    def _add(self, *item) -> None:
        with self.lock:
            self.calls.append(item)

    def opened(self, description, again):
        self._add("opened", again)

    def failed(self, message, ended):
        self._add("failed", message, ended)

    def note(self, message):
        self._add("note", message)

    def processed(self, frame, result, behind):
        self._add("processed", frame.index)

    def on_result(self, result, simulated):
        self._add("result", simulated)

    def on_source_down(self, reason):
        self._add("down", reason)

    def on_source_up(self):
        self._add("up")

    def kinds(self) -> list[str]:
        with self.lock:
            return [c[0] for c in self.calls]


#: The bound of a wait for the frame loop's thread, s.
WAIT_S = 20.0


def config(source: str = "fake", **kw) -> RunConfig:
    return RunConfig(source, CAMERA, 50.0, ("ippe",), **kw)


def opener_of(*sources_or_errors):
    """An opener returning the given sources in turn (an Exception is raised instead)."""
    queue = list(sources_or_errors)

    def opener(spec, **kwargs):
        item = queue.pop(0) if len(queue) > 1 else queue[0]
        if isinstance(item, Exception):
            raise item
        item.open()
        return item

    return opener


@pytest.mark.parametrize(("name", "live", "simulated"), [("usb:3", True, False), ("picamera2", True, False),
                                                         ("video", False, True), ("usb:3", False, True),
                                                         ("fakecam", True, True)])  # fmt: skip
def test_only_a_live_camera_is_not_simulated(name, live, simulated) -> None:
    rec = Recorder()
    loop = FrameLoop(
        config(), events=rec, sinks=[rec], opener=opener_of(FakeSource(name, live)), max_frames=3
    )
    assert loop.run() == DONE
    results = [c for c in rec.calls if c[0] == "result"]
    assert len(results) == 3 and all(c[1] is simulated for c in results)


def test_a_stand_in_camera_marked_simulated_is_never_live() -> None:
    source = FakeSource("picamera2", live=True)
    source.simulated = True  # a stand-in twin of a real camera (its `simulated` attribute)
    rec = Recorder()
    FrameLoop(config(), events=rec, sinks=[rec], opener=opener_of(source), max_frames=2).run()
    assert [c[1] for c in rec.calls if c[0] == "result"] == [True, True]


def test_a_source_that_cannot_open_is_retried_and_the_sinks_hear_it_is_down() -> None:
    rec = Recorder()
    good = FakeSource()
    opener = opener_of(SourceError("no camera"), SourceError("no camera"), good)
    loop = FrameLoop(config(retry_s=0.05), events=rec, sinks=[rec], opener=opener, max_frames=2)
    assert loop.run() == DONE
    kinds = rec.kinds()
    assert kinds[:4] == ["down", "failed", "failed", "opened"] and kinds.count("down") == 1
    failures = [c[1] for c in rec.calls if c[0] == "failed"]
    assert failures[0].startswith("cannot open source 'fake': no camera") and failures[1].startswith("still ")
    assert ("opened", True) in rec.calls  # reopened after a failure
    assert kinds.index("up") < kinds.index("result")  # up with the first frame, before its result


def test_without_retry_a_failed_source_ends_the_loop_or_waits_for_reopen() -> None:
    rec = Recorder()
    loop = FrameLoop(config(), events=rec, sinks=[rec], opener=opener_of(FakeSource(fail_at=2)))
    assert loop.run() == FAILED
    assert rec.calls[-2:] == [
        ("down", "source failed: unplugged"),
        ("failed", "source failed: unplugged", False),
    ]
    # Held (the app): the loop waits, closed, until reopen(); then it measures again.
    rec = Recorder()
    held = FrameLoop(config(), events=rec, sinks=[rec], opener=opener_of(FakeSource(fail_at=1), FakeSource()),
                     hold_when_down=True)  # fmt: skip
    thread = threading.Thread(target=held.run, daemon=True)
    thread.start()
    wait_until(lambda: "down" in rec.kinds(), WAIT_S)
    assert held.source is None and thread.is_alive()
    held.reopen()
    wait_until(lambda: rec.kinds().count("result") >= 3, WAIT_S)
    held.stop()
    thread.join(10)
    assert not thread.is_alive() and held.source is None


class OwnerEvents(LoopEventsBase):
    """The owner's down/up events (the app's worker turns them into signals), into ``rec``."""

    def __init__(self, rec: Recorder) -> None:
        self.rec = rec

    def source_down(self, reason):
        self.rec._add("owner down", reason)

    def source_up(self):
        self.rec._add("owner up")


def test_a_live_camera_that_stops_delivering_is_down_until_frames_come_again() -> None:
    source = FakeSource("usb:0", live=True, stall_at=3)
    rec = Recorder()
    loop = FrameLoop(config(), events=OwnerEvents(rec), sinks=[rec], opener=opener_of(source))
    loop.NO_FRAMES_S = 0.3
    thread = threading.Thread(target=loop.run, daemon=True)
    thread.start()
    wait_until(lambda: "owner down" in rec.kinds(), WAIT_S)
    source.release.set()
    wait_until(lambda: "owner up" in rec.kinds(), WAIT_S)
    loop.stop()
    thread.join(10)
    down = next(c for c in rec.calls if c[0] == "down")
    assert "no frame for" in down[1]
    # The sinks first (the serial link's NOSRC must not wait), then the owner, with the same reason.
    assert [k for k in rec.kinds() if k != "result"][:4] == ["down", "owner down", "up", "owner up"]
    assert next(c for c in rec.calls if c[0] == "owner down")[1] == down[1]


def test_the_end_of_a_file_ends_the_loop_and_a_stop_request_stops_it() -> None:
    rec = Recorder()
    assert FrameLoop(config(), events=rec, opener=opener_of(FakeSource(end_at=4))).run() == ENDED
    assert [c[1] for c in rec.calls if c[0] == "processed"] == [0, 1, 2, 3]  # every frame of a file
    loop = FrameLoop(config(), opener=opener_of(FakeSource()))
    loop.stop_from_signal()
    assert loop.run() == STOPPED


def test_new_bench_settings_apply_live_and_a_new_source_reopens() -> None:
    from qrfield.sources import open_source

    opened = []

    def opener(spec, **kwargs):
        opened.append(spec)
        return open_source(spec, **kwargs)

    rec = Recorder()
    bench = VirtualBenchSettings(fps=0.0, z_mm=300.0)
    loop = FrameLoop(config("virtual", virtual=bench), events=rec, opener=opener)
    truths = []
    loop.events = rec
    original = rec.processed

    def processed(frame, result, behind):
        truths.append(frame.truth.position_mm[2])
        original(frame, result, behind)
        if len(truths) == 2:
            loop.configure(config("virtual", virtual=VirtualBenchSettings(fps=0.0, z_mm=350.0)))
        if truths[-1] == 350.0 and len(truths) < 100:
            loop.stop()

    rec.processed = processed
    assert loop.run() == STOPPED
    assert opened == ["virtual"] and truths[0] == 300.0 and truths[-1] == 350.0  # one open, live change


def test_each_source_records_the_request_it_was_opened_for() -> None:
    """configure() and reopen() return request numbers; a source opened after request k has
    generation k, so an owner drops the results of the sources before its request strictly."""
    first, second = FakeSource("one"), FakeSource("two")
    seen: list[tuple[str, int]] = []  # (source, generation) of each processed frame

    class Events(LoopEventsBase):
        def processed(self, frame, result, behind):
            seen.append((loop.source.name, loop.source_generation))

    loop = FrameLoop(config(), events=Events(), opener=opener_of(first, second))
    thread = threading.Thread(target=loop.run, daemon=True)
    thread.start()
    wait_until(lambda: len(seen) >= 2, WAIT_S)
    same = loop.configure(config())  # nothing to reopen: the source and its generation stay
    wait_until(lambda: loop._pending is None and len(seen) >= 4, WAIT_S)
    request = loop.reopen()
    assert request > same > 0
    wait_until(lambda: any(name == "two" for name, _ in seen[-3:]), WAIT_S)
    loop.stop()
    thread.join(10)
    assert {g for name, g in seen if name == "one"} == {0}  # opened for the first configuration
    assert {g for name, g in seen if name == "two"} == {request}
    switch = next(i for i, (name, _) in enumerate(seen) if name == "two")
    assert all(name == "two" for name, _ in seen[switch:])  # no frame of the old source after it


def test_a_sink_or_events_object_missing_a_method_is_refused_when_the_loop_is_made() -> None:
    class HalfSink:
        def on_result(self, result, simulated):
            pass

    with pytest.raises(TypeError, match="on_source_down, on_source_up"):
        FrameLoop(config(), sinks=[HalfSink()], opener=opener_of(FakeSource()))

    class HalfEvents:
        def note(self, message):
            pass

    with pytest.raises(TypeError, match="opened, failed, processed, source_down, source_up"):
        FrameLoop(config(), events=HalfEvents(), opener=opener_of(FakeSource()))
