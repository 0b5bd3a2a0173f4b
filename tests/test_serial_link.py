"""The serial link over its simulated twins (loop://, a pty with a reader in another process) and fakes.

Every line on the wire is checked with tests/serial_truth.py, a parser that shares no code with
the link. Nothing here measures speed: the pacing (newest pose first, answers first, one line on
the wire at a time) is checked on the :class:`Outbox` with a fake clock; waits are bounded polls.
"""

from __future__ import annotations

import contextlib
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from serial_truth import parse_frame_line, split_lines
from waiting import wait_until

from qrfield.serial.codec import ControllerCommand, FrameError, encode_command, encode_ok, wire_pose
from qrfield.serial.link import (
    CLOSED,
    CONNECTED,
    DISCONNECTED,
    NOSRC_INTERVAL_S,
    PACE_MARGIN,
    Outbox,
    PoseItem,
    SerialLink,
    SerialLinkSettings,
    line_time_s,
    publish_result,
)
from qrfield.serial.port import LOOP_URL, list_ports, open_pyserial

pytestmark = pytest.mark.timeout(30)

READER = r"""
import os, sys
fd = int(sys.argv[1])
out = sys.stdout.buffer
while True:
    try:
        data = os.read(fd, 4096)
    except OSError:
        break
    if not data:
        break
    out.write(data)
    out.flush()
"""


class PtyTwin:
    """A pty pair whose slave is reached through a symlink we control; the master is read by a
    separate Python process that copies raw bytes to its stdout (collected by a thread here)."""

    def __init__(self, link_path: Path) -> None:
        self.path = link_path
        self.data = bytearray()
        self._lock = threading.Lock()
        self.master, self.slave = os.openpty()  # keep the slave open so the master never reads EIO early
        tmp = link_path.with_suffix(".new")
        os.symlink(os.ttyname(self.slave), tmp)
        os.replace(tmp, link_path)  # atomically repoint the path the link opens
        self.proc = subprocess.Popen(
            [sys.executable, "-c", READER, str(self.master)], pass_fds=(self.master,), stdout=subprocess.PIPE
        )
        self._thread = threading.Thread(target=self._collect, daemon=True)
        self._thread.start()

    def _collect(self) -> None:
        assert self.proc.stdout is not None
        while chunk := self.proc.stdout.read1(4096):
            with self._lock:
                self.data += chunk

    def received(self) -> bytes:
        with self._lock:
            return bytes(self.data)

    def vanish(self) -> None:
        """Unplug: the reader process ends and every master fd is closed."""
        self.proc.kill()
        self.proc.wait(5)
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._thread.join(5)


class LoopTap:
    """pyserial's loop:// port, whose bytes read back by the link are also kept raw for the test."""

    def __init__(self) -> None:
        self.data = bytearray()
        self._lock = threading.Lock()

    def opener(self, settings):
        port = open_pyserial(settings)
        tap = self

        class Tapped:
            def write(self, data):
                return port.write(data)

            def read(self, size=1):
                data = port.read(size)
                with tap._lock:
                    tap.data += data
                return data

            def close(self):
                port.close()

        return Tapped()

    def received(self) -> bytes:
        with self._lock:
            return bytes(self.data)


@pytest.fixture(params=["loop", "pty"])
def twin(request, tmp_path):
    """(settings kwargs, link kwargs, received() -> raw bytes) for each simulated serial port."""
    if request.param == "loop":
        tap = LoopTap()
        yield {"port": LOOP_URL}, {"opener": tap.opener}, tap.received
    else:
        pty = PtyTwin(tmp_path / "ttyQRF")
        yield {"port": str(pty.path)}, {}, pty.received
        pty.vanish()


def frames_of(received) -> list[dict]:
    return [parse_frame_line(line) for line in split_lines(received())]


def poses(n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        position = rng.uniform([-300, -300, 100], [300, 300, 2000])
        angles = np.array([rng.uniform(-180, 180), rng.uniform(-90, 90), rng.uniform(-180, 180)])
        out.append((position, angles))
    return out


def test_contract_frames_arrive_in_order_with_values_as_sent(twin):
    port_kwargs, link_kwargs, received = twin
    settings = SerialLinkSettings(**port_kwargs, max_rate_hz=500, stale_after_s=0)
    sent = {}
    with SerialLink(settings, **link_kwargs) as link:
        assert link.wait_for_state(CONNECTED, 5), link.status()
        for i, (position, angles) in enumerate(poses(40, seed=3)):
            t_ms = 1000 + 7 * i
            sent[t_ms] = (position, angles)
            assert link.publish(t_ms, position, angles, "OK")
            time.sleep(0.004)
        link.publish(2000, None, None, "NOQR")
        wait_until(lambda: any(f["t_ms"] == 2000 for f in frames_of(received)), what="the last frame")
        wait_until(lambda: link.status().frames_sent == len(frames_of(received)), what="the count")
        status = link.status()
    frames = frames_of(received)
    if frames[-1]["status"] == "NOSRC":  # the closing line (loop:// is not read after close)
        frames = frames[:-1]
    assert [f["seq"] for f in frames] == list(range(len(frames)))  # in order, none lost on the line
    assert [f["t_ms"] for f in frames] == sorted(f["t_ms"] for f in frames)
    assert frames[-1]["status"] == "NOQR" and frames[-1]["pose"] is None
    for f in frames[:-1]:
        position, angles = sent[f["t_ms"]]
        assert f["status"] == "OK"
        assert np.all(np.abs(np.array(f["pose"][:3]) - position) <= 0.05 + 1e-9)  # mm, 1 decimal
        assert np.all(np.abs(np.array(f["pose"][3:]) - angles) <= 0.005 + 1e-9)  # degrees, 2 decimals
    # Every published pose is accounted for: written, or superseded by a newer one.
    assert status.frames_sent == len(frames) and status.frames_sent + status.frames_dropped == 41
    assert status.errors == 0 and link.status().state == CLOSED


def test_seq_wraps_after_65535(twin):
    port_kwargs, link_kwargs, received = twin
    settings = SerialLinkSettings(**port_kwargs, max_rate_hz=1000, stale_after_s=0)
    with SerialLink(settings, first_seq=65534, **link_kwargs) as link:
        assert link.wait_for_state(CONNECTED, 5)
        for i in range(3):
            link.publish(i, None, None, "NOQR")
            wait_until(lambda i=i: len(frames_of(received)) == i + 1, what=f"frame {i}")
    assert [f["seq"] for f in frames_of(received)][:3] == [65534, 65535, 0]  # then the closing NOSRC


def test_stale_goes_out_with_empty_fields_and_the_age_of_the_last_frame(twin):
    port_kwargs, link_kwargs, received = twin
    settings = SerialLinkSettings(**port_kwargs, max_rate_hz=100, stale_after_s=0.05)
    with SerialLink(settings, **link_kwargs) as link:
        assert link.wait_for_state(CONNECTED, 5)
        link.publish(77, (10.0, -20.0, 300.0), (1.0, 2.0, 3.0), "OK")
        wait_until(lambda: len([f for f in frames_of(received) if f["t_ms"] >= 77]) >= 3, what="two STALE")
    frames = [f for f in frames_of(received) if f["t_ms"] >= 77]
    first, stale1, stale2 = frames[:3]
    assert first["status"] == "OK" and first["pose"] == [10, -20, 300, 1, 2, 3]
    assert stale1["status"] == stale2["status"] == "STALE" and stale1["pose"] is None
    # t_ms: the time the line was made on the stream's clock; age_ms: since the last capture.
    assert 77 + 50 <= stale1["t_ms"] <= stale2["t_ms"] and stale1["age_ms"] >= 50
    assert abs((stale2["age_ms"] - stale1["age_ms"]) - (stale2["t_ms"] - stale1["t_ms"])) <= 1  # ms rounding
    assert [first["seq"], stale1["seq"], stale2["seq"]] == [first["seq"] + k for k in range(3)]


def test_pty_vanishes_mid_stream_frame_loop_goes_on_and_stream_resumes_at_same_path(tmp_path):
    path = tmp_path / "ttyQRF"
    first = PtyTwin(path)
    states = []
    settings = SerialLinkSettings(port=str(path), max_rate_hz=200, reconnect_interval_s=0.05, stale_after_s=0)
    link = SerialLink(settings, on_status=lambda s: states.append(s.state)).start()
    try:
        assert link.wait_for_state(CONNECTED, 5)
        t = 0
        while len(frames_of(first.received)) < 5:
            link.publish(t, (1.0, 2.0, 300.0 + t), (0, 0, 0))
            t += 1
            time.sleep(0.005)
        first.vanish()  # the USB adapter is pulled
        # The frame loop keeps going: every publish returns at once while the port is gone.
        while link.status().state != DISCONNECTED:
            assert link.publish(t, (1.0, 2.0, 300.0 + t), (0, 0, 0))
            t += 1
            time.sleep(0.005)
            assert t < 2000, "the link never noticed the port vanished"
        for _ in range(20):
            assert link.publish(t, (1.0, 2.0, 300.0 + t), (0, 0, 0))
            t += 1
        assert link.status().state == DISCONNECTED and "ttyQRF" in link.status().last_error
        second = PtyTwin(path)  # a new pty (another /dev/pts number) behind the same path
        try:
            assert link.wait_for_state(CONNECTED, 5), link.status()
            resumed_from = t
            while not any(f["t_ms"] >= resumed_from for f in frames_of(second.received)):
                link.publish(t, (1.0, 2.0, 300.0 + t), (0, 0, 0))
                t += 1
                time.sleep(0.005)
                assert t < resumed_from + 2000, "streaming did not resume"
            frames = frames_of(second.received)
            assert all(f["pose"][2] == pytest.approx(300.0 + f["t_ms"]) for f in frames)
            seqs = [f["seq"] for f in frames]
            assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
            assert link.status().reconnects == 1
        finally:
            link.close()
            second.vanish()
    finally:
        link.close()
    changes = [s for i, s in enumerate(states) if i == 0 or s != states[i - 1]]  # errors notify too
    assert changes[:3] == [CONNECTED, DISCONNECTED, CONNECTED] and changes[-1] == CLOSED


class SlowPort:
    """A port whose write takes a while (a slow line); records what was written."""

    def __init__(self, write_s: float) -> None:
        self.write_s = write_s
        self.written: list[bytes] = []
        self.times: list[float] = []
        self.writing = threading.Event()
        self.release = threading.Event()

    def write(self, data: bytes) -> int:
        self.writing.set()
        if self.write_s < 0:
            self.release.wait(10)  # blocked until the test releases it
        else:
            time.sleep(self.write_s)
        self.written.append(bytes(data))
        self.times.append(time.monotonic())
        return len(data)

    def read(self, size: int = 1) -> bytes:
        return b""

    def close(self) -> None:
        self.release.set()


def test_newest_pose_wins_under_a_slow_port_and_the_queue_stays_bounded():
    port = SlowPort(write_s=-1)
    settings = SerialLinkSettings(port="fake", max_rate_hz=1000, stale_after_s=0)
    with SerialLink(settings, opener=lambda s: port) as link:
        link.publish(0, (0.0, 0.0, 100.0), (0, 0, 0))
        assert port.writing.wait(5)  # frame 0 is stuck in write()
        for i in range(1, 50):
            assert link.publish(i, (float(i), 0.0, 100.0), (0, 0, 0))  # returns although the port is stuck
            assert link.status().pending <= 1
        port.writing.clear()
        port.release.set()
        wait_until(lambda: len(port.written) >= 2, what="the second write")
        status = link.status()
    second = parse_frame_line(port.written[1])
    assert second["t_ms"] == 49 and second["pose"][0] == 49.0 and second["seq"] == 1
    assert status.frames_dropped == 48 and status.pending == 0


@pytest.mark.slow
def test_rate_limit_caps_frames_per_second_and_the_newest_pose_goes_last():
    port = SlowPort(write_s=0)
    settings = SerialLinkSettings(port="fake", max_rate_hz=20, stale_after_s=0)
    with SerialLink(settings, opener=lambda s: port) as link:
        start = time.monotonic()
        published = 0
        while time.monotonic() - start < 0.5:  # a frame loop far faster than 20 Hz
            link.publish(published, (float(published), 0.0, 100.0), (0, 0, 0))
            published += 1
            time.sleep(0.001)
        end = time.monotonic()
        # Every published pose is accounted for once the last one is written: sent or superseded.
        wait_until(
            lambda: link.status().frames_sent + link.status().frames_dropped == published,
            what="the last pose written",
        )
        status = link.status()
    # The link takes a pose at most once per 1/20 s, and none before `start`, so by `end` at most
    # (end - start) * 20 + 1 frames can have been written (scheduling delays only lower the count).
    in_window = sum(1 for t in port.times if t <= end)
    assert 2 <= in_window <= (end - start) * 20 + 1
    last = [f for f in map(parse_frame_line, port.written) if f["status"] == "OK"][-1]
    assert last["t_ms"] == published - 1  # the newest pose is never lost, only superseded ones
    assert status.pending == 0 and status.frames_dropped > 0
    assert status.frames_sent == len(port.written) - 1  # the closing NOSRC was written after


def test_close_writes_the_newest_pose_held_back_by_the_rate_limit_then_nosrc_last():
    # `qrfield run --frames 1 --serial PORT` closes the link right after publishing its only pose.
    port = SlowPort(write_s=0)
    settings = SerialLinkSettings(port="fake", max_rate_hz=0.1, stale_after_s=0)  # one frame per 10 s
    link = SerialLink(settings, opener=lambda s: port).start()
    link.publish(1, (1.0, 2.0, 300.0), (0, 0, 0))
    wait_until(lambda: len(port.written) == 1, what="the first frame")
    link.publish(2, (2.0, 2.0, 300.0), (0, 0, 0))  # held back: the next slot is 10 s away
    link.close()
    frames = [parse_frame_line(line) for line in port.written]
    assert [(f["t_ms"], f["status"]) for f in frames[:2]] == [(1, "OK"), (2, "OK")]
    assert frames[-1]["status"] == "NOSRC" and len(frames) == 3  # the controller is told, not left guessing
    status = link.status()
    assert status.frames_sent == 3 and status.frames_dropped == 0 and status.state == CLOSED


def test_non_finite_pose_goes_out_as_noconv_with_the_reason_recorded():
    port = SlowPort(write_s=0)
    sent = []
    settings = SerialLinkSettings(port="fake", stale_after_s=0)
    with SerialLink(settings, opener=lambda s: port, on_sent=lambda b, dt: sent.append(b)) as link:
        assert link.publish(5.4, (1.0, float("nan"), 3.0), (0, 0, 0), "OK")  # no exception in the frame loop
        wait_until(lambda: link.status().frames_sent == 1, what="the frame")
        status = link.status()
    frame = parse_frame_line(port.written[0])
    assert (frame["status"], frame["pose"], frame["t_ms"]) == ("NOCONV", None, 5)
    assert status.errors == 1 and "finite" in status.last_error and "t_ms=5.4" in status.last_error
    assert sent == port.written[:1]  # then the closing NOSRC
    assert status.last_sent == port.written[0].decode().rstrip()


def test_publish_rejects_misuse_and_returns_false_once_closed():
    link = SerialLink(SerialLinkSettings(), opener=lambda s: SlowPort(0))
    with pytest.raises(FrameError, match="shape"):
        link.publish(0, (1, 2), (0, 0, 0))
    with pytest.raises(ValueError, match="t_ms"):
        link.publish(float("nan"), (1, 2, 3), (0, 0, 0))
    with pytest.raises(FrameError, match="give position_mm and angles_deg"):
        link.publish(0, (1, 2, 3), None)
    with pytest.raises(ValueError, match="status must be one of"):
        link.publish(0, None, None, "LOST")
    link.close()
    assert link.status().state == CLOSED
    assert link.publish(0, (1, 2, 3), (0, 0, 0)) is False


def test_settings_are_validated_and_ports_listed():
    with pytest.raises(ValueError, match="baud"):
        SerialLink(SerialLinkSettings(baud=10))
    with pytest.raises(ValueError, match="max_rate_hz"):
        SerialLink(SerialLinkSettings(max_rate_hz=-1))
    with pytest.raises(ValueError, match="only device paths and loop://"):
        SerialLink(SerialLinkSettings(port="socket://localhost:7777"))
    SerialLink(SerialLinkSettings(port="socket://localhost:7777", allow_url=True)).close()
    assert list_ports()[-1].device == LOOP_URL


def test_missing_port_reports_disconnected_and_keeps_trying(tmp_path):
    path = tmp_path / "ttyNone"
    settings = SerialLinkSettings(port=str(path), reconnect_interval_s=0.05)
    with SerialLink(settings) as link:
        assert link.wait_for_state(DISCONNECTED, 5)
        wait_until(lambda: link.status().errors >= 3, what="repeated attempts")
        assert "cannot open" in link.status().last_error and str(path) in link.status().last_error
        assert link.status().summary().startswith(f"serial {path}: disconnected, 0 sent")
        assert link.publish(0, None, None, "NOQR")
        pty = PtyTwin(path)
        try:
            assert link.wait_for_state(CONNECTED, 5)
            wait_until(lambda: len(frames_of(pty.received)) >= 1, what="the pending frame")
            assert frames_of(pty.received)[0]["status"] == "NOQR"
        finally:
            link.close()
            pty.vanish()


def test_receive_callback_gets_controller_commands_over_loop():
    got: queue.Queue = queue.Queue()
    holder = {}

    def opener(settings):
        holder["port"] = open_pyserial(settings)
        return holder["port"]

    with SerialLink(SerialLinkSettings(stale_after_s=0), on_receive=got.put, opener=opener) as link:
        assert link.wait_for_state(CONNECTED, 5)
        holder["port"].write(b"noise" + encode_command("RATE", "10"))  # loop:// reads it back
        assert got.get(timeout=5) == ControllerCommand("QRC", ("RATE", "10"))
        wait_until(lambda: link.status().received.get("garbage_bytes") == 5, what="garbage count")


# ---------------------------------------------------------------------- result status -> wire status
#: By hand from docs/conventions.md: a frame without a pose of its own (no code, no convergence, an
#: error) goes out with empty fields; a pose goes out as OK only from a live camera and unambiguous,
#: AMBIG from a live camera when its flip is unresolved, else SIM. Keys: (status, simulated, ambiguous).
WIRE_STATUS_OF_RESULT = {
    ("OK", False, False): "OK",
    ("OK", False, True): "AMBIG",
    ("OK", True, False): "SIM",
    ("OK", True, True): "SIM",
    **{(s, sim, amb): "NOQR" for s in ("NOQR",) for sim in (False, True) for amb in (False, True)},
    **{
        (s, sim, amb): "NOCONV" for s in ("NOCONV", "ERROR") for sim in (False, True) for amb in (False, True)
    },
}


def test_every_result_status_maps_to_the_wire_status_it_is_sent_as() -> None:
    from types import SimpleNamespace

    from qrfield.pipeline import RESULT_STATUSES, FrameResult
    from qrfield.serial.codec import FRAME_STATUSES, encode_frame

    assert set(RESULT_STATUSES) == {"OK", "NOQR", "NOCONV", "ERROR"}
    assert set(FRAME_STATUSES) == {"OK", "AMBIG", "SIM", "NOQR", "NOCONV", "STALE", "NOSRC"}

    class Recorder:
        def publish(self, t_ms, position_mm, angles_deg, status, **kwargs):
            self.sent = (t_ms, position_mm, angles_deg, status, kwargs)
            return True

    for (status, simulated, ambiguous), wire in WIRE_STATUS_OF_RESULT.items():
        pose = SimpleNamespace(
            converged=True,
            position_mm=np.array([1.0, -2.0, 300.0]),
            angles_deg=np.array([5.0, -6.0, 7.0]),
            position_std_mm=np.array([0.1, 0.1, 0.4]),
            angles_std_deg=np.array([0.2, 0.2, 0.05]),
            ambiguous=ambiguous,
        )
        result = FrameResult(index=0, t_ms=40, status=status, poses={"numerical": pose}, t_capture=12.5)
        link = Recorder()
        assert publish_result(link, result, simulated=simulated)
        t_ms, position, angles, sent, kwargs = link.sent
        assert (t_ms, sent, kwargs["captured_at"]) == (40, wire, 12.5), (status, simulated, ambiguous)
        has_pose = wire in ("OK", "AMBIG", "SIM")
        assert (position is not None) == has_pose and (angles is not None) == has_pose
        pose_fields = None
        if has_pose:
            pose_fields = wire_pose(position, angles, kwargs["std_position_mm"], kwargs["std_angles_deg"])
        line = encode_frame(0, t_ms, 3, sent, pose_fields)
        parsed = parse_frame_line(line)
        assert parsed["status"] == wire
        if has_pose:
            assert parsed["sigma"] == [0.1, 0.1, 0.4, 0.2, 0.2, 0.05]


# ---------------------------------------------------------------------- pacing on a fake clock
BAUD = 9600


def item(t_ms: int, at: float, status: str = "OK") -> PoseItem:
    pose = wire_pose((t_ms / 10, 0.0, 300.0), (0, 0, 0)) if status == "OK" else None
    return PoseItem(t_ms, at, status, pose, at)


def outbox(now: float = 0.0, **kwargs) -> Outbox:
    return Outbox(**{"baud": BAUD, "max_rate_hz": 0, "stale_after_s": 0, "now": now, **kwargs})


def test_at_most_one_pose_waits_and_a_newer_one_replaces_it():
    box = outbox()
    first = box.take(0.0)
    assert first is None  # nothing published
    box.put_pose(item(0, 0.0))
    out = box.take(0.0)
    assert out is not None and out.kind == "pose"
    box.written(out, 0.0)
    for k in range(1, 20):  # a 30 Hz frame loop while the first line is on the wire
        box.put_pose(item(k, k / 300))
        assert box.pose.full and box.pose.dropped == k - 1
    busy_until = line_time_s(len(out.line), BAUD) * PACE_MARGIN
    assert box.take(busy_until - 1e-6) is None  # the wire is still busy: nothing more is handed over
    nxt = box.take(busy_until)
    assert nxt is not None and parse_frame_line(nxt.line)["t_ms"] == 19  # the newest, no backlog
    assert parse_frame_line(nxt.line)["seq"] == 1


def test_age_ms_counts_from_the_capture_to_the_moment_the_line_is_handed_over():
    box = outbox()
    box.put_pose(item(5, at=10.0))
    out = box.take(10.25)
    assert out is not None and out.age_ms == 250 and parse_frame_line(out.line)["age_ms"] == 250


def test_answers_jump_the_queue_and_wait_only_for_the_wire():
    box = outbox(max_rate_hz=1)
    box.put_pose(item(0, 0.0))
    box.written(box.take(0.0), 0.0)
    box.put_pose(item(1, 0.01))
    box.put_answer(encode_ok("PING"))
    free = box.wire_free_at
    assert box.take(free - 1e-6) is None
    out = box.take(free)
    assert out is not None and out.kind == "answer"  # before the waiting pose
    box.written(out, free)
    assert box.take(box.wire_free_at) is None  # the pose waits for its rate limit, 1 s
    assert box.take(1.0).kind == "pose"


def test_the_drivers_own_queue_holds_the_next_line_back():
    box = outbox()
    box.put_pose(item(0, 0.0))
    box.driver_queue(96, 0.0)  # 96 bytes still in the UART's buffer: 0.1 s at 9600 baud
    assert box.take(0.099) is None and box.take(0.1 * PACE_MARGIN) is not None


def test_nosrc_at_once_then_every_interval_and_stale_when_nothing_is_published():
    box = outbox(stale_after_s=0.5)
    box.put_pose(item(1000, 1.0))
    box.written(box.take(1.0), 1.0)
    box.set_source_down(True, 2.0)
    nosrc = box.take(2.0)
    assert nosrc is not None and nosrc.kind == "nosrc"
    parsed = parse_frame_line(nosrc.line)
    assert (parsed["status"], parsed["t_ms"], parsed["age_ms"]) == ("NOSRC", 2000, 1000)
    box.written(nosrc, 2.0)
    assert (
        box.take(2.0 + NOSRC_INTERVAL_S - 0.01) is None and box.take(2.0 + NOSRC_INTERVAL_S).kind == "nosrc"
    )
    box.set_source_down(False, 3.0)
    assert box.take(3.0).kind == "stale"  # up, but nothing new since t = 1 s
    fresh = outbox(stale_after_s=0.5, now=0.0)
    stale = fresh.take(0.5)
    assert stale is not None and parse_frame_line(stale.line)["age_ms"] is None  # no frame ever


def test_thirty_seconds_at_9600_baud_every_line_carries_the_newest_pose_and_none_queues():
    """A 30 Hz frame loop into a 9600-baud wire, on a fake clock stepping 1 ms: the wire is never
    handed a line before the previous one is through, and every pose line is the newest pose."""
    box = outbox(max_rate_hz=30)
    wire_busy_until, lines, newest, on_wire = 0.0, 0, -1, 0.0
    for step in range(30_000):
        now = step / 1000
        if step % 33 == 0:
            newest = step
            box.put_pose(item(step, now))
        out = box.take(now)
        if out is None:
            continue
        assert now >= wire_busy_until - 1e-9  # nothing waits behind a line still on the wire
        wire_busy_until = now + line_time_s(len(out.line), BAUD)
        box.written(out, now)
        assert parse_frame_line(out.line)["t_ms"] == newest
        lines += 1
        on_wire += line_time_s(len(out.line), BAUD)
    # The wire is kept busy (the 1 ms steps leave it idle up to 1 ms a line), never over-full, and
    # carries far fewer lines than the 900 poses published.
    assert 0.9 * 30 < on_wire <= 30 + 0.2 and lines < 600


def test_an_ambiguous_misfit_goes_out_ambig_with_the_streams_scaled_sigma() -> None:
    """audit-serial: a live frame ambiguous with no history (a stream's first frame, a distinct
    mirror) whose fit's chi-square is 39.21 goes out AMBIG with every sigma field 4 times the
    solver's (hand-computed: variance x 1 + (39.21 - 9.21) / 2 = 16, docs/uncertainty.md), as an
    unambiguous misfit's does; before, the AMBIG line carried the solver's raw std."""
    from dataclasses import replace

    from stream_cases import SIDE_MM, frame_result, solved

    from qrfield.stream import StreamStage

    class Recorder:
        def publish(self, t_ms, position_mm, angles_deg, status, **kwargs):
            self.sent = (status, kwargs)
            return True

    raw = next(r for r in (solved(seed, 0.15) for seed in range(50)) if r.converged and r.ambiguous)
    pose = replace(raw, chi2=39.21, mirror_chi2=40.21)
    result = frame_result(pose, 0, 0, noise_px=0.15)
    StreamStage().apply(result, SIDE_MM, result.detection.pose_cov)
    link = Recorder()
    assert publish_result(link, result, simulated=False)
    status, kwargs = link.sent
    assert status == "AMBIG"
    assert np.allclose(kwargs["std_position_mm"], 4.0 * pose.position_std_mm, rtol=1e-6)
    assert np.allclose(kwargs["std_angles_deg"], 4.0 * pose.angles_std_deg, rtol=1e-6)


@pytest.mark.parametrize("down", [False, True])
def test_no_pose_goes_out_after_a_stale_or_nosrc_line_that_is_newer_than_it(down) -> None:
    """audit-serial: at RATE 1 a pose published at 40 ms waits for its turn at 1 s; the frames
    stop (STALE at 0.54 s: stale_after_s 0.5 after the last publish) or the source goes down
    (NOSRC at 0.3 s). That waiting pose is older than the status line that went out first: it must
    not follow it as OK (a pose 967 ms old, its t_ms before the STALE's, the controller told
    nothing newer came and then handed an OK). Before, it did."""
    box = outbox(max_rate_hz=1, stale_after_s=0.5)
    box.put_pose(item(0, 0.0))
    box.written(box.take(0.0), 0.0)
    box.put_pose(item(33, 0.033))  # published at 0.033 s, rate-limited until 1 s
    if down:
        box.set_source_down(True, 0.3)
    lines = []
    for step in range(1, 3000):
        now = step / 1000
        out = box.take(now)
        if out is not None:
            box.written(out, now)
            lines.append(parse_frame_line(out.line))
    statuses = [line["status"] for line in lines]
    first = statuses.index("NOSRC" if down else "STALE")
    assert "OK" not in statuses[first:], statuses
    assert box.expired == 1
