"""``qrfield run --headless``: measure from a camera source with no window, one pose per frame.

This is how a Raspberry Pi without a monitor runs qrfield: frames come from ``--source``, each
is detected and solved by the core's frame loop (:mod:`qrfield.engine`, the one the app runs), and
one line per frame goes to stdout (JSON lines with ``--json-lines``, else a compact human line).
Notes and errors go to stderr. Settings come from the run configuration the app saves
(:mod:`qrfield.runconfig`; ``qrfield config`` shows them), options override them.

With ``--serial [PORT]`` every pose also goes to the gripper controller as a $QRF line (protocol 2,
docs/serial.md) and its $QRC commands are answered (:mod:`qrfield.serial.controller`): a pose is OK
only unambiguous and from a live camera (AMBIG when its flip is unresolved, SIM from the virtual
bench, a video or a folder), NOSRC goes out while the source is down, after a video or folder ends
and as the last line before the run exits; ``--source auto`` then never falls back to the virtual
bench unless ``--allow-virtual`` is given. The port is opened exclusively: a port another qrfield
(or any program holding its lock) has open is refused at start, naming the other process.

No silent states: an unknown backend, method or setting value, on the command line or in app.json
(the message names the file and the key), stops the run at start with exit code 2.

With ``--frame tool`` or ``--frame base`` (and a hand-eye file, docs/handeye.md) the poses on stdout
and in the serial link's $QRF and $QRM lines are in the gripper's tool frame or the robot's base
frame, their uncertainty with the calibration's added; each JSON line says which in ``pose_frame``
and HELLO reports it. The controller may calibrate over the link: ``$QRC,TOOL`` records pairs,
``$QRC,HANDEYE`` solves for ``--handeye-setup`` (auto: the frame's) and saves the hand-eye file (the
previous one kept); in a ``--frame tool|base`` run both streams take the new calibration at once
(:mod:`qrfield.serial.handeye`). A hand-eye file made from simulated frames is refused with a live
camera.

stdout is best effort: lines are written by a thread of their own, so a reader that stops reading
never holds up the frame loop, the serial line or shutdown (lines it did not take are counted on
stderr). SIGINT (Ctrl-C) and SIGTERM stop the run cleanly after the current frame. Exit codes: 0
done or stopped; 1 the source could not be opened or failed (without ``--retry-s``), or the serial
port could not be opened during the whole run; 2 bad options or settings, or a busy serial port.
No Qt is imported, ever.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from typing import Any

from qrfield.seams import BaseSink, LoopEventsBase

HELP = "measure poses from a camera source without a window (headless; JSON lines for other programs)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count
    from qrfield.runconfig import add_run_arguments

    parser.add_argument(
        "--headless", action="store_true", help="no window (always true for run; accepted for clarity)"
    )
    parser.add_argument(
        "--frames",
        type=count("--frames"),
        default=0,
        metavar="N",
        help="stop after N frames (0 = until stopped)",
    )
    parser.add_argument("--json-lines", action="store_true", help="one JSON object per frame on stdout")
    parser.add_argument(
        "--allow-virtual",
        action="store_true",
        help="with --serial: let --source auto fall back to the virtual bench (its poses go out as SIM)",
    )
    add_run_arguments(parser)


class _Stderr:
    """Messages for humans on stderr."""

    def __call__(self, message: str) -> None:
        print(f"qrfield run: {message}", file=sys.stderr, flush=True)


class _Events(LoopEventsBase):
    """The frame loop's events, said on stderr; a broken stdout without a serial link stops the run."""

    def __init__(self, say: _Stderr, writer: Any, link: Any, camera_line: str = "") -> None:
        self.say, self.writer, self.link = say, writer, link
        self.loop: Any = None
        self.latest_only = False  # a live source was read (newest frame only)
        self._last_failure, self._failure_said_at = "", 0.0
        # Which profile file the camera model came from (docs/cli.md): said once, after the source
        # and the notes of its opening (the first lines say what is measured from, e.g. SIMULATED).
        self._camera_line = camera_line
        self._several_said: set[frozenset[str]] = set()  # the sets of texts said by _say_several

    def _say_several(self, result: Any) -> None:
        """Several codes in view: which one is reported, said once per set of texts (as ``solve``
        says it; the lines on stdout carry only the reported code's)."""
        detections, chosen = getattr(result, "detections", None) or [], getattr(result, "detection", None)
        if len(detections) < 2 or chosen is None:
            return
        texts = frozenset(d.text for d in detections)
        if texts in self._several_said or len(self._several_said) >= 100:
            return
        self._several_said.add(texts)
        others = sorted({repr(d.text) for d in detections if d is not chosen})
        self.say(
            f"frame {result.index}: {len(detections)} codes in view (others: {', '.join(others)}); "
            f"reporting the one with text {chosen.text!r}; --select-text TEXT picks one (else the largest)"
        )

    def _say_camera(self) -> None:
        if self._camera_line:
            self.say(self._camera_line)
            self._camera_line = ""

    def opened(self, description: str, again: bool) -> None:
        self._last_failure = ""
        self.say(f"source reopened: {description}" if again else f"source: {description}")
        self.latest_only = self.latest_only or self.loop.latest_only
        if self.link is not None and self.loop.simulated:
            self.say("serial: this source is not a live camera: its poses go out as SIM, never OK")

    def failed(self, message: str, ended: bool) -> None:
        # A source that stays away is retried every --retry-s with the same error: said once a minute.
        now = time.monotonic()
        reason = message.removeprefix("still ")
        if reason != self._last_failure or now - self._failure_said_at >= 60.0:
            self.say(message)
            self._last_failure, self._failure_said_at = reason, now
        self._say_camera()

    def note(self, message: str) -> None:
        self.say(message)

    def processed(self, frame: Any, result: Any, behind: int) -> None:
        self._say_camera()
        self._say_several(result)
        if self.writer.broken and self.link is None and self.loop is not None:
            self.loop.stop()  # the reader went away (e.g. `| head`) and nothing else listens


class _StdoutSink(BaseSink):
    """Each result as one line on stdout (through the LineWriter: never blocks)."""

    def __init__(self, writer: Any, json_lines: bool) -> None:
        self.writer, self.json_lines = writer, json_lines

    def on_result(self, result: Any, simulated: bool) -> None:
        line = (_json_line if self.json_lines else _human_line)(result, simulated)
        self.writer.write(line)


def _gripper_link(settings: Any, say: _Stderr, config: Any, pose_frame: Any, handeye: Any) -> Any:
    from qrfield.serial.controller import GripperLink

    shown = {"state": "", "error": ""}

    def on_status(status: Any) -> None:
        # Each state change once, and each new error once: a port that stays away is retried every
        # reconnect interval with the same error, which would otherwise fill the log.
        if status.state != shown["state"]:
            shown["state"] = status.state
            say(f"serial {status.port}: {status.state}")
        if status.last_error and status.last_error != shown["error"]:
            shown["error"] = status.last_error
            say(f"serial {status.port}: {status.last_error}")

    link = GripperLink(settings, on_status=on_status, pose_frame=pose_frame)
    link.set_context(side_mm=config.side_mm, camera=config.camera.name)
    link.add_handeye(handeye)
    link.start(open_first=True)  # a busy port refuses here, with one line naming the other process
    rate = f"at most {settings.max_rate_hz:g}/s" if settings.max_rate_hz > 0 else "as fast as the port allows"
    say(
        f"serial: $QRF lines (protocol 2) to {settings.port} at {settings.baud} baud, {rate}, newest pose "
        f"first, in the {pose_frame.frame} frame; answering $QRC commands (PING, HELLO, STREAM, RATE, "
        "MEAS, TOOL, HANDEYE)"
    )
    if handeye.setup is None:
        say("serial: HANDEYE has no set-up to solve for (--handeye-setup eye-in-hand|eye-to-hand)")
    else:
        say(f"serial: HANDEYE solves {handeye.setup} and saves {handeye.save_to}")
    return link


def _handeye_commands(effective: Any, args: argparse.Namespace, config: Any, say: _Stderr) -> Any:
    """$QRC,TOOL and $QRC,HANDEYE for the link; HandEyeError when the set-up does not fit the frame."""
    from qrfield.serial.handeye import HandEyeCommands

    info = {"camera": config.camera.name, "side_mm": float(config.side_mm), "pose_method": config.methods[0]}
    handeye = HandEyeCommands.from_settings(effective.groups["handeye"], args.config_dir, info=info)

    def calibrated(done: Any) -> None:
        c = done.calibration
        kept = f" (the one before kept as {done.previous})" if done.previous else ""
        kind = " from simulated frames" if done.simulated else ""
        say(
            f"serial: HANDEYE: {c.setup} calibration{kind} from {c.n_pairs} pairs, residuals "
            f"{c.residual_mm:.3f} mm, {c.residual_deg:.3f} deg; saved to {done.path}{kept}"
        )

    handeye.calibrated.append(calibrated)
    return handeye


def run(args: argparse.Namespace) -> int:
    from qrfield.camera import camera_origin
    from qrfield.engine import FAILED, STOPPED, FrameLoop
    from qrfield.handeye import InFrame, PoseFrame
    from qrfield.runconfig import effective_settings
    from qrfield.sources import may_be_live_camera, source_kind
    from qrfield.stdout_lines import LineWriter

    if args.frames < 0:
        raise ValueError(f"--frames must be >= 0, got {args.frames}")
    effective = effective_settings(args, strict=True)
    say = _Stderr()
    for problem in effective.store.problems:
        say(f"settings: {problem}")
    serial = effective.serial_port is not None
    config = effective.run_config(allow_virtual=not serial or args.allow_virtual)
    if source_kind(config.source) != "virtual":
        for note in effective.assumed():
            say(note)
    pose_frame = PoseFrame.from_settings(effective.groups["handeye"], args.config_dir)
    pose_frame.check_source(may_be_live_camera(config.source))
    handeye = _handeye_commands(effective, args, config, say) if serial else None
    if not pose_frame.identity:
        say(pose_frame.describe())
    config.make_pipeline()  # every detector, solver and camera setting is checked now, not per frame
    link = _gripper_link(effective.serial_settings(), say, config, pose_frame, handeye) if serial else None
    writer = LineWriter(sys.stdout)
    stop_signal = {"name": ""}
    camera = config.camera
    events = _Events(
        say, writer, link, f"camera {camera.name} from {camera_origin(camera)}" if camera.path else ""
    )
    stdout_sink: Any = _StdoutSink(writer, args.json_lines)
    if not pose_frame.identity:
        stdout_sink = InFrame(stdout_sink, pose_frame)
        if link is not None:  # after a HANDEYE, stdout follows the link's new calibration
            link.handeye.calibrated.append(lambda _done: setattr(stdout_sink, "pose_frame", link.pose_frame))
    sinks: list[Any] = [stdout_sink] + ([link] if link is not None else [])
    loop = FrameLoop(config, events=events, sinks=sinks, max_frames=args.frames)
    events.loop = loop

    def on_signal(signum: int, _frame: Any) -> None:
        stop_signal["name"] = signal.Signals(signum).name
        loop.stop_from_signal()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        ending = loop.run()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if link is not None:
            link.close()
        # A run stopped by a signal must exit now; a finished one waits while stdout is read.
        left = writer.close(0.5) if stop_signal["name"] else writer.close(stalled_after=5.0)
    code = 1 if ending == FAILED else 0
    if link is not None:
        sent = link.status()
        say(
            f"serial: {sent.frames_sent} frames sent, {sent.frames_dropped} replaced by newer ones, "
            f"{sent.answers_sent} answers"
        )
        if not sent.ever_connected:
            say(f"serial: error: port {sent.port} could not be opened during the whole run")
            code = 1
    if writer.dropped:
        say(f"stdout: {writer.dropped} lines not written (the reader did not keep up; {left} at the end)")
    ending_text = {
        STOPPED: f"stopped by {stop_signal['name']}" if stop_signal["name"] else "stopped: stdout was closed",
        FAILED: "ended: no source",
    }.get(ending, "done")
    summary = f"{ending_text} after {loop.frames_processed} frames"
    if loop.dropped or events.latest_only:
        summary += (
            f"; {loop.dropped} newer camera frames arrived while one was processed and were dropped "
            "(only the latest frame is kept)"
        )
    say(summary)
    return code


def _json_line(result: Any, simulated: bool) -> str:
    from qrfield.handeye.frames import frame_of

    out = result.to_json_dict(simulated)
    out["pose_frame"] = frame_of(result)  # camera, tool or base (docs/handeye.md)
    return json.dumps(out)


def _human_line(result: Any, simulated: bool) -> str:
    from qrfield.handeye.frames import frame_of
    from qrfield.handeye.setups import CAMERA

    frame = frame_of(result)
    return result.summary(simulated) + ("" if frame == CAMERA else f"  [{frame} frame]")
