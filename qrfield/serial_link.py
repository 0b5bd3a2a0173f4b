"""The serial link: streams pose frames from its own thread; the frame loop never blocks.

The frame loop calls :meth:`SerialLink.publish` (mm and degrees, see :mod:`qrfield.serial_frames`),
and :meth:`SerialLink.set_source_down` while it has no camera frames: the link then writes a NOSRC
frame every :data:`NOSRC_INTERVAL_S` from its own thread, so the controller can tell "no camera" from
"cable cut" even while opening a camera blocks the frame loop. Answers to the controller's commands
(:mod:`qrfield.serial_controller`) go out through :meth:`SerialLink.send_line`, ahead of any pose;
:meth:`SerialLink.set_streaming` starts and stops the $QRF lines (``$QRC,STREAM,OFF``).
The pose goes into a one-slot :class:`~qrfield.mailbox.Mailbox`: a newer pose replaces one not yet
written (counted in ``frames_dropped``), so the queue can never grow and the controller always gets
the newest pose.
The link's thread owns the port: it writes at most ``max_rate_hz`` frames per second, numbers them
(``seq``), reads and decodes what the controller sends, and when the port vanishes (a write or read
raises) it reports ``disconnected`` and reopens the port every ``reconnect_interval_s`` until it is
back.

The simulated twin of a serial port is pyserial's ``loop://`` (every byte written is read back) or a
pty pair; :func:`list_ports` offers ``loop://`` beside the machine's ports.

Named ``serial_link`` so as not to shadow pyserial's ``serial`` module. The frame format, encoder and
decoder live in :mod:`qrfield.serial_frames` (no I/O) and are re-exported here.
"""

from __future__ import annotations

import contextlib
import math
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from qrfield.mailbox import Mailbox
from qrfield.serial_frames import (  # re-exported: one import gives the whole serial API
    MAX_LINE_BYTES,
    SEQ_MODULUS,
    T_MS_MODULUS,
    WIRE_STATUSES,
    ControllerCommand,
    Decoded,
    DecoderCounters,
    FrameDecoder,
    FrameError,
    PoseValueError,
    QraAnswer,
    QrfFrame,
    QrmMeasurement,
    check_pose_fields,
    checksum,
    encode_answer,
    encode_command,
    encode_frame,
    encode_measurement,
)
from qrfield.settings import setting, validated
from qrfield.status import WireStatus, reported_status, usable_pose, wire_status

CONNECTING = "connecting"
CONNECTED = "connected"
DISCONNECTED = "disconnected"
CLOSED = "closed"
LOOP_URL = "loop://"

__all__ = [
    "CLOSED",
    "CONNECTED",
    "CONNECTING",
    "DISCONNECTED",
    "LOOP_URL",
    "MAX_LINE_BYTES",
    "WIRE_STATUSES",
    "ControllerCommand",
    "DecoderCounters",
    "FrameDecoder",
    "FrameError",
    "LinkStatus",
    "PortInfo",
    "PoseValueError",
    "QraAnswer",
    "QrfFrame",
    "QrmMeasurement",
    "SerialLink",
    "SerialLinkSettings",
    "checksum",
    "encode_answer",
    "encode_command",
    "encode_frame",
    "encode_measurement",
    "list_ports",
    "open_pyserial",
    "publish_result",
]


#: While the source is down, a NOSRC frame goes out this often, s (docs/conventions.md: >= 1/s).
NOSRC_INTERVAL_S = 0.5
#: Answers waiting to be written at most; an older one is dropped when a controller floods us.
MAX_ANSWERS = 16


@dataclass(frozen=True)
class SerialLinkSettings:
    """Settings of the serial link to the gripper controller (8N1 framing is fixed)."""

    port: str = setting(
        LOOP_URL,
        label="port",
        help="device path (/dev/ttyUSB0, COM3) or pyserial URL; loop:// is the simulated port",
    )
    baud: int = setting(115200, label="baud rate", unit="baud", minimum=1200, maximum=4_000_000, help="8N1")
    max_rate_hz: float = setting(
        30.0,
        label="maximum rate",
        unit="Hz",
        minimum=0.1,
        maximum=1000.0,
        decimals=1,
        help="frames per second at most; newer poses replace unsent ones "
        "(115200 baud 8N1 carries ~175 frames/s of 66 bytes)",
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
        help="repeat the last frame as STALE when nothing new was published for this long (0 = never)",
    )
    write_timeout_s: float = setting(
        0.5,
        label="write timeout",
        unit="s",
        minimum=0.01,
        maximum=10.0,
        decimals=2,
        help="a write blocked longer than this (line stalled by flow control) drops that frame",
    )


@dataclass(frozen=True)
class LinkStatus:
    """A snapshot of the link, safe to read from any thread."""

    state: str  # connecting / connected / disconnected / closed
    port: str
    frames_sent: int = 0
    frames_dropped: int = 0  # superseded by a newer pose before being written, or lost to a write timeout
    errors: int = 0
    last_error: str = ""
    pending: int = 0  # poses waiting to be written: 0 or 1, never more
    reconnects: int = 0
    received: dict[str, int] = field(default_factory=dict)  # the decoder's counters for incoming bytes
    last_sent: str = ""  # the last frame written, without CR LF
    ever_connected: bool = False  # the port was opened at least once
    answers_sent: int = 0  # $QRA / $QRM lines written
    streaming: bool = True  # $QRF lines go out (the controller may send STREAM,OFF)
    source_down: bool = False  # NOSRC frames are being sent

    def summary(self) -> str:
        """One line for a status bar or a headless log."""
        text = (
            f"serial {self.port}: {self.state}, {self.frames_sent} sent, {self.frames_dropped} superseded, "
            f"{self.errors} errors"
        )
        return f"{text} (last: {self.last_error})" if self.errors and self.last_error else text


@dataclass(frozen=True)
class PortInfo:
    """A port to offer in a chooser: its device (or URL) and a description."""

    device: str
    description: str


def list_ports() -> list[PortInfo]:
    """The machine's serial ports (pyserial's list_ports) followed by the simulated ``loop://``."""
    ports: list[PortInfo] = []
    try:
        from serial.tools import list_ports as pyserial_list_ports

        for info in sorted(pyserial_list_ports.comports(), key=lambda p: p.device):
            ports.append(PortInfo(info.device, info.description or info.device))
    except Exception as exc:  # a broken sysfs must not break the chooser
        ports.append(PortInfo("", f"(could not list ports: {exc})"))
    ports.append(PortInfo(LOOP_URL, "simulated port: pyserial loopback, every byte written is read back"))
    return ports


class PortLike(Protocol):
    """The part of a pyserial Serial object the link uses (fakes in tests implement just this)."""

    def write(self, data: bytes) -> int | None: ...
    def read(self, size: int = 1) -> bytes: ...
    def close(self) -> None: ...


def open_pyserial(settings: SerialLinkSettings) -> PortLike:
    """Open ``settings.port`` with pyserial (paths and URLs such as loop://), 8N1, non-blocking reads."""
    import serial

    return serial.serial_for_url(
        settings.port,
        baudrate=settings.baud,
        bytesize=8,
        parity="N",
        stopbits=1,
        timeout=0,
        write_timeout=settings.write_timeout_s,
    )


@dataclass
class _Pending:
    t_ms: int
    position: tuple[float, ...] | None
    angles: tuple[float, ...] | None
    status: str
    published_at: float  # time.perf_counter() at publish, for latency measurements


def _is_write_timeout(exc: BaseException) -> bool:
    if isinstance(exc, queue.Full):  # pyserial's loop:// raises this when its buffer is full
        return True
    try:
        import serial

        return isinstance(exc, serial.SerialTimeoutException)
    except ImportError:
        return False


class SerialLink:
    """Stream pose frames to a serial port from a background thread (see the module docstring).

    on_status(LinkStatus) is called from the link's thread on every state change and error;
    on_receive(item) for every line decoded from the port (a ControllerCommand; over ``loop://``
    also the link's own frames and answers coming back). on_tick() about every POLL_S while the
    port is open (command timeouts). Callbacks must be quick; a Qt app forwards them by signal.
    on_sent(frame_bytes, seconds_since_publish) after each frame written.
    ``opener`` makes a port from the settings (default: pyserial; tests pass fakes).
    ``first_seq`` is the seq of the first frame written.
    """

    POLL_S = 0.02  # how often the thread reads incoming bytes when nothing is published

    def __init__(
        self,
        settings: SerialLinkSettings,
        *,
        on_status: Callable[[LinkStatus], None] | None = None,
        on_receive: Callable[[Decoded], None] | None = None,
        on_sent: Callable[[bytes, float], None] | None = None,
        opener: Callable[[SerialLinkSettings], PortLike] | None = None,
        first_seq: int = 0,
        on_tick: Callable[[], None] | None = None,
    ) -> None:
        self.settings = validated(settings)
        if not self.settings.port:
            raise ValueError("SerialLinkSettings.port is empty: give a device path or loop://")
        if not 0 <= first_seq < SEQ_MODULUS:
            raise ValueError(f"first_seq must be in 0..{SEQ_MODULUS - 1}, got {first_seq}")
        self._on_status = on_status
        self._on_receive = on_receive
        self._on_sent = on_sent
        self._on_tick = on_tick
        self._opener = opener or open_pyserial
        self._answers: list[bytes] = []
        self._streaming = True
        self._source_down = False
        self._nosrc_due = 0.0
        self._clock: tuple[int, float] | None = None  # (t_ms, monotonic s) of the last publish
        self._ever_connected = False
        self._seq = first_seq
        self._lock = threading.Condition()
        # The newest pose not yet written: a newer one replaces it (frames_dropped). It shares the
        # link's condition: the thread waits for a pose, an answer, NOSRC's time or a stop at once.
        self._pose: Mailbox[_Pending] = Mailbox(self._lock)
        self._last_frame: _Pending | None = None
        self._stop = False
        self._thread: threading.Thread | None = None
        self._port: PortLike | None = None
        self._decoder = FrameDecoder()
        self._t0 = time.monotonic()
        self._state = CONNECTING
        self._counts = {
            "frames_sent": 0,
            "frames_dropped": 0,  # lost to a write timeout (the superseded ones: self._pose.dropped)
            "errors": 0,
            "reconnects": 0,
            "answers_sent": 0,
        }
        self._last_error = ""
        self._last_sent = ""

    # ----- the frame loop's side -------------------------------------------------------------
    def start(self) -> SerialLink:
        """Start the link's thread (it opens the port); returns self. Idempotent."""
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
        """Milliseconds since the link was made: a t_ms for callers without their own clock."""
        return int((time.monotonic() - self._t0) * 1000) % T_MS_MODULUS

    def publish(
        self,
        t_ms: int | float | None,
        position_mm: Sequence[float] | np.ndarray | None,
        angles_deg: Sequence[float] | np.ndarray | None,
        status: str = WireStatus.OK,
    ) -> bool:
        """Hand the newest pose to the link; returns at once and never blocks on the port.

        t_ms: capture time in ms since the stream started (None: :meth:`stream_time_ms`; floats are
        rounded; wraps at 2**32). position_mm (x, y, z, camera frame, mm) and angles_deg (alpha,
        beta, gamma, degrees) as for :func:`encode_frame`. Returns False once the link is closed.
        Raises FrameError (ValueError) on misuse (unknown status, wrong shapes, pose given or missing
        against the status), so the mistake shows at the call site. A pose of the right shape with a
        non-finite or out-of-range value is data, not misuse: it goes out as NOCONV with empty fields,
        and ``errors`` / ``last_error`` say why (the frame loop goes on).
        """
        try:
            position, angles = check_pose_fields(status, position_mm, angles_deg)
        except PoseValueError as exc:
            self._error(f"pose at t_ms={t_ms} sent as NOCONV: {exc}")
            position, angles, status = None, None, WireStatus.NOCONV
        if t_ms is None:
            t = self.stream_time_ms()
        else:
            try:
                value = float(t_ms)
            except (TypeError, ValueError):
                value = math.nan
            if isinstance(t_ms, bool) or not math.isfinite(value) or value < 0:
                raise ValueError(f"t_ms must be a finite number of ms >= 0, got {t_ms!r}")
            t = round(value) % T_MS_MODULUS
        item = _Pending(t, position, angles, status, time.perf_counter())
        with self._lock:
            if self._stop:
                return False
            self._clock = (t, time.monotonic())
            if not self._streaming:
                return True  # the controller asked for no $QRF lines
            self._pose.put(item)
        return True

    def send_line(self, line: bytes) -> bool:
        """Write one complete line (an answer to the controller) as soon as the port allows, ahead
        of any pose; never blocks. False once the link is closed."""
        with self._lock:
            if self._stop:
                return False
            self._answers = [*self._answers[-(MAX_ANSWERS - 1) :], bytes(line)]
            self._lock.notify()
        return True

    def set_streaming(self, on: bool) -> None:
        """Start or stop the $QRF lines (poses, STALE and NOSRC alike); answers still go out."""
        with self._lock:
            self._streaming = bool(on)
            if not on:
                self._pose.clear()
                self._last_frame = None  # nothing to repeat as STALE once the stream resumes
            self._lock.notify()

    def set_source_down(self, down: bool) -> None:
        """``down``: the frame loop has no camera frames; NOSRC goes out every NOSRC_INTERVAL_S,
        the first one at once, until the source is up again."""
        with self._lock:
            if down and not self._source_down:
                self._nosrc_due = 0.0
            self._source_down = bool(down)
            self._lock.notify()

    def _now_t_ms(self) -> int:
        """The stream's clock now: the last published t_ms plus the time since, else our own clock."""
        if self._clock is None:
            return self.stream_time_ms()
        t_ms, at = self._clock
        return int(t_ms + (time.monotonic() - at) * 1000.0) % T_MS_MODULUS

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
        """Write the newest pose still waiting (if connected), stop the thread (joined up to
        ``timeout`` s) and close the port; state becomes closed."""
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
        return LinkStatus(
            state=self._state,
            port=self.settings.port,
            last_error=self._last_error,
            pending=1 if self._pose.full else 0,
            received=self._decoder.counters.as_dict(),
            last_sent=self._last_sent,
            ever_connected=self._ever_connected,
            streaming=self._streaming,
            source_down=self._source_down,
            **{**self._counts, "frames_dropped": self._counts["frames_dropped"] + self._pose.dropped},
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

    def _try_open(self) -> bool:
        try:
            self._port = self._opener(self.settings)
        except Exception as exc:
            self._port = None
            self._error(f"cannot open {self.settings.port}: {exc}")
            return False
        self._decoder.discard_partial()  # a line cut by the reconnect must not join the next one
        with self._lock:
            self._ever_connected = True
        self._set_state(CONNECTED)
        return True

    def _lose_port(self, exc: BaseException, doing: str) -> None:
        self._close_port()
        self._error(f"{doing} {self.settings.port} failed: {exc}")
        self._set_state(DISCONNECTED)

    def _run(self) -> None:
        interval = 1.0 / self.settings.max_rate_hz
        stale_after = self.settings.stale_after_s
        next_send = 0.0  # monotonic time before which no frame is written (rate limit)
        next_open = 0.0  # monotonic time of the next attempt to open the port
        last_sent = time.monotonic()
        ever_connected = False
        while True:
            if self._port is None:
                now = time.monotonic()
                if now >= next_open:
                    if self._try_open():
                        if ever_connected:
                            with self._lock:
                                self._counts["reconnects"] += 1
                        ever_connected = True
                    else:
                        next_open = now + self.settings.reconnect_interval_s
                        self._set_state(DISCONNECTED)
                if self._port is None:
                    with self._lock:
                        if self._stop:
                            break
                        self._lock.wait(max(0.001, next_open - time.monotonic()))
                    continue
            # Connected: write the newest pose when the rate allows, a STALE repeat when nothing new
            # came for stale_after, else wait for a pose (or the next poll of incoming bytes).
            item: _Pending | None = None
            is_stale = False
            with self._lock:
                stopping = self._stop
                if stopping:
                    # Closing: the newest pose not yet written still goes out, once, rate limit or
                    # not (a run that stops right after its last frame must not lose that pose).
                    item = self._pose.take()
            if stopping:
                self._write_answers()
                if item is not None:
                    self._write(item, False)  # once: a failed write is not retried while closing
                break
            self._write_answers()
            if self._port is None:  # lost while answering
                next_open = time.monotonic() + self.settings.reconnect_interval_s
                continue
            with self._lock:
                now = time.monotonic()
                down = self._source_down and self._streaming
                stale_due = (
                    last_sent + stale_after
                    if stale_after > 0 and self._last_frame is not None and not down
                    else None
                )
                waiting = self._pose.full
                if waiting and now >= next_send:
                    item = self._pose.take()
                elif down and not waiting and now >= self._nosrc_due:
                    item = _Pending(self._now_t_ms(), None, None, WireStatus.NOSRC, time.perf_counter())
                    self._nosrc_due = now + NOSRC_INTERVAL_S
                elif not waiting and stale_due is not None and now >= max(stale_due, next_send):
                    item, is_stale = self._last_frame, True
                else:
                    wake = now + self.POLL_S
                    if waiting:
                        wake = min(wake, next_send)
                    elif stale_due is not None:
                        wake = min(wake, max(stale_due, next_send))
                    self._lock.wait(max(0.001, wake - now))
            if item is not None:
                next_send = time.monotonic() + interval
                self._write(item, is_stale)
                last_sent = time.monotonic()
            self._read_incoming()
            if self._port is None:
                next_open = time.monotonic() + self.settings.reconnect_interval_s
            elif self._on_tick is not None:
                try:
                    self._on_tick()
                except Exception as exc:  # a faulty callback must not stop the link
                    self._error(f"tick callback failed: {exc!r}", notify=False)
        self._close_port()
        self._set_state(CLOSED)

    def _write_answers(self) -> None:
        """Write the waiting answers, oldest first (a lost port keeps the rest for the next one)."""
        while self._port is not None:
            with self._lock:
                if not self._answers:
                    return
                line = self._answers.pop(0)
            try:
                self._port.write(line)
            except Exception as exc:
                if _is_write_timeout(exc):
                    self._error(f"answer to the controller timed out: {exc!r}")
                    continue
                self._lose_port(exc, "writing to")
                return
            with self._lock:
                self._counts["answers_sent"] += 1

    def _write(self, item: _Pending, is_stale: bool) -> None:
        try:
            frame = encode_frame(
                self._seq,
                item.t_ms,
                item.position,
                item.angles,
                WireStatus.STALE if is_stale else item.status,
            )
        except ValueError as exc:  # publish() validated already; never let the thread die
            self._error(f"cannot encode frame: {exc}")
            return
        port = self._port
        assert port is not None
        try:
            port.write(frame)
        except Exception as exc:
            if _is_write_timeout(exc):
                with self._lock:
                    self._counts["frames_dropped"] += 1
                self._error(f"write to {self.settings.port} timed out: {exc!r}")
                return
            self._lose_port(exc, "writing to")
            if not is_stale:  # not sent: offer it again after reconnecting unless a newer pose came
                self._pose.put_if_empty(item)
            return
        sent_at = time.perf_counter()
        with self._lock:
            self._seq = (self._seq + 1) % SEQ_MODULUS
            self._counts["frames_sent"] += 1
            self._last_sent = frame.decode("ascii").rstrip()
            if not is_stale:
                self._last_frame = item
        if self._on_sent is not None:
            with contextlib.suppress(Exception):
                self._on_sent(frame, sent_at - item.published_at)

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

    The status goes out by the one rule of :mod:`qrfield.status` (``reported_status`` then
    ``wire_status``): ERROR and unknown statuses as NOCONV with empty pose fields; a pose carries its
    first method's position (mm) and angles (degrees), as OK only when ``simulated`` is False (the
    frame came from a live camera: :func:`qrfield.sources.is_live_camera`), else as SIM. Returns
    what :meth:`SerialLink.publish` returns (False once the link is closed).
    """
    try:
        status = wire_status(reported_status(getattr(result, "status", ""), live=not simulated))
    except ValueError:
        status = WireStatus.NOCONV
    pose = getattr(result, "primary", None)
    t_ms = getattr(result, "t_ms", None)
    if status not in (WireStatus.OK, WireStatus.SIM) or not usable_pose(pose):
        empty = WireStatus.NOQR if status == WireStatus.NOQR else WireStatus.NOCONV
        return link.publish(t_ms, None, None, empty)
    return link.publish(t_ms, pose.position_mm, pose.angles_deg, status)
