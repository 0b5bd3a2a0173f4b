"""The serial link: the port's own thread, paced so the controller gets the newest pose, never a backlog.

The frame loop calls :meth:`SerialLink.publish` and never blocks; the link's thread owns the port.
What goes out next is decided by an :class:`Outbox` (no I/O, no thread; tests drive it with a fake
clock), by docs/conventions.md's "Pacing, newest first":

- at most one ``$QRF`` pose waits for the port (a :class:`~qrfield.mailbox.Mailbox`): a newer pose
  replaces it (``superseded``), and a pose is encoded only when it is written, so its ``age_ms``
  counts to the moment it is handed to the port;
- lines go out no faster than the port carries them: after a line of n bytes the wire is taken to
  be busy for n x 10 / baud s (8N1), and 2 % more, so a UART a little slower than its nominal baud
  still never builds a queue; where the driver reports its output queue (pyserial's
  ``out_waiting`` on a device), the wire is busy until that queue would be empty. Poses also go
  out no faster than ``max_rate_hz`` (0: as fast as frames and the port allow, ``$QRC,RATE``);
- answers to commands wait only for the wire, and go out before any waiting pose;
- NOSRC goes out every :data:`NOSRC_INTERVAL_S` while the source is down, the first at once; STALE
  every ``stale_after_s`` while the source is up but nothing was published for that long; either
  discards a pose still waiting (held back by the rate limit): it is older than what the status
  line says, and never follows it as OK (counted in ``frames_dropped``);
- closing writes the answers and the pose still waiting, then one NOSRC (the last line before the
  run ends: the controller is told the source is gone, not left guessing from silence).

When the port vanishes (a write or read raises) the link says ``disconnected`` and reopens it every
``reconnect_interval_s``. The port is opened by :func:`qrfield.serial.port.open_pyserial` (exclusive,
names checked); the line format is :mod:`qrfield.serial.codec`'s. The simulated twins of a port are
pyserial's ``loop://`` and a pty pair (a pty ignores the baud: :mod:`qrfield.serial.relay` passes
bytes at a UART's pace).
"""

from __future__ import annotations

import collections
import contextlib
import math
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from qrfield.mailbox import Mailbox
from qrfield.serial import codec
from qrfield.serial.port import LOOP_URL, PortBusyError, PortLike, check_port_name, is_url, open_pyserial
from qrfield.settings import setting, validated
from qrfield.status import WireStatus, reported_status, usable_pose, wire_status

CONNECTING = "connecting"
CONNECTED = "connected"
DISCONNECTED = "disconnected"
CLOSED = "closed"

#: While the source is down, a NOSRC line goes out this often, s (docs/conventions.md: >= 1/s).
NOSRC_INTERVAL_S = 0.5
#: The wire is taken to carry this much less than baud / 10 bytes/s (a UART's clock may be slow).
PACE_MARGIN = 1.02
#: The window over which LinkStatus.line_rate_hz counts $QRF lines, s.
RATE_WINDOW_S = 2.0
#: Statuses a caller may publish (the link makes STALE and NOSRC itself).
PUBLISHED_STATUSES = (WireStatus.OK, WireStatus.AMBIG, WireStatus.SIM, WireStatus.NOQR, WireStatus.NOCONV)


@dataclass(frozen=True)
class SerialLinkSettings:
    """Settings of the serial link to the gripper controller (8N1 framing is fixed)."""

    port: str = setting(
        LOOP_URL,
        label="port",
        help="device path (/dev/ttyUSB0, COM3) or loop://, the simulated port; other pyserial URLs "
        "need allow_url",
    )
    baud: int = setting(
        115200,
        label="baud rate",
        unit="baud",
        minimum=1200,
        maximum=4_000_000,
        help="8N1; lines are paced to it, so a slow line carries fewer, newer poses, never a backlog",
    )
    max_rate_hz: float = setting(
        30.0,
        label="maximum rate",
        unit="Hz",
        minimum=0.0,
        maximum=1000.0,
        decimals=1,
        help="pose lines per second at most (0 = as fast as frames and the port allow); newer poses "
        "replace unsent ones (9600 baud carries about 8 lines/s, 115200 about 100)",
    )
    reconnect_interval_s: float = setting(
        1.0,
        label="reconnect interval",
        unit="s",
        minimum=0.05,
        maximum=60.0,
        decimals=2,
        help="how often a vanished port is tried again",
    )
    stale_after_s: float = setting(
        0.5,
        label="stale after",
        unit="s",
        minimum=0.0,
        maximum=60.0,
        decimals=2,
        help="send STALE while the source is up but no frame was processed for this long (0 = never)",
    )
    write_timeout_s: float = setting(
        0.5,
        label="write timeout",
        unit="s",
        minimum=0.01,
        maximum=10.0,
        decimals=2,
        help="a write blocked longer than this (line stalled by flow control) drops that line",
    )
    allow_url: bool = setting(
        False,
        label="allow URLs",
        help="accept pyserial URLs such as socket://host:port as the port (poses then leave this machine)",
    )


@dataclass(frozen=True)
class LinkStatus:
    """A snapshot of the link, safe to read from any thread."""

    state: str  # connecting / connected / disconnected / closed
    port: str
    frames_sent: int = 0  # $QRF lines written (poses, STALE and NOSRC)
    frames_dropped: int = 0  # poses superseded unsent (by a newer one, STALE, NOSRC), or timed out
    errors: int = 0
    last_error: str = ""
    pending: int = 0  # poses waiting for the port: 0 or 1, never more
    reconnects: int = 0
    received: dict[str, int] = field(default_factory=dict)  # the decoder's counters for incoming bytes
    last_sent: str = ""  # the last $QRF line written, without CR LF
    ever_connected: bool = False  # the port was opened at least once
    answers_sent: int = 0  # $QRA / $QRM lines written
    answers_waiting: int = 0  # answers not yet written
    streaming: bool = True  # $QRF lines go out (the controller may send STREAM,OFF)
    source_down: bool = False  # NOSRC lines are being sent
    line_rate_hz: float = 0.0  # $QRF lines written per second over the last RATE_WINDOW_S
    lag_ms: float = math.nan  # the last pose's age when its last byte left: age_ms + the line's time
    max_rate_hz: float = 0.0  # the rate limit in force (RATE changes it), 0 = none
    last_command: str = ""  # the controller's last command and its answer (GripperLink fills it)

    def summary(self) -> str:
        """One line for a status bar or a headless log."""
        text = (
            f"serial {self.port}: {self.state}, {self.frames_sent} sent, {self.frames_dropped} superseded, "
            f"{self.errors} errors"
        )
        return f"{text} (last: {self.last_error})" if self.errors and self.last_error else text


@dataclass
class PoseItem:
    """A published result waiting for the port: encoded only when written."""

    t_ms: int
    captured_at: float  # the link's clock (time.monotonic() s) at the frame's capture
    status: str
    pose: codec.WirePose | None
    published_at: float


@dataclass(frozen=True)
class Outgoing:
    """One line the outbox hands the thread to write: kind answer / pose / nosrc / stale."""

    kind: str
    line: bytes
    item: PoseItem | None = None
    age_ms: int | None = None


def line_time_s(n_bytes: int, baud: float) -> float:
    """Seconds a line of ``n_bytes`` takes on an 8N1 wire at ``baud`` (10 bits a byte)."""
    return n_bytes * 10.0 / baud


class Outbox:
    """What the link writes next, and when (see the module doc). Not thread-safe on its own: the
    link calls it under its lock; ``condition`` is the lock the pose slot notifies.

    :meth:`take` returns the line to write now or None; :meth:`wake_at` says when to ask again;
    :meth:`written` (after a write) and :meth:`unsent` (a write that failed) settle it.
    """

    def __init__(
        self,
        *,
        baud: float,
        max_rate_hz: float,
        stale_after_s: float,
        now: float,
        first_seq: int = 0,
        condition: threading.Condition | None = None,
    ) -> None:
        self.baud = float(baud)
        self.max_rate_hz = float(max_rate_hz)
        self.stale_after_s = float(stale_after_s)
        self.seq = int(first_seq)
        self.answers: collections.deque[bytes] = collections.deque()
        self.pose: Mailbox[PoseItem] = Mailbox(condition)
        self.streaming = True
        self.source_down = False
        self.wire_free_at = now
        self._next_pose_at = now
        self._nosrc_due = now
        self._stale_due = now
        self._last_publish_at = now
        self._created_at = now
        self._last_capture: tuple[int, float] | None = None  # (t_ms, captured_at) of the newest frame
        self.error = ""  # the last line that could not be encoded
        self.expired = 0  # waiting poses discarded because a STALE or NOSRC line went out first

    # ----- inputs
    def put_pose(self, item: PoseItem) -> None:
        """The newest result; replaces a waiting one (the count of those: ``pose.dropped``)."""
        self._last_publish_at = item.published_at
        if self._last_capture is None or item.captured_at >= self._last_capture[1]:
            self._last_capture = (item.t_ms, item.captured_at)
        if self.streaming:
            self.pose.put(item)

    def put_answer(self, line: bytes) -> None:
        self.answers.append(bytes(line))

    def set_source_down(self, down: bool, now: float) -> None:
        if down and not self.source_down:
            self._nosrc_due = now
        self.source_down = bool(down)

    def set_streaming(self, on: bool) -> None:
        self.streaming = bool(on)
        if not on:
            self.pose.clear()

    def set_rate(self, hz: float, now: float) -> None:
        self.max_rate_hz = float(hz)
        self._next_pose_at = now

    def driver_queue(self, n_bytes: int, now: float) -> None:
        """The driver reports ``n_bytes`` not yet sent: the wire is busy until they are."""
        self.wire_free_at = max(self.wire_free_at, now + line_time_s(n_bytes, self.baud) * PACE_MARGIN)

    # ----- the stream's clock
    def stream_t_ms(self, now: float) -> int:
        """The stream's clock now: the newest frame's t_ms plus the time since its capture."""
        if self._last_capture is None:
            return int((now - self._created_at) * 1000.0) % codec.T_MS_MODULUS
        t_ms, at = self._last_capture
        return round(t_ms + (now - at) * 1000.0) % codec.T_MS_MODULUS

    def since_capture_ms(self, now: float) -> int | None:
        """ms since the newest frame's capture, None before any."""
        if self._last_capture is None:
            return None
        return _age_ms(now - self._last_capture[1])

    # ----- output
    def wake_at(self, now: float) -> float:
        """When :meth:`take` may next return a line (inf: only an input changes that)."""
        due = math.inf
        if self.answers:
            due = self.wire_free_at
        if self.streaming:
            if self.pose.full:
                due = min(due, max(self.wire_free_at, self._next_pose_at))
            if self.source_down:
                due = min(due, max(self.wire_free_at, self._nosrc_due))
            elif self.stale_after_s > 0:
                stale = max(self._last_publish_at + self.stale_after_s, self._stale_due)
                due = min(due, max(self.wire_free_at, stale))
        return due

    def take(self, now: float, *, closing: bool = False) -> Outgoing | None:
        """The line to write now (answers first, then the newest pose, NOSRC, STALE), or None.
        ``closing``: the wire and the rate limit are not waited for, and NOSRC and STALE are not made."""
        if not closing and now < self.wire_free_at:
            return None
        if self.answers:
            return Outgoing("answer", self.answers.popleft())
        if not self.streaming:
            return None
        if self.pose.full and (closing or now >= self._next_pose_at):
            item = self.pose.take()
            assert item is not None
            age = _age_ms(now - item.captured_at)
            try:
                line = codec.encode_frame(self.seq, item.t_ms, age, item.status, item.pose)
            except codec.FrameError as exc:  # publish() checked it: never let the thread die
                self.error = f"cannot encode the line: {exc}"
                return None
            return Outgoing("pose", line, item, age)
        if closing:
            return None
        if self.source_down and now >= self._nosrc_due:
            self._nosrc_due = now + NOSRC_INTERVAL_S
            self._expire()
            return self.status_line(WireStatus.NOSRC, now)
        stale_at = max(self._last_publish_at + self.stale_after_s, self._stale_due)
        if not self.source_down and self.stale_after_s > 0 and now >= stale_at:
            self._stale_due = now + self.stale_after_s
            self._expire()
            return self.status_line(WireStatus.STALE, now)
        return None

    def _expire(self) -> None:
        """A STALE or NOSRC line goes out: a pose still waiting (held back by the rate limit) is
        older than what that line says, so it is discarded, never sent after it as OK."""
        if self.pose.clear() is not None:
            self.expired += 1

    def status_line(self, status: str, now: float) -> Outgoing:
        """A STALE or NOSRC line for now (t_ms the stream's clock, age_ms since the newest capture)."""
        age = self.since_capture_ms(now)
        line = codec.encode_frame(self.seq, self.stream_t_ms(now), age, status)
        return Outgoing(str(status).lower(), line, None, age)

    def written(self, out: Outgoing, now: float) -> None:
        """``out`` was handed to the port at ``now``: the wire is busy for its bytes."""
        self.wire_free_at = max(now, self.wire_free_at) + line_time_s(len(out.line), self.baud) * PACE_MARGIN
        if out.kind != "answer":
            self.seq = (self.seq + 1) % codec.SEQ_MODULUS
        if out.kind == "pose":
            self._next_pose_at = now + (1.0 / self.max_rate_hz if self.max_rate_hz > 0 else 0.0)

    def unsent(self, out: Outgoing) -> None:
        """The write of ``out`` failed (port lost): an answer goes first again; a pose is offered
        again unless a newer one came meanwhile."""
        if out.kind == "answer":
            self.answers.appendleft(out.line)
        elif out.item is not None:
            self.pose.put_if_empty(out.item)


def _age_ms(seconds: float) -> int:
    return min(max(0, round(seconds * 1000.0)), codec.T_MS_MODULUS - 1)


def _is_write_timeout(exc: BaseException) -> bool:
    if isinstance(exc, queue.Full):  # pyserial's loop:// raises this when its buffer is full
        return True
    try:
        import serial

        return isinstance(exc, serial.SerialTimeoutException)
    except ImportError:
        return False


class SerialLink:
    """Stream lines to a serial port from a background thread (see the module docstring).

    on_status(LinkStatus) is called from the link's thread on every state change and error;
    on_receive(item) for every item decoded from the port (commands, and a
    :class:`~qrfield.serial.codec.RejectedLine` for each line that could not be read; over
    ``loop://`` also the link's own lines coming back); on_tick() about every POLL_S while the port
    is open; on_sent(line, seconds_since_publish) after each pose line written. Callbacks must be
    quick; a Qt app forwards them by signal. ``opener`` makes a port from the settings (default:
    :func:`~qrfield.serial.port.open_pyserial`; tests pass fakes); ``clock`` is time.monotonic
    unless a test gives its own; ``first_seq`` is the seq of the first $QRF line.
    """

    POLL_S = 0.01  # how often the thread reads incoming bytes when it has nothing to write

    def __init__(
        self,
        settings: SerialLinkSettings,
        *,
        on_status: Callable[[LinkStatus], None] | None = None,
        on_receive: Callable[[codec.Decoded], None] | None = None,
        on_sent: Callable[[bytes, float], None] | None = None,
        opener: Callable[[SerialLinkSettings], PortLike] | None = None,
        first_seq: int = 0,
        on_tick: Callable[[], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.settings = validated(settings)
        check_port_name(self.settings.port, self.settings.allow_url)
        if not 0 <= first_seq < codec.SEQ_MODULUS:
            raise ValueError(f"first_seq must be in 0..{codec.SEQ_MODULUS - 1}, got {first_seq}")
        self._on_status = on_status
        self._on_receive = on_receive
        self._on_sent = on_sent
        self._on_tick = on_tick
        self._opener = opener or open_pyserial
        self._clock = clock
        self._lock = threading.Condition()
        s = self.settings
        self._outbox = Outbox(
            baud=s.baud,
            max_rate_hz=s.max_rate_hz,
            stale_after_s=s.stale_after_s,
            now=clock(),
            first_seq=first_seq,
            condition=self._lock,
        )
        # The driver's own output queue is asked on a device (pyserial's out_waiting, TIOCOUTQ);
        # loop:// reports the bytes its own reader has not taken yet, which says nothing of a wire.
        self._ask_driver = not is_url(s.port)
        self._ever_connected = False
        self._stop = False
        self._thread: threading.Thread | None = None
        self._port: PortLike | None = None
        self._decoder = codec.FrameDecoder(report_rejected=True)
        self._state = CONNECTING
        self._counts = {
            "frames_sent": 0,
            "frames_dropped": 0,
            "errors": 0,
            "reconnects": 0,
            "answers_sent": 0,
        }
        self._last_error = ""
        self._last_sent = ""
        self._lag_ms = math.nan
        self._sent_times: collections.deque[float] = collections.deque(maxlen=4096)

    # ----- the frame loop's side -------------------------------------------------------------
    def start(self, *, open_first: bool = False) -> SerialLink:
        """Start the link's thread (it opens the port); returns self. Idempotent.

        ``open_first``: open the port here first, so a busy port raises PortBusyError (and a name
        not accepted ValueError) to the caller; any other failure is left to the thread's retries.
        """
        with self._lock:
            if self._thread is not None or self._stop:
                return self
        if open_first:
            try:
                self._port = self._opener(self.settings)
            except (PortBusyError, ValueError):
                raise
            except Exception as exc:
                self._error(f"cannot open {self.settings.port}: {exc}", notify=False)
            else:
                self._connected()
        with self._lock:
            if self._thread is None and not self._stop:
                self._thread = threading.Thread(
                    target=self._run, name=f"serial-link {self.settings.port}", daemon=True
                )
                self._thread.start()
        return self

    def __enter__(self) -> SerialLink:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def stream_time_ms(self) -> int:
        """The stream's clock now, ms (the newest frame's t_ms plus the time since its capture)."""
        with self._lock:
            return self._outbox.stream_t_ms(self._clock())

    def publish(
        self,
        t_ms: int | float | None,
        position_mm: Sequence[float] | np.ndarray | None,
        angles_deg: Sequence[float] | np.ndarray | None,
        status: str = WireStatus.OK,
        *,
        std_position_mm: Sequence[float | None] | np.ndarray | None = None,
        std_angles_deg: Sequence[float | None] | np.ndarray | None = None,
        captured_at: float | None = None,
    ) -> bool:
        """Hand the newest result to the link; returns at once and never blocks on the port.

        t_ms: capture time in ms since the stream started (None: the stream's clock now; floats are
        rounded; wraps at 2**32). position_mm (x, y, z, camera frame, mm), angles_deg (alpha, beta,
        gamma, degrees) and their standard uncertainties (NaN or None where unknown) for OK, AMBIG
        and SIM; None for NOQR and NOCONV. captured_at: the capture's time on the link's clock
        (time.monotonic() s, ``Frame.t_capture``; None: now), from which age_ms counts.
        Returns False once the link is closed. Raises FrameError (ValueError) on misuse (a status
        other than OK, AMBIG, SIM, NOQR, NOCONV; a pose given or missing against the status; wrong
        shapes), so the mistake shows at the call site. A pose of the right shape with a non-finite
        or out-of-range value is data, not misuse: it goes out as NOCONV with empty fields, and
        ``errors`` / ``last_error`` say why.
        """
        if status not in PUBLISHED_STATUSES:
            names = ", ".join(str(s) for s in PUBLISHED_STATUSES)
            raise codec.FrameError(
                f"status must be one of {names} (the link makes STALE and NOSRC), got {status!r}"
            )
        has_pose = status in codec.POSE_STATUSES
        if (position_mm is not None or angles_deg is not None) != has_pose or (
            has_pose and (position_mm is None or angles_deg is None)
        ):
            raise codec.FrameError(
                f"status {status}: give position_mm and angles_deg"
                if has_pose
                else f"status {status} has no pose"
            )
        pose = None
        if has_pose:
            try:
                pose = codec.wire_pose(position_mm, angles_deg, std_position_mm, std_angles_deg)  # type: ignore[arg-type]
            except codec.PoseValueError as exc:
                self._error(f"pose at t_ms={t_ms} sent as NOCONV: {exc}")
                status = WireStatus.NOCONV
        now = self._clock()
        if t_ms is None:
            with self._lock:
                t = self._outbox.stream_t_ms(now)
        else:
            try:
                value = float(t_ms)
            except (TypeError, ValueError):
                value = math.nan
            if isinstance(t_ms, bool) or not math.isfinite(value) or value < 0:
                raise ValueError(f"t_ms must be a finite number of ms >= 0, got {t_ms!r}")
            t = round(value) % codec.T_MS_MODULUS
        at = now if captured_at is None or not math.isfinite(captured_at) else min(float(captured_at), now)
        item = PoseItem(t, at, str(status), pose, now)
        with self._lock:
            if self._stop:
                return False
            self._outbox.put_pose(item)
            self._lock.notify()
        return True

    def send_line(self, line: bytes) -> bool:
        """Write one complete line (an answer to the controller) as soon as the wire is free, ahead
        of any pose; never blocks. False once the link is closed."""
        with self._lock:
            if self._stop:
                return False
            self._outbox.put_answer(line)
            self._lock.notify()
        return True

    def answers_waiting(self) -> int:
        """Answers handed to :meth:`send_line` and not yet written."""
        with self._lock:
            return len(self._outbox.answers)

    def set_streaming(self, on: bool) -> None:
        """Start or stop the $QRF lines (poses, STALE and NOSRC alike); answers still go out."""
        with self._lock:
            self._outbox.set_streaming(on)
            self._lock.notify()

    def set_rate(self, hz: float) -> None:
        """Pose lines per second at most from now on (0: as fast as frames and the port allow)."""
        hz = float(hz)
        if not (hz == 0 or 0.1 <= hz <= 1000):
            raise ValueError(f"a rate is 0 or 0.1..1000 Hz, got {hz:g}")
        with self._lock:
            self._outbox.set_rate(hz, self._clock())
            self._lock.notify()

    def set_source_down(self, down: bool) -> None:
        """``down``: the frame loop has no camera frames; NOSRC goes out every NOSRC_INTERVAL_S,
        the first one at once, until the source is up again."""
        with self._lock:
            self._outbox.set_source_down(down, self._clock())
            self._lock.notify()

    def status(self) -> LinkStatus:
        """A consistent snapshot of state and counters."""
        with self._lock:
            return self._snapshot()

    def wait_for_state(self, state: str, timeout: float) -> bool:
        """Block up to ``timeout`` s until the link is in ``state`` (for tools and tests)."""
        deadline = time.monotonic() + timeout
        with self._lock:
            while self._state != state:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._lock.wait(min(left, 0.05))
            return True

    def close(self, timeout: float = 2.0) -> None:
        """Write the answers and the pose still waiting and a last NOSRC (if connected and
        streaming), stop the thread (joined up to ``timeout`` s) and close the port."""
        with self._lock:
            self._stop = True
            self._lock.notify_all()
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        if thread is None or not thread.is_alive():
            self._close_port()
            self._set_state(CLOSED)

    # ----- the link's thread ------------------------------------------------------------------
    def _snapshot(self) -> LinkStatus:
        now = self._clock()
        box = self._outbox
        recent = sum(1 for t in self._sent_times if t >= now - RATE_WINDOW_S)
        return LinkStatus(
            state=self._state,
            port=self.settings.port,
            last_error=self._last_error,
            pending=1 if box.pose.full else 0,
            received=self._decoder.counters.as_dict(),
            last_sent=self._last_sent,
            ever_connected=self._ever_connected,
            streaming=box.streaming,
            source_down=box.source_down,
            answers_waiting=len(box.answers),
            line_rate_hz=recent / RATE_WINDOW_S,
            lag_ms=self._lag_ms,
            max_rate_hz=box.max_rate_hz,
            **{
                **self._counts,
                "frames_dropped": self._counts["frames_dropped"] + box.pose.dropped + box.expired,
            },
        )

    def _notify(self) -> None:
        if self._on_status is not None:
            snapshot = self.status()
            try:
                self._on_status(snapshot)
            except Exception as exc:  # a faulty callback must not stop the link
                self._error(f"status callback failed: {exc!r}", notify=False)

    def _set_state(self, state: str) -> None:
        with self._lock:
            changed = state != self._state
            self._state = state
            self._lock.notify_all()
        if changed:
            self._notify()

    def _error(self, text: str, notify: bool = True) -> None:
        with self._lock:
            self._counts["errors"] += 1
            self._last_error = text
        if notify:
            self._notify()

    def _close_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()

    def _connected(self) -> None:
        self._decoder.discard_partial()  # a line cut by the reconnect must not join the next one
        with self._lock:
            if self._ever_connected:
                self._counts["reconnects"] += 1
            self._ever_connected = True
        self._set_state(CONNECTED)

    def _try_open(self) -> bool:
        try:
            self._port = self._opener(self.settings)
        except Exception as exc:
            self._port = None
            self._error(f"cannot open {self.settings.port}: {exc}")
            return False
        self._connected()
        return True

    def _lose_port(self, exc: BaseException, doing: str) -> None:
        self._close_port()
        self._error(f"{doing} {self.settings.port} failed: {exc}")
        self._set_state(DISCONNECTED)

    def _driver_backlog(self) -> int:
        if not self._ask_driver or self._port is None:
            return 0
        try:
            return int(getattr(self._port, "out_waiting", 0) or 0)
        except Exception:  # a driver that cannot say: the baud alone paces
            self._ask_driver = False
            return 0

    def _run(self) -> None:
        next_open = 0.0  # time of the next attempt to open the port
        while True:
            if self._port is None:
                now = self._clock()
                if now >= next_open and not self._stop and not self._try_open():
                    next_open = now + self.settings.reconnect_interval_s
                    self._set_state(DISCONNECTED)
                if self._port is None:
                    with self._lock:
                        if self._stop:
                            break
                        self._lock.wait(max(0.001, min(next_open - self._clock(), 0.1)))
                    continue
            with self._lock:
                stopping = self._stop
                due = self._outbox.wake_at(self._clock())
            if stopping:
                self._finish()
                break
            if due <= self._clock():
                backlog = self._driver_backlog()
                if backlog > 0:
                    with self._lock:
                        self._outbox.driver_queue(backlog, self._clock())
            with self._lock:
                now = self._clock()
                out = self._outbox.take(now)
                if out is None and not self._stop:
                    wait = min(self._outbox.wake_at(now), now + self.POLL_S) - now
                    self._lock.wait(max(0.0005, wait))
                error, self._outbox.error = self._outbox.error, ""
            if error:
                self._error(error)
            if out is not None:
                self._write(out)
            self._read_incoming()
            if self._port is None:
                next_open = self._clock() + self.settings.reconnect_interval_s
            elif self._on_tick is not None:
                try:
                    self._on_tick()
                except Exception as exc:  # a faulty callback must not stop the link
                    self._error(f"tick callback failed: {exc!r}", notify=False)
        self._close_port()
        self._set_state(CLOSED)

    def _finish(self) -> None:
        """Closing: the answers and the waiting pose once each, then one NOSRC (if streaming)."""
        while self._port is not None:
            with self._lock:
                out = self._outbox.take(self._clock(), closing=True)
            if out is None:
                break
            self._write(out, retry=False)
        with self._lock:
            last = (
                self._outbox.status_line(WireStatus.NOSRC, self._clock()) if self._outbox.streaming else None
            )
        if last is not None and self._port is not None:
            self._write(last, retry=False)

    def _write(self, out: Outgoing, retry: bool = True) -> None:
        port = self._port
        assert port is not None
        try:
            port.write(out.line)
        except Exception as exc:
            if _is_write_timeout(exc):
                with self._lock:
                    if out.kind == "pose":
                        self._counts["frames_dropped"] += 1
                self._error(f"write to {self.settings.port} timed out: {exc!r}")
                return
            self._lose_port(exc, "writing to")
            if retry:
                with self._lock:
                    self._outbox.unsent(out)
            return
        now = self._clock()
        with self._lock:
            self._outbox.written(out, now)
            if out.kind == "answer":
                self._counts["answers_sent"] += 1
                return
            self._counts["frames_sent"] += 1
            self._sent_times.append(now)
            self._last_sent = out.line.decode("ascii").rstrip()
            if out.kind == "pose" and out.age_ms is not None:
                self._lag_ms = out.age_ms + line_time_s(len(out.line), self.settings.baud) * 1000.0
        if self._on_sent is not None and out.item is not None:
            with contextlib.suppress(Exception):
                self._on_sent(out.line, now - out.item.published_at)

    def _read_incoming(self) -> None:
        port = self._port
        if port is None:
            return
        try:
            data = port.read(4096)
        except Exception as exc:
            self._lose_port(exc, "reading from")
            return
        if not data:
            return
        items = self._decoder.feed(data)
        if self._on_receive is not None:
            for item in items:
                try:
                    self._on_receive(item)
                except Exception as exc:
                    self._error(f"receive callback failed: {exc!r}", notify=False)


def publish_result(link: SerialLink, result: object, simulated: bool = True) -> bool:
    """Hand one pipeline result (:class:`qrfield.pipeline.FrameResult`) to ``link``; never blocks.

    The status goes out by the one rule of :mod:`qrfield.status`: ``reported_status`` with the
    result's ``ambiguous`` (OK only for an unambiguous pose from a live camera, AMBIG for an
    ambiguous one, SIM when ``simulated``), then ``wire_status`` (ERROR and unknown statuses as
    NOCONV with empty fields). A pose carries the first method's position (mm), angles (degrees)
    and their standard uncertainties; age_ms counts from the result's ``t_capture``. Returns what
    :meth:`SerialLink.publish` returns (False once the link is closed).
    """
    try:
        ambiguous = bool(getattr(result, "ambiguous", False))
        status = wire_status(
            reported_status(getattr(result, "status", ""), live=not simulated, ambiguous=ambiguous)
        )
    except ValueError:
        status = WireStatus.NOCONV
    pose = getattr(result, "primary", None)
    t_ms = getattr(result, "t_ms", None)
    captured_at = getattr(result, "t_capture", None)
    if status not in codec.POSE_STATUSES or not usable_pose(pose):
        empty = WireStatus.NOQR if status == WireStatus.NOQR else WireStatus.NOCONV
        return link.publish(t_ms, None, None, empty, captured_at=captured_at)
    return link.publish(
        t_ms,
        pose.position_mm,
        pose.angles_deg,
        status,
        std_position_mm=getattr(pose, "position_std_mm", None),
        std_angles_deg=getattr(pose, "angles_std_deg", None),
        captured_at=captured_at,
    )
