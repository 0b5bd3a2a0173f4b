"""The gripper controller's commands, answered in order, and the frame loop's sink that streams poses.

:class:`GripperLink` is what a frame loop publishes to (``qrfield run --serial``, the app's Serial
tab, ``qrfield serial-demo``): a :class:`~qrfield.serial.link.SerialLink` streaming each result as a
``$QRF`` line (OK only for an unambiguous pose from a live camera, AMBIG for an ambiguous one, SIM
from any other source; NOSRC while the source is down) and a :class:`CommandHandler` answering the
controller's ``$QRC`` commands on the same port, one answer per command, in order
(docs/conventions.md, "Serial protocol 2"):

- ``PING`` -> ``$QRA,PING,OK``;
- ``HELLO`` -> ``$QRA,HELLO,QRF2,<version>,<side_mm>,<camera model>,<frame>`` (frame: camera,
  tool or base: the frame of the ``$QRF`` and ``$QRM`` poses, :meth:`GripperLink.set_pose_frame`);
- ``STREAM,ON`` / ``STREAM,OFF`` -> ``$QRA,STREAM,OK``; ``RATE,<hz>`` -> ``$QRA,RATE,OK,<hz>``;
- ``MEAS,<n>`` -> ``$QRM,...``: the mean of the next n frames with a converged pose and its
  standard uncertainty of the mean (:func:`qrfield.sessions.averaging.average_frames`), or why there
  is none when they are not in within 2 s + n / 5 s;
- ``TOOL`` and ``HANDEYE``: hand-eye pairs and their solve once :meth:`GripperLink.add_handeye` put
  :class:`qrfield.serial.handeye.HandEyeCommands` in :attr:`CommandHandler.handlers` (else ``ERR``);
- anything else -> ``$QRA,<command>,ERR,<reason>``; a line that cannot be read (CRC, length,
  format) -> ``$QRA,?,ERR,CRC`` (or ``LENGTH``, ``FORMAT``); more than 16 commands waiting -> the
  newest are discarded and ``$QRA,?,ERR,OVERFLOW,<n>`` follows once the queue drains.

The commands wait in one queue: a MEAS holds the commands after it until its answer is out (one
answer per command, in order). Our decisions where the conventions leave room: commands are
accepted in any case (``ping``); the ``$QRM`` seq counts the measurements (0, 1, ...); its t_ms is
the capture time of the last frame averaged (of the last frame seen for a failure); a MEAS fails
with NOSRC when the source is down at its deadline (or the link closes first), else with the
status of the last frame seen (NOQR or NOCONV) when no frame converged, else TIMEOUT; a MEAS over
frames of which any is from a source other than a live camera is SIM, else AMBIG when any frame's
flip was unresolved.
"""

from __future__ import annotations

import collections
import dataclasses
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from qrfield.handeye.frames import InFrame, PoseFrame
from qrfield.handeye.setups import CAMERA
from qrfield.seams import BaseSink
from qrfield.serial import codec
from qrfield.serial.link import LinkStatus, SerialLink, SerialLinkSettings, publish_result
from qrfield.status import ResultStatus, WireStatus, pose_reported, usable_pose, wire_status

#: MEAS takes 1..MAX_MEAS_FRAMES frames.
MAX_MEAS_FRAMES = 100
#: A MEAS not complete after MEAS_BASE_S + n * MEAS_PER_FRAME_S seconds is answered TIMEOUT.
MEAS_BASE_S = 2.0
MEAS_PER_FRAME_S = 0.2
#: More commands than this waiting (queued or answered but not yet written): the newest are discarded.
MAX_WAITING = 16
#: The camera frame (qrfield.handeye.CAMERA): HELLO's frame when poses are reported as measured.
CAMERA_FRAME = CAMERA
_RATE = re.compile(r"(?:0|[1-9][0-9]{0,3})(?:\.[0-9]{1,3})?")


def meas_timeout_s(n: int) -> float:
    """docs/conventions.md: n converged frames within 2 s + n / 5 s."""
    return MEAS_BASE_S + n * MEAS_PER_FRAME_S


class LinkControl(Protocol):
    """What the commands need of the link (a :class:`SerialLink`; tests pass a fake)."""

    def send_line(self, line: bytes) -> bool: ...
    def set_streaming(self, on: bool) -> None: ...
    def set_rate(self, hz: float) -> None: ...
    def answers_waiting(self) -> int: ...


@dataclass
class Command:
    """One command from the controller: its name as answered (upper case, ``?`` for a line that
    could not be read), its arguments and the text received."""

    name: str
    args: tuple[str, ...]
    text: str


#: A command's handler: called once with the command and ``reply``, which it calls exactly once
#: with the answer line, at once or later from any thread (MEAS: when its frames are in).
Handler = Callable[[Command, Callable[[bytes], None]], None]


@dataclass
class _Meas:
    n: int
    deadline: float
    reply: Callable[[bytes], None]
    frames: list[Any] = field(default_factory=list)
    simulated: bool = False
    ambiguous: bool = False
    last_t_ms: int | None = None
    last_status: str = ""


@dataclass
class Context:
    """What HELLO reports: the QR side (mm), the camera model's name, the frame of the poses."""

    side_mm: float | None = None
    camera: str = ""
    frame: str = CAMERA_FRAME


class CommandHandler:
    """Answers the controller's commands in order (see the module docstring); no I/O of its own.

    :meth:`handle` takes each item the link decodes (the link's thread), :meth:`on_result` each frame
    result (the frame loop's thread: :meth:`notify` then :meth:`measure`), :meth:`poll` runs often
    (MEAS deadlines, then each of ``pollers``). ``handlers`` maps a command's name to its
    :data:`Handler` (hand-eye puts TOOL and HANDEYE there), ``frame_listeners`` receives
    ``(result, simulated)`` for every frame (in the camera frame: :class:`GripperLink` calls
    :meth:`notify` before it takes poses into the tool or base frame). Thread-safe.
    """

    def __init__(self, link: LinkControl, clock: Callable[[], float] = time.monotonic) -> None:
        self.link = link
        self._clock = clock
        self._lock = threading.RLock()
        self._queue: collections.deque[Command] = collections.deque()
        self._running: Command | None = None
        self._advancing = False
        self._discarded = 0
        self._meas: _Meas | None = None
        self._seq = 0
        self._source_down = False
        self._last_t_ms = 0
        self.context = Context()
        self.handled = 0
        self.last_command = ""
        self.frame_listeners: list[Callable[[Any, bool], None]] = []
        self.pollers: list[Callable[[], None]] = []
        self.closers: list[Callable[[], None]] = []  # answer what waits for frames, closing (TOOL)
        self.handlers: dict[str, Handler] = {
            "PING": self._ping,
            "HELLO": self._hello,
            "STREAM": self._stream,
            "RATE": self._rate,
            "MEAS": self._start_meas,
            "TOOL": self._not_available,
            "HANDEYE": self._not_available,
            codec.UNKNOWN_COMMAND: self._unreadable,
        }

    # ----- the link's thread
    def handle(self, item: Any) -> None:
        """Queue one decoded item: a $QRC command, or a line that could not be read; lines of other
        talkers (our own lines echoed by loop://) are ignored."""
        if isinstance(item, codec.RejectedLine):
            command = Command(codec.UNKNOWN_COMMAND, (item.reason,), item.text.decode("ascii", "replace"))
        elif isinstance(item, codec.ControllerCommand) and item.talker == codec.COMMAND_TALKER:
            name = item.fields[0] if item.fields else ""
            command = Command(
                codec.answer_command(name) if name.strip() else codec.UNKNOWN_COMMAND,
                tuple(item.fields[1:]) if name.strip() else ("empty command",),
                ",".join(item.fields),
            )
        else:
            return
        with self._lock:
            self.handled += 1
            if len(self._queue) + self.link.answers_waiting() >= MAX_WAITING:
                self._discarded += 1  # said by _advance once nothing of ours waits
            else:
                self._queue.append(command)
        self._advance()

    def poll(self) -> None:
        """Answer a MEAS whose deadline has passed; then run each of ``pollers`` (other deadlines)."""
        self._poll_meas()
        for poller in list(self.pollers):
            poller()

    def _poll_meas(self) -> None:
        with self._lock:
            meas = self._meas
            if meas is None or self._clock() < meas.deadline:
                return
            self._meas = None
            if self._source_down:
                status = WireStatus.NOSRC
            elif not meas.frames and meas.last_status in (WireStatus.NOQR, WireStatus.NOCONV):
                status = WireStatus(meas.last_status)
            else:
                status = WireStatus.TIMEOUT
            t_ms = meas.last_t_ms if meas.last_t_ms is not None else self._last_t_ms
            line = codec.encode_measurement(self._next_seq(), t_ms, status)
        meas.reply(line)

    # ----- the queue
    def _advance(self) -> None:
        """Run the commands at the head of the queue until one is deferred (MEAS) or none is left."""
        with self._lock:
            if self._advancing:
                return  # the loop below, further up this thread's stack, goes on
            self._advancing = True
        while True:
            with self._lock:
                if self._running is not None or not self._queue:
                    if self._running is None and self._discarded:
                        n, self._discarded = self._discarded, 0
                        self.link.send_line(codec.encode_error(codec.UNKNOWN_COMMAND, "OVERFLOW", str(n)))
                    self._advancing = False
                    return
                command = self._queue[0]
                self._running = command
            handler = self.handlers.get(command.name, self._unknown)
            try:
                handler(command, lambda line, c=command: self._reply(c, line))
            except Exception as exc:  # a faulty handler still answers, and the queue goes on
                self._reply(command, codec.encode_error(command.name, f"failed: {type(exc).__name__}"))

    def _reply(self, command: Command, line: bytes) -> None:
        with self._lock:
            if self._running is not command:
                return  # answered already
            self._queue.popleft()
            self._running = None
            self.last_command = (
                f"{command.text[:40]} -> {line.decode('ascii', 'replace').split('*')[0][1:][:60]}"
            )
            self.link.send_line(line)
        self._advance()

    # ----- the commands
    def _no_args(self, command: Command, reply: Callable[[bytes], None]) -> bool:
        if command.args:
            reply(codec.encode_error(command.name, f"{command.name} takes no argument"))
            return False
        return True

    def _ping(self, command: Command, reply: Callable[[bytes], None]) -> None:
        if self._no_args(command, reply):
            reply(codec.encode_ok("PING"))

    def _hello(self, command: Command, reply: Callable[[bytes], None]) -> None:
        if not self._no_args(command, reply):
            return
        from qrfield import __version__

        c = self.context
        side = "" if c.side_mm is None else f"{c.side_mm:.1f}"
        reply(
            codec.encode_answer(
                "HELLO",
                codec.PROTOCOL,
                codec.field_text(__version__),
                side,
                codec.field_text(c.camera),
                c.frame,
            )
        )

    def _stream(self, command: Command, reply: Callable[[bytes], None]) -> None:
        word = command.args[0].strip().upper() if len(command.args) == 1 else ""
        if word not in ("ON", "OFF"):
            reply(codec.encode_error("STREAM", "give STREAM ON or OFF"))
            return
        self.link.set_streaming(word == "ON")
        reply(codec.encode_ok("STREAM"))

    def _rate(self, command: Command, reply: Callable[[bytes], None]) -> None:
        text = command.args[0] if len(command.args) == 1 else ""
        hz = float(text) if _RATE.fullmatch(text) else -1.0
        if not (hz == 0 or 0.1 <= hz <= 1000):
            reply(codec.encode_error("RATE", "give RATE hz with hz 0 or 0.1..1000"))
            return
        self.link.set_rate(hz)
        reply(codec.encode_ok("RATE", f"{hz:g}"))

    def _not_available(self, command: Command, reply: Callable[[bytes], None]) -> None:
        reply(codec.encode_error(command.name, "hand-eye calibration not available"))

    def _unreadable(self, command: Command, reply: Callable[[bytes], None]) -> None:
        reply(codec.encode_error(codec.UNKNOWN_COMMAND, command.args[0] if command.args else "FORMAT"))

    def _unknown(self, command: Command, reply: Callable[[bytes], None]) -> None:
        reply(codec.encode_error(command.name, "unknown command"))

    def _start_meas(self, command: Command, reply: Callable[[bytes], None]) -> None:
        text = command.args[0].strip() if len(command.args) == 1 else ""
        if not (text.isdigit() and 1 <= int(text) <= MAX_MEAS_FRAMES):
            reply(codec.encode_error("MEAS", f"give MEAS n with n 1..{MAX_MEAS_FRAMES}"))
            return
        n = int(text)
        with self._lock:
            self._meas = _Meas(n, self._clock() + meas_timeout_s(n), reply)

    # ----- the frame loop's thread
    def on_result(self, result: Any, simulated: bool) -> None:
        """One frame result (qrfield.pipeline.FrameResult) of a source; ``simulated``: not a live
        camera. :meth:`notify` and :meth:`measure` with the same result."""
        self.notify(result, simulated)
        self.measure(result, simulated)

    def notify(self, result: Any, simulated: bool) -> None:
        """Hand one frame result to each of ``frame_listeners``."""
        for listener in list(self.frame_listeners):
            listener(result, simulated)

    def measure(self, result: Any, simulated: bool) -> None:
        """Feed one frame result (in the frame the poses are reported in) to a running MEAS; one
        whose deadline has passed is answered first (:meth:`poll` runs only while the port is open:
        a late frame must not complete it)."""
        self._poll_meas()
        done = None
        with self._lock:
            t_ms = getattr(result, "t_ms", None)
            if isinstance(t_ms, int):
                self._last_t_ms = t_ms % codec.T_MS_MODULUS
            meas = self._meas
            if meas is None:
                return
            meas.last_t_ms = self._last_t_ms
            status = str(getattr(result, "status", ""))
            pose = getattr(result, "primary", None)
            try:
                meas.last_status = wire_status(status) if status != ResultStatus.OK else WireStatus.OK
            except ValueError:
                meas.last_status = WireStatus.NOCONV
            if status == ResultStatus.OK and usable_pose(pose):
                # A pipeline FrameResult itself, so that the mean knows which frames the stream
                # filter made (their sigma is then the mean's: qrfield.sessions.averaging).
                meas.frames.append(result if hasattr(result, "poses") else pose)
                meas.simulated = meas.simulated or simulated
                meas.ambiguous = meas.ambiguous or bool(getattr(result, "ambiguous", False))
            if len(meas.frames) >= meas.n:
                self._meas = None
                done = (meas, self._answer(meas))
        if done is not None:
            done[0].reply(done[1])

    def finish(self) -> None:
        """Closing (the run ends, the source is gone): a MEAS under way is answered NOSRC at once
        and each of ``closers`` answers what it keeps waiting for frames (a TOOL), so each command
        still gets its answer; the commands queued behind them then run and are answered so too.
        At most MAX_WAITING + 1 rounds."""
        for _ in range(MAX_WAITING + 1):
            with self._lock:
                meas, self._meas = self._meas, None
                if meas is not None:
                    t_ms = meas.last_t_ms if meas.last_t_ms is not None else self._last_t_ms
                    line = codec.encode_measurement(self._next_seq(), t_ms, WireStatus.NOSRC)
            if meas is not None:
                meas.reply(line)
            for closer in list(self.closers):
                closer()
            with self._lock:
                if self._running is None:  # every command answered
                    return

    def on_source_down(self) -> None:
        with self._lock:
            self._source_down = True

    def on_source_up(self) -> None:
        with self._lock:
            self._source_down = False

    def _next_seq(self) -> int:
        seq, self._seq = self._seq, (self._seq + 1) % codec.SEQ_MODULUS
        return seq

    def _answer(self, meas: _Meas) -> bytes:
        from qrfield.sessions.averaging import average_frames

        average = average_frames(meas.frames)
        status = wire_status(pose_reported(live=not meas.simulated, ambiguous=meas.ambiguous))
        try:
            pose = codec.wire_pose(
                average.position_mm, average.angles_deg, average.sem_position_mm, average.sem_angles_deg
            )
            return codec.encode_measurement(
                self._next_seq(), meas.last_t_ms or 0, status, pose, average.n_converged
            )
        except codec.FrameError:  # a mean beyond the line's limits (absurd numbers): no pose to give
            return codec.encode_measurement(self._next_seq(), meas.last_t_ms or 0, WireStatus.NOCONV)


class _Stream(BaseSink):
    """The link's part of a frame result in the reported frame: a running MEAS and the $QRF line."""

    def __init__(self, commands: CommandHandler, link: SerialLink) -> None:
        self.commands, self.link = commands, link

    def on_result(self, result: Any, simulated: bool) -> bool:
        self.commands.measure(result, simulated)
        return publish_result(self.link, result, simulated)


class GripperLink:
    """A serial link to the gripper controller with its commands; a frame loop's sink.

    ``start()`` opens the port on the link's thread (``open_first``: here, so a busy port raises
    :class:`~qrfield.serial.port.PortBusyError`); :meth:`on_result`, :meth:`on_source_down` and
    :meth:`on_source_up` are called by the frame loop and never block; ``close()`` stops it.
    ``on_status``, ``opener`` and ``clock`` go to :class:`~qrfield.serial.link.SerialLink`.

    ``pose_frame`` (:class:`~qrfield.handeye.PoseFrame`, default the camera frame): the frame of
    the ``$QRF`` and ``$QRM`` poses and their sigmas (through :class:`~qrfield.handeye.InFrame`),
    which HELLO reports; the commands' frame listeners (hand-eye pairs) get the camera's poses.
    """

    def __init__(
        self,
        settings: SerialLinkSettings,
        *,
        on_status: Callable[[LinkStatus], None] | None = None,
        opener: Any = None,
        clock: Callable[[], float] = time.monotonic,
        pose_frame: PoseFrame | None = None,
    ) -> None:
        self.link = SerialLink(
            settings,
            on_status=on_status,
            on_receive=self._receive,
            on_tick=self._tick,
            opener=opener,
            clock=clock,
        )
        self.commands = CommandHandler(self.link, clock)
        self._stream = InFrame(_Stream(self.commands, self.link), pose_frame or PoseFrame())
        self.commands.context.frame = self._stream.pose_frame.frame
        self.handeye: Any = None  # qrfield.serial.handeye.HandEyeCommands, once add_handeye is called

    def _receive(self, item: Any) -> None:
        self.commands.handle(item)

    def _tick(self) -> None:
        self.commands.poll()

    @property
    def settings(self) -> SerialLinkSettings:
        return self.link.settings

    def set_context(
        self, *, side_mm: float | None = None, camera: str = "", frame: str | None = None
    ) -> None:
        """What HELLO reports: QR side (mm), camera model name (the frame is the pose frame's, see
        :meth:`set_pose_frame`; ``frame`` is accepted for compatibility and must be that one)."""
        own = self._stream.pose_frame.frame
        if frame is not None and frame != own:
            raise ValueError(f"frame {frame!r}: the link reports poses in the {own} frame (set_pose_frame)")
        self.commands.context = Context(side_mm, camera, own)

    @property
    def pose_frame(self) -> PoseFrame:
        """The frame of the $QRF and $QRM poses."""
        return self._stream.pose_frame

    def set_pose_frame(self, pose_frame: PoseFrame) -> None:
        """Report the poses of the frames from now on in ``pose_frame`` (any thread); HELLO says its
        frame. A $QRF line already waiting for the port keeps the frame it was made in."""
        self._stream.pose_frame = pose_frame
        self.commands.context = dataclasses.replace(self.commands.context, frame=pose_frame.frame)

    def add_handeye(self, handeye: Any) -> Any:
        """Answer TOOL and HANDEYE with ``handeye`` (:class:`qrfield.serial.handeye.HandEyeCommands`);
        a calibration it makes for the set-up of this link's pose frame replaces that frame's
        calibration at once (docs/serial.md). Returns ``handeye``."""
        handeye.attach(self.commands)
        handeye.calibrated.append(self._calibrated)
        self.handeye = handeye
        return handeye

    def _calibrated(self, done: Any) -> None:
        calibration = done.calibration
        if self.pose_frame.frame == calibration.target_frame:
            self.set_pose_frame(PoseFrame(calibration.target_frame, calibration))

    def start(self, *, open_first: bool = False) -> GripperLink:
        self.link.start(open_first=open_first)
        return self

    def close(self, timeout: float = 2.0) -> None:
        """Stop: a hand-eye solve under way is waited for (its answer goes out), a MEAS under way is
        answered NOSRC (:meth:`CommandHandler.finish`), then the link closes."""
        if self.handeye is not None:
            self.handeye.close(timeout)
        self.commands.finish()  # a MEAS under way is answered NOSRC before the link's last line
        self.link.close(timeout)

    def status(self) -> LinkStatus:
        """The link's status with the last command and its answer."""
        status = self.link.status()
        return LinkStatus(**{**status.__dict__, "last_command": self.commands.last_command})

    def wait_for_state(self, state: str, timeout: float) -> bool:
        return self.link.wait_for_state(state, timeout)

    # ----- the frame loop's sink
    def on_result(self, result: Any, simulated: bool) -> bool:
        """Hand one frame result (camera frame) to the commands' frame listeners, then, in the pose
        frame, feed a running MEAS and publish it (see :func:`~qrfield.serial.link.publish_result`)."""
        self.commands.notify(result, simulated)
        return bool(self._stream.on_result(result, simulated))

    def on_source_down(self, reason: str = "") -> None:
        self.link.set_source_down(True)
        self.commands.on_source_down()

    def on_source_up(self) -> None:
        self.link.set_source_down(False)
        self.commands.on_source_up()
