"""``qrfield run --headless``: measure from a camera source with no window, one pose per frame.

This is how a Raspberry Pi without a monitor runs qrfield: frames come from ``--source``, each
is detected and solved, and one line per frame goes to stdout (JSON lines with
``--json-lines``, else a compact human line). Notes and errors go to stderr. SIGINT (Ctrl-C) and
SIGTERM stop it cleanly after the current frame: the source is closed and the exit code is 0.
No Qt is imported, ever.

A live camera (USB, picamera2: ``source.live``) is read on its own thread that keeps only the
newest frame (:class:`qrfield.sources.LatestFrameReader`), so a slow frame loop never falls behind
the camera's buffer: frames that arrive while one is processed are dropped, and their count is in
the final summary on stderr. A video file, an image folder and the virtual bench are read frame by
frame, none dropped (so ``--frames N`` on a file is repeatable).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
import time
from typing import Any

from qrfield.camera import add_camera_arguments

HELP = "measure poses from a camera source without a window (headless; JSON lines for other programs)"

#: Camera model assumed when none is named (the virtual bench renders through it, too).
DEFAULT_CAMERA = "picam-v2@640x480"
DEFAULT_SIDE_MM = 50.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.pipeline import METHOD_CHOICES
    from qrfield.serial_link import SerialLinkSettings
    from qrfield.settings import add_arguments as add_setting_arguments
    from qrfield.sources import SOURCE_HELP, Picamera2Settings, UsbCameraSettings, VirtualBenchSettings

    parser.add_argument(
        "--headless", action="store_true", help="no window (always true for run; accepted for clarity)"
    )
    parser.add_argument("--source", default="auto", metavar="SRC", help=SOURCE_HELP)
    parser.add_argument(
        "--frames", type=int, default=0, metavar="N", help="stop after N frames (0 = until stopped)"
    )
    parser.add_argument("--json-lines", action="store_true", help="one JSON object per frame on stdout")
    add_camera_arguments(parser, default=None)
    parser.add_argument(
        "--side-mm",
        type=float,
        default=DEFAULT_SIDE_MM,
        metavar="L",
        help=f"QR symbol side without quiet zone, mm (default {DEFAULT_SIDE_MM:g})",
    )
    parser.add_argument(
        "--method",
        choices=METHOD_CHOICES,
        default="numerical",
        help="pose method: the thesis' numerical model, OpenCV IPPE, or both (numerical gives the status)",
    )
    parser.add_argument("--select-text", default="", metavar="TEXT", help="only use a code with this payload")
    parser.add_argument("--loop", action="store_true", help="a video file or folder starts again at its end")
    parser.add_argument(
        "--pace", action="store_true", help="play a video file at its own frame rate (a folder at 2 images/s)"
    )
    parser.add_argument(
        "--retry-s",
        type=float,
        default=0.0,
        metavar="S",
        help="when the source fails, reopen it after S seconds instead of stopping (0 = stop)",
    )
    group = parser.add_argument_group("virtual bench (--source virtual)")
    add_setting_arguments(group, VirtualBenchSettings, prefix="virtual_")
    group = parser.add_argument_group(
        "serial link to the gripper controller ($QRF frames; docs/conventions.md)"
    )
    group.add_argument(
        "--serial",
        metavar="PORT",
        default=None,
        help="also send each frame's pose as a $QRF line to PORT (/dev/ttyUSB0, COM3, loop://)",
    )
    add_setting_arguments(group, SerialLinkSettings, prefix="serial_")
    group = parser.add_argument_group(
        "Raspberry Pi camera (--source picamera2; default size: the camera model's)"
    )
    add_setting_arguments(group, Picamera2Settings, prefix="picamera_")
    group = parser.add_argument_group("USB camera (--source usb:N)")
    add_setting_arguments(group, UsbCameraSettings, prefix="usb_")


class StopFlag:
    """Set by SIGINT/SIGTERM; the frame loop checks it after every frame."""

    def __init__(self) -> None:
        self.signal_name = ""

    def __bool__(self) -> bool:
        return bool(self.signal_name)

    def install(self) -> dict[int, Any]:
        previous = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, self._handle)
        return previous

    def _handle(self, signum: int, _frame: Any) -> None:
        self.signal_name = signal.Signals(signum).name


def _camera(args: argparse.Namespace) -> Any:
    from qrfield.camera import camera_from_args, resolve_camera

    if args.camera or args.focal_px is not None or args.size is not None:
        return camera_from_args(args), True
    return resolve_camera(DEFAULT_CAMERA), False


def _serial_link(args: argparse.Namespace, say: Any) -> Any:
    """The started SerialLink when --serial or --serial-port was given, else None."""
    from qrfield.serial_link import SerialLink, SerialLinkSettings
    from qrfield.settings import from_arguments

    port = args.serial or args.serial_port
    if not port:
        return None
    settings = from_arguments(SerialLinkSettings, args, prefix="serial_")
    settings = dataclasses.replace(settings, port=port)

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

    link = SerialLink(settings, on_status=on_status).start()
    say(f"serial: sending $QRF frames to {port} at {settings.baud} baud, at most {settings.max_rate_hz:g}/s")
    return link


def run(args: argparse.Namespace) -> int:
    from qrfield.pipeline import Pipeline, methods_from_choice
    from qrfield.serial_link import publish_result
    from qrfield.settings import from_arguments, specs
    from qrfield.sources import (
        EndOfStream,
        Picamera2Settings,
        SourceError,
        UsbCameraSettings,
        VirtualBenchSettings,
        stream_camera,
    )

    if args.frames < 0:
        raise ValueError(f"--frames must be >= 0, got {args.frames}")
    if not 0 <= args.retry_s < float("inf"):  # nan would retry in a busy loop
        raise ValueError(f"--retry-s must be a number of seconds >= 0, got {args.retry_s}")
    camera, named = _camera(args)
    named_camera = camera  # the model the user named (a source may map it to its stream)
    virtual = from_arguments(VirtualBenchSettings, args, prefix="virtual_")
    picamera_given = any(
        getattr(args, f"picamera_{spec.name}") is not None for spec in specs(Picamera2Settings)
    )
    base = Picamera2Settings(width=camera.width, height=camera.height)
    args.picamera = (
        from_arguments(Picamera2Settings, args, prefix="picamera_", base=base) if picamera_given else None
    )
    args.usb = from_arguments(UsbCameraSettings, args, prefix="usb_")
    stop = StopFlag()
    previous = stop.install()
    say = _Stderr()
    link = _serial_link(args, say)
    source = None
    frames: FrameFeed | None = None
    count = 0
    try:
        source = _open(args, camera, virtual, say, stop)
        if source is None:
            return 1 if not stop else 0
        if source.name != "virtual" and not named:
            say(f"camera model: {camera.name} assumed (name yours with --camera)")
        camera = stream_camera(source, camera)  # a picamera2 stream's: through its sensor crop
        pipeline = Pipeline(
            camera, args.side_mm, methods_from_choice(args.method), select_text=args.select_text
        )
        emit = _json_line if args.json_lines else _human_line
        frames = FrameFeed(source, stop)
        while not stop and (args.frames == 0 or count < args.frames):
            try:
                frame = frames.read()
                if frame is None:  # stopped by a signal while waiting for a live frame
                    break
            except EndOfStream as exc:
                say(str(exc))
                break
            except SourceError as exc:
                say(f"source failed: {exc}")
                frames.close()
                if args.retry_s <= 0:
                    return 1
                source = _reopen(args, named_camera, virtual, say, stop)
                if source is None:
                    break
                if stream_camera(source, named_camera) != pipeline.camera:
                    pipeline = Pipeline(
                        stream_camera(source, named_camera),
                        args.side_mm,
                        methods_from_choice(args.method),
                        select_text=args.select_text,
                    )
                frames = FrameFeed(source, stop, dropped_before=frames.dropped)
                continue
            result = pipeline.process(frame)
            emit(result)
            if link is not None:
                publish_result(link, result)
            count += 1
            say.notes(source)
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly; stdout must not be flushed again.
        sys.stdout = None  # type: ignore[assignment]
        return 0
    finally:
        if frames is not None:
            frames.close()
        if source is not None:
            source.close()
        if link is not None:
            link.close()
            sent = link.status()
            say(f"serial: {sent.frames_sent} frames sent, {sent.frames_dropped} replaced by newer ones")
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    ending = f"stopped by {stop.signal_name}" if stop else "done"
    if frames is not None and frames.latest_only:
        say(
            f"{ending} after {count} frames; {frames.dropped} newer camera frames arrived while one was "
            "processed and were dropped (only the latest frame is kept)"
        )
    else:
        say(f"{ending} after {count} frames")
    return 0


class FrameFeed:
    """The frames of one opened source for the frame loop.

    A live source (a camera that delivers frames whether or not they are read) is read by a
    :class:`~qrfield.sources.LatestFrameReader` thread, and :meth:`read` returns the newest frame
    (``dropped`` counts the ones skipped); any other source is read directly, every frame in turn.
    ``dropped_before`` carries the count over a reopened source.
    """

    #: How often (s) a wait for a live frame looks at the stop flag.
    POLL_S = 0.1

    def __init__(self, source: Any, stop: Any, dropped_before: int = 0) -> None:
        from qrfield.sources import LatestFrameReader

        self.source = source
        self.stop = stop
        self.latest_only = bool(source.live)
        self._dropped_before = dropped_before
        self.reader = LatestFrameReader(source).start() if self.latest_only else None

    @property
    def dropped(self) -> int:
        return self._dropped_before + (self.reader.dropped if self.reader is not None else 0)

    def read(self) -> Any:
        """The next frame to process (the newest, for a live source); None when a stop signal came
        while waiting. Raises the source's SourceError / EndOfStream."""
        if self.reader is None:
            return self.source.read()
        while not self.stop:
            frame = self.reader.get(timeout=self.POLL_S)
            if frame is not None:
                return frame
        return None

    def close(self) -> None:
        """Stop the reader thread (if any) and close the source; safe to call twice."""
        if self.reader is not None:
            self.reader.stop()
        self.source.close()


def _open_once(args: argparse.Namespace, camera: Any, virtual: Any) -> Any:
    """The source the options name, opened (SourceError if it cannot be)."""
    from qrfield.sources import open_source

    return open_source(
        args.source,
        camera=camera,
        side_mm=args.side_mm,
        virtual=virtual,
        picamera=args.picamera,
        usb=getattr(args, "usb", None),
        loop=args.loop,
        pace=args.pace,
    )


def _open(args: argparse.Namespace, camera: Any, virtual: Any, say: _Stderr, stop: StopFlag) -> Any:
    from qrfield.sources import SourceError

    try:
        source = _open_once(args, camera, virtual)
    except SourceError as exc:
        say(f"cannot open source: {exc}")
        if args.retry_s <= 0:
            return None
        return _reopen(args, camera, virtual, say, stop)
    say(f"source: {source.description}")
    say.notes(source)
    return source


def _reopen(args: argparse.Namespace, camera: Any, virtual: Any, say: _Stderr, stop: StopFlag) -> Any:
    """Retry every --retry-s seconds until the source opens or a signal arrives."""
    from qrfield.sources import SourceError

    while not stop:
        deadline = time.monotonic() + args.retry_s
        while not stop and time.monotonic() < deadline:
            time.sleep(min(0.1, args.retry_s))
        if stop:
            break
        try:
            source = _open_once(args, camera, virtual)
        except SourceError as exc:
            say(f"still cannot open source: {exc}")
            continue
        say(f"source reopened: {source.description}")
        return source
    return None


class _Stderr:
    """Messages for humans on stderr, and each source note once."""

    def __init__(self) -> None:
        self._source: Any = None
        self._seen = 0

    def __call__(self, message: str) -> None:
        print(f"qrfield run: {message}", file=sys.stderr, flush=True)

    def notes(self, source: Any) -> None:
        if source is not self._source:
            self._source, self._seen = source, 0
        for note in source.notes[self._seen :]:
            self(note)
        self._seen = len(source.notes)


def _json_line(result: Any) -> None:
    sys.stdout.write(json.dumps(result.to_json_dict()) + "\n")
    sys.stdout.flush()


def _human_line(result: Any) -> None:
    sys.stdout.write(result.summary() + "\n")
    sys.stdout.flush()
