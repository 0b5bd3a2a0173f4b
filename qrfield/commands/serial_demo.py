"""``qrfield serial-demo PORT``: stream a synthetic moving pose to a port, without camera or app;
``qrfield serial-demo --robot``: the whole hand-eye workflow over serial, without hardware.

For whoever writes the gripper controller: the controller sees exactly the lines the app would
send (protocol 2, through the same :class:`~qrfield.serial.controller.GripperLink`: pacing to the
baud, newest pose first, reconnect, STALE, NOSRC as the last line, and answers to PING, HELLO,
STREAM, RATE and MEAS), from a smooth made-up path (the card
swaying 300-500 mm in front of the camera), with one second of NOQR every ``--noqr-every`` seconds
so the controller's "no pose" branch gets exercised too. The poses are made up, so they go out as
SIM, never OK (docs/conventions.md): a controller under test treats SIM as a pose in its test mode.

With ``--robot`` (no PORT) the demo plays both ends (:mod:`qrfield.serial.robot_demo`): a simulated
robot with a known hand-eye transform moves the virtual bench's card, a scripted controller sends
``$QRC,TOOL`` at each tool pose and then ``$QRC,HANDEYE`` over a pty at a UART's pace; every command
and answer is printed, then the transform found and its error against the known one.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from qrfield.commands._signals import restore_sigterm, sigterm_as_interrupt
from qrfield.status import ResultStatus

HELP = "stream a synthetic moving pose to a serial port (test a controller without camera or app)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import add_side_argument, rate, seconds, seed, whole_number
    from qrfield.handeye.setups import SETUPS

    parser.add_argument(
        "port",
        metavar="PORT",
        nargs="?",
        help="device path (/dev/ttyUSB0, COM3, a pty) or URL (loop://); not with --robot",
    )
    robot = parser.add_argument_group("hand-eye over serial (--robot)")
    robot.add_argument(
        "--robot",
        action="store_true",
        help="play a robot program and qrfield on both ends of a pty: TOOL at each tool pose, then HANDEYE",
    )
    robot.add_argument(
        "--setup", choices=SETUPS, default="eye-in-hand", help="the cell (default eye-in-hand)"
    )
    robot.add_argument(
        "--poses",
        type=whole_number("--poses", 5, 100),
        default=15,
        help="tool poses visited (5..100, default 15)",
    )
    robot.add_argument("--seed", type=seed("--seed"), default=0, help="the tool poses' seed (default 0)")
    robot.add_argument(
        "--out-dir",
        metavar="DIR",
        help="keep the calibration in DIR (default: a temporary folder, removed at the end)",
    )
    parser.add_argument(
        "--fps", type=rate("--fps"), default=30.0, help="poses produced per second (default 30)"
    )
    parser.add_argument(
        "--seconds", type=seconds("--seconds"), default=None, metavar="S", help="stop after S seconds"
    )
    parser.add_argument(
        "--noqr-every",
        type=seconds("--noqr-every"),
        default=10.0,
        metavar="S",
        help="1 s of NOQR every S s; 0 never",
    )
    parser.add_argument("--baud", type=int, default=115200, help="baud rate, 8N1 (default 115200)")
    parser.add_argument(
        "--max-rate",
        type=rate("--max-rate"),
        default=30.0,
        metavar="HZ",
        help="the link's rate cap (0 = none)",
    )
    add_side_argument(parser, 50.0)  # the QR side HELLO reports


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
    if args.robot:
        if args.port is not None:
            raise ValueError("--robot plays both ends of its own pty: give no PORT")
        if args.out_dir:  # before the robot's program runs, not when its result cannot be saved
            from qrfield.files import make_folder

            make_folder(Path(args.out_dir).expanduser(), "--out-dir")
        return _robot(args)
    if args.port is None:
        raise ValueError("give PORT (a device path or loop://), or --robot")
    if args.seconds is not None and not 0 < args.seconds < math.inf:
        raise ValueError(f"--seconds must be a positive number of seconds, got {args.seconds}")
    if 0 < args.noqr_every <= 1.0:  # 1 s of NOQR every S s: S <= 1 would be NOQR all the time
        raise ValueError(
            "--noqr-every must be 0 (never) or more than 1 s (1 s of NOQR every S s), "
            f"got {args.noqr_every:g}"
        )
    settings = validated(SerialLinkSettings(port=args.port, baud=args.baud, max_rate_hz=args.max_rate))

    previous = sigterm_as_interrupt()
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
        restore_sigterm(previous)
    status = link.status()
    if not status.ever_connected:  # the link retried all along: said, and not a success
        last = f" (last: {status.last_error})" if status.last_error else ""
        print(f"qrfield serial-demo: {args.port} never opened: nothing was sent{last}", file=sys.stderr)
        return 1
    return 0


def _robot(args: argparse.Namespace) -> int:
    import tempfile

    from qrfield.camera import DEFAULT_CAMERA, resolve_camera
    from qrfield.geometry import angles_from_rotation
    from qrfield.handeye import SimulatedRobot
    from qrfield.handeye.setups import TRANSFORM_KEY
    from qrfield.serial.robot_demo import run_robot_demo

    def fmt(values: object, digits: int) -> str:
        return ", ".join(f"{v:.{digits}f}" for v in values)  # type: ignore[attr-defined]

    camera = resolve_camera(DEFAULT_CAMERA)
    robot = SimulatedRobot.example(args.setup)
    key = TRANSFORM_KEY[args.setup]
    truth = robot.transform
    print(
        f"serial-demo --robot: {args.setup} cell, true {key} at ({fmt(truth[:3, 3], 2)}) mm, "
        f"({fmt(angles_from_rotation(truth[:3, :3]), 2)}) deg; {args.poses} tool poses (seed {args.seed}); "
        f"{camera.name}, {args.side_mm:g} mm code on the virtual bench at {args.fps:g} fps; {args.baud} baud",
        flush=True,
    )

    def show(command: str, answer: str) -> None:
        print(f"-> {command}\n<- {answer}", flush=True)

    with tempfile.TemporaryDirectory(prefix="qrfield-serial-demo-") as scratch:
        folder = Path(args.out_dir).expanduser() if args.out_dir else Path(scratch)
        result = run_robot_demo(
            args.setup,
            folder,
            poses=args.poses,
            seed=args.seed,
            camera=camera,
            side_mm=args.side_mm,
            fps=args.fps,
            baud=args.baud,
            robot=robot,
            on_exchange=show,
        )
        print(f"{result.pairs} pairs recorded, {result.refused} tool poses refused")
        if result.calibration is None:
            reason = result.handeye.reason if result.handeye is not None else "no answer"
            print(f"serial-demo --robot: HANDEYE failed: {reason}", file=sys.stderr)
            return 1
        c = result.calibration
        found = c.transform
        std_mm = c.extra.get("translation_std_mm", [math.nan] * 3)
        std_deg = c.extra.get("rotation_std_deg", [math.nan] * 3)
        print(
            f"{key} found: ({fmt(found[:3, 3], 2)}) mm, std ({fmt(std_mm, 3)}) mm; "
            f"({fmt(angles_from_rotation(found[:3, :3]), 3)}) deg, rotation std ({fmt(std_deg, 4)}) deg"
        )
        print(f"residuals {c.residual_mm:.3f} mm, {c.residual_deg:.3f} deg over {c.n_pairs} pairs")
        where = (
            f"saved to {c.path}" if args.out_dir else "in a temporary folder, removed (--out-dir keeps it)"
        )
        print(f"error against the true {key}: {result.error_mm:.3f} mm, {result.error_deg:.4f} deg ({where})")
    return 0
