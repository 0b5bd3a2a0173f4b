"""``qrfield serial-demo PORT``: stream a synthetic moving pose to a port, without camera or app.

For whoever writes the gripper controller: the controller sees exactly the lines the app would
send (protocol 2, through the same :class:`~qrfield.serial.controller.GripperLink`: pacing to the
baud, newest pose first, reconnect, STALE, NOSRC as the last line, and answers to PING, HELLO,
STREAM, RATE and MEAS), from a smooth made-up path (the card
swaying 300-500 mm in front of the camera), with one second of NOQR every ``--noqr-every`` seconds
so the controller's "no pose" branch gets exercised too. The poses are made up, so they go out as
SIM, never OK (docs/conventions.md): a controller under test treats SIM as a pose in its test mode.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from dataclasses import dataclass

from qrfield.status import ResultStatus

HELP = "stream a synthetic moving pose to a serial port (test a controller without camera or app)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "port", metavar="PORT", help="device path (/dev/ttyUSB0, COM3, a pty) or URL (loop://)"
    )
    parser.add_argument("--fps", type=float, default=30.0, help="poses produced per second (default 30)")
    parser.add_argument("--seconds", type=float, default=None, metavar="S", help="stop after S seconds")
    parser.add_argument(
        "--noqr-every", type=float, default=10.0, metavar="S", help="1 s of NOQR every S s; 0 never"
    )
    parser.add_argument("--baud", type=int, default=115200, help="baud rate, 8N1 (default 115200)")
    parser.add_argument(
        "--max-rate", type=float, default=30.0, metavar="HZ", help="the link's rate cap (0 = none)"
    )
    parser.add_argument("--side-mm", type=float, default=50.0, help="the QR side HELLO reports (default 50)")


def demo_pose(t_s: float) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The synthetic path at time t_s: position (mm, camera frame) and angles (degrees)."""
    position = (60.0 * math.sin(0.5 * t_s), 40.0 * math.sin(0.3 * t_s), 400.0 + 100.0 * math.sin(0.2 * t_s))
    angles = (15.0 * math.sin(0.4 * t_s), 20.0 * math.sin(0.25 * t_s), 30.0 * math.sin(0.15 * t_s))
    return position, angles


#: The made-up path's standard uncertainty per frame: mm (x, y, z) and degrees (alpha, beta, gamma).
DEMO_STD_MM = (0.2, 0.2, 1.0)
DEMO_STD_DEG = (0.1, 0.1, 0.05)


@dataclass
class _DemoPose:
    position_mm: tuple[float, float, float]
    angles_deg: tuple[float, float, float]
    converged: bool = True
    position_std_mm: tuple[float, float, float] = DEMO_STD_MM
    angles_std_deg: tuple[float, float, float] = DEMO_STD_DEG


@dataclass
class _DemoResult:
    """What the frame loop hands a sink, for one synthetic frame (see qrfield.pipeline.FrameResult)."""

    t_ms: int
    status: str
    primary: _DemoPose | None
    t_capture: float  # time.monotonic() s: the line's age_ms counts from it
    ambiguous: bool = False


def run(args: argparse.Namespace) -> int:
    from qrfield.serial.controller import GripperLink
    from qrfield.serial.link import SerialLinkSettings
    from qrfield.settings import validated

    if not 0 < args.fps < math.inf:
        raise ValueError(f"--fps must be positive, got {args.fps}")
    if args.seconds is not None and not 0 < args.seconds < math.inf:
        raise ValueError(f"--seconds must be a positive number of seconds, got {args.seconds}")
    settings = validated(SerialLinkSettings(port=args.port, baud=args.baud, max_rate_hz=args.max_rate))

    def on_sigterm(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:  # not the main thread (a test, an embedding program): Ctrl-C only
        previous = None
    link = GripperLink(settings, on_status=lambda s: print(s.summary(), file=sys.stderr, flush=True))
    link.set_context(side_mm=args.side_mm, camera="serial-demo")
    start = time.monotonic()
    next_report = start + 1.0
    try:
        link.start(open_first=True)
        frame = 0
        while args.seconds is None or time.monotonic() - start < args.seconds:
            t_s = frame / args.fps
            t_ms = round(t_s * 1000.0)
            noqr = args.noqr_every > 0 and (t_s % args.noqr_every) >= args.noqr_every - 1.0
            if noqr:
                link.on_result(_DemoResult(t_ms, ResultStatus.NOQR, None, time.monotonic()), simulated=True)
            else:
                pose = _DemoPose(*demo_pose(t_s))
                link.on_result(_DemoResult(t_ms, ResultStatus.OK, pose, time.monotonic()), simulated=True)
            frame += 1
            if time.monotonic() >= next_report:
                print(link.status().summary(), file=sys.stderr, flush=True)
                next_report += 1.0
            time.sleep(max(0.0, start + frame / args.fps - time.monotonic()))
    except KeyboardInterrupt:
        pass
    finally:
        link.close()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0
