"""The gripper controller's side of the serial link: pose frames out, commands in, answers back.

:class:`GripperLink` is what a frame loop publishes to (``qrfield run --serial`` and the app's
Serial tab alike): a :class:`~qrfield.serial_link.SerialLink` that streams each result as a $QRF
line (OK only from a live camera, else SIM; NOSRC while the source is down) and a
:class:`CommandHandler` that answers the controller's ``$QRC`` commands on the same port
(docs/conventions.md):

- ``PING`` -> ``$QRA,PING,OK``;
- ``STREAM,ON`` / ``STREAM,OFF`` -> ``$QRA,STREAM,OK``: starts or stops the $QRF lines;
- ``MEAS,<n>`` (n = 1..100) -> ``$QRM,...``: the mean of the next n frames whose first method
  converged (positions arithmetic, angles circular means, standard deviations over the frames,
  all by :func:`qrfield.sessions.averaging.average_frames`, the sessions' own averaging), or why
  there is none when they are not in within 2 s + n / 5 s;
- anything else -> ``$QRA,<command>,ERR,<reason>``.

Our decisions where the conventions leave room: the $QRM ``seq`` counts the $QRM answers (0, 1, ...;
the $QRF seq stays gap-free for the frames); its ``t_ms`` is the capture time of the last frame
averaged (of the last frame seen for a failure; 0 before any); with one frame the deviations are 0.0
(a spread needs two frames); a MEAS while another is collecting is answered ``ERR,busy``; a failed
MEAS says NOSRC when the source was down at the deadline, else the status of the last frame seen
(NOQR or NOCONV) when no frame converged, else TIMEOUT (no frames, or fewer than n converged).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from qrfield.serial_frames import (
    COMMAND_TALKER,
    SEQ_MODULUS,
    T_MS_MODULUS,
    ControllerCommand,
    FrameError,
    encode_answer,
    encode_measurement,
)
from qrfield.serial_link import LinkStatus, SerialLink, SerialLinkSettings, publish_result
from qrfield.status import WireStatus, pose_reported, reported_status, usable_pose, wire_status

#: MEAS takes 1..MAX_MEAS_FRAMES frames.
MAX_MEAS_FRAMES = 100
#: A MEAS not complete after MEAS_BASE_S + n * MEAS_PER_FRAME_S seconds is answered TIMEOUT.
MEAS_BASE_S = 2.0
MEAS_PER_FRAME_S = 0.2


def meas_timeout_s(n: int) -> float:
    """docs/conventions.md: n converged frames within 2 s + n / 5 s."""
    return MEAS_BASE_S + n * MEAS_PER_FRAME_S


@dataclass
class _Meas:
    n: int
    deadline: float
    poses: list[Any] = field(default_factory=list)
    simulated: bool = False
    last_t_ms: int | None = None
    last_status: str = ""
    frames_seen: int = 0


class CommandHandler:
    """Answers $QRC commands (see the module docstring); no I/O of its own.

    ``send(line)`` writes an answer line; ``set_streaming(on)`` starts or stops the $QRF lines.
    :meth:`handle` is called with each decoded item (the link's thread), :meth:`on_result` with each
    frame result (the frame loop's thread), :meth:`poll` often (times MEAS out). Thread-safe.
    """

    def __init__(
        self,
        send: Callable[[bytes], Any],
        set_streaming: Callable[[bool], Any],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._send = send
        self._set_streaming = set_streaming
        self._clock = clock
        self._lock = threading.Lock()
        self._meas: _Meas | None = None
        self._seq = 0
        self._source_down = False
        self._last_t_ms = 0
        self.handled = 0

    # ----- the link's thread
    def handle(self, item: Any) -> None:
        """Act on one decoded line; lines of other talkers (our own echoes over loop://) are ignored."""
        if not isinstance(item, ControllerCommand) or item.talker != COMMAND_TALKER:
            return
        self.handled += 1
        name = item.fields[0].strip().upper() if item.fields else ""
        args = item.fields[1:]
        command = name[:16] or "?"
        if name == "PING" and not args:
            self._send(encode_answer("PING"))
        elif name == "STREAM":
            if len(args) == 1 and args[0].strip().upper() in ("ON", "OFF"):
                self._set_streaming(args[0].strip().upper() == "ON")
                self._send(encode_answer("STREAM"))
            else:
                self._send(encode_answer("STREAM", "ERR", "give STREAM ON or OFF"))
        elif name == "MEAS":
            self._start_meas(args)
        elif not name:
            self._send(encode_answer(command, "ERR", "empty command"))
        else:
            self._send(encode_answer(command, "ERR", "unknown command (PING STREAM MEAS)"))

    def _start_meas(self, args: tuple[str, ...]) -> None:
        text = args[0].strip() if len(args) == 1 else ""
        if not text.isdigit() or not 1 <= int(text) <= MAX_MEAS_FRAMES:
            self._send(encode_answer("MEAS", "ERR", f"give MEAS n with n 1..{MAX_MEAS_FRAMES}"))
            return
        n = int(text)
        with self._lock:
            if self._meas is not None:
                busy = True
            else:
                busy = False
                self._meas = _Meas(n, self._clock() + meas_timeout_s(n))
        if busy:
            self._send(encode_answer("MEAS", "ERR", "busy: a MEAS is collecting"))

    def poll(self) -> None:
        """Answer a MEAS whose deadline has passed."""
        with self._lock:
            meas = self._meas
            if meas is None or self._clock() < meas.deadline:
                return
            self._meas = None
            if self._source_down:
                status = WireStatus.NOSRC
            elif not meas.poses and meas.last_status in (WireStatus.NOQR, WireStatus.NOCONV):
                status = meas.last_status
            else:
                status = WireStatus.TIMEOUT
            line = self._failure(status, meas)
        self._send(line)

    # ----- the frame loop's thread
    def on_result(self, result: Any, simulated: bool) -> None:
        """One frame result (qrfield.pipeline.FrameResult) of a source; ``simulated``: not a live camera."""
        line = None
        with self._lock:
            t_ms = getattr(result, "t_ms", None)
            if isinstance(t_ms, int):
                self._last_t_ms = t_ms % T_MS_MODULUS
            meas = self._meas
            if meas is None:
                return
            meas.frames_seen += 1
            meas.last_t_ms = self._last_t_ms
            try:
                meas.last_status = wire_status(reported_status(getattr(result, "status", ""), live=True))
            except ValueError:
                meas.last_status = WireStatus.NOCONV
            pose = getattr(result, "primary", None)
            if meas.last_status == WireStatus.OK and usable_pose(pose):
                meas.poses.append(pose)
                meas.simulated = meas.simulated or simulated
            if len(meas.poses) >= meas.n:
                self._meas = None
                line = self._answer(meas)
        if line is not None:
            self._send(line)

    def on_source_down(self) -> None:
        with self._lock:
            self._source_down = True

    def on_source_up(self) -> None:
        with self._lock:
            self._source_down = False

    # ----- answers (called with the lock held)
    def _next_seq(self) -> int:
        seq, self._seq = self._seq, (self._seq + 1) % SEQ_MODULUS
        return seq

    def _failure(self, status: str, meas: _Meas) -> bytes:
        t_ms = meas.last_t_ms if meas.last_t_ms is not None else self._last_t_ms
        return encode_measurement(self._next_seq(), t_ms, status)

    def _answer(self, meas: _Meas) -> bytes:
        from qrfield.sessions.averaging import average_frames

        average = average_frames(meas.poses)
        std_pos = np.nan_to_num(average.std_position_mm, nan=0.0)  # one frame: no spread to give
        std_ang = np.nan_to_num(average.std_angles_deg, nan=0.0)
        status = wire_status(pose_reported(live=not meas.simulated))
        try:
            return encode_measurement(
                self._next_seq(),
                meas.last_t_ms or 0,
                status,
                average.position_mm,
                average.angles_deg,
                std_pos,
                std_ang,
                average.n_converged,
            )
        except FrameError:  # a mean beyond the frame's limits (absurd numbers): no pose to give
            return self._failure(WireStatus.NOCONV, meas)


class GripperLink:
    """A serial link to the gripper controller with its command protocol; a frame loop's sink.

    ``start()`` opens the port on the link's thread; :meth:`on_result`, :meth:`on_source_down` and
    :meth:`on_source_up` are called by the frame loop and never block; ``close()`` stops it.
    ``on_status`` and ``opener`` go to :class:`~qrfield.serial_link.SerialLink`.
    """

    def __init__(
        self,
        settings: SerialLinkSettings,
        *,
        on_status: Callable[[LinkStatus], None] | None = None,
        opener: Any = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.commands = CommandHandler(self._send, self._set_streaming, clock)
        self.link = SerialLink(
            settings,
            on_status=on_status,
            on_receive=self.commands.handle,
            on_tick=self.commands.poll,
            opener=opener,
        )

    def _send(self, line: bytes) -> None:
        self.link.send_line(line)

    def _set_streaming(self, on: bool) -> None:
        self.link.set_streaming(on)

    @property
    def settings(self) -> SerialLinkSettings:
        return self.link.settings

    def start(self) -> GripperLink:
        self.link.start()
        return self

    def close(self, timeout: float = 2.0) -> None:
        self.link.close(timeout)

    def status(self) -> LinkStatus:
        return self.link.status()

    def wait_for_state(self, state: str, timeout: float) -> bool:
        return self.link.wait_for_state(state, timeout)

    # ----- the frame loop's sink
    def on_result(self, result: Any, simulated: bool) -> bool:
        """Publish one frame result (SIM unless ``simulated`` is False) and feed a running MEAS."""
        self.commands.on_result(result, simulated)
        return publish_result(self.link, result, simulated)

    def on_source_down(self, reason: str = "") -> None:
        self.link.set_source_down(True)
        self.commands.on_source_down()

    def on_source_up(self) -> None:
        self.link.set_source_down(False)
        self.commands.on_source_up()
