"""``qrfield gui`` (also ``qrfield`` alone): the bench app window."""

from __future__ import annotations

import argparse
import os
import sys

HELP = "open the bench app window (the default when no subcommand is given)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.methods import METHOD_CHOICES
    from qrfield.runconfig import add_config_dir_argument
    from qrfield.sources import SOURCE_HELP

    parser.add_argument(
        "--source", default=None, help=SOURCE_HELP + " (default: the last one used, else auto)"
    )
    parser.add_argument(
        "--camera", default=None, metavar="CAM", help="camera profile NAME[@WxH] or PATH.json"
    )
    parser.add_argument("--side-mm", type=float, default=None, metavar="L", help="QR symbol side, mm")
    parser.add_argument("--method", choices=METHOD_CHOICES, default=None, help="pose method(s)")
    add_config_dir_argument(parser)
    parser.add_argument(
        "--quit-after",
        type=float,
        default=None,
        metavar="SECONDS",
        help="close the window after SECONDS (smoke tests)",
    )
    parser.add_argument(
        "--screenshot",
        default=None,
        metavar="FILE",
        help="with --quit-after: save the window as an image first",
    )


def display_available() -> bool:
    """True when Qt can open a window: a display server, or an explicit QT_QPA_PLATFORM."""
    if os.environ.get("QT_QPA_PLATFORM"):
        return True
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def check_arguments(args: argparse.Namespace) -> None:
    """Reject bad --side-mm, --camera and --quit-after before any window opens (ValueError naming it).

    The app would otherwise take them as they are (a negative QR side, a camera it cannot resolve).
    """
    from qrfield.camera import resolve_camera
    from qrfield.runconfig import RunSettings
    from qrfield.settings import from_dict

    if args.side_mm is not None:
        from_dict(RunSettings, {"side_mm": args.side_mm})  # its declared limits, in mm
    if args.camera is not None:
        resolve_camera(args.camera)  # CameraModelError naming the preset or file
    if args.quit_after is not None and not args.quit_after > 0:
        raise ValueError(f"--quit-after must be a positive number of seconds, got {args.quit_after}")


def run(args: argparse.Namespace) -> int:
    check_arguments(args)
    if not display_available():
        print(
            "qrfield: no display (DISPLAY and WAYLAND_DISPLAY are unset), so no window can open; "
            "run headless instead: qrfield run --headless --source auto --json-lines",
            file=sys.stderr,
        )
        return 3
    from ui.app import main as app_main

    return app_main(args)
