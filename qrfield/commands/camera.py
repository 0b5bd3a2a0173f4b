"""``qrfield camera list|check``: the cameras found, their sensor modes, and the model of a stream.

``list`` shows every Raspberry Pi camera (through picamera2) with its sensor modes (size, fps, the
sensor crop each reads) and every USB camera OpenCV can open; ``--simulated`` adds the picamera2
stand-ins. ``check`` opens one camera as ``qrfield run`` would (the same settings) and prints the
mode asked for and the one chosen, the ScalerCrop, the focus, and the camera model of its frames
with the formula that gives it: where each number came from.
"""

from __future__ import annotations

import argparse
import sys

HELP = "list the cameras and their sensor modes, or check the camera model of a stream"
DESCRIPTION = (
    "list: the cameras found (Raspberry Pi cameras through picamera2, USB cameras through OpenCV), "
    "their sensor modes (size, fps, sensor crop). check: open one camera as qrfield run would and "
    "show the sensor mode chosen for the size, the ScalerCrop, the focus and the camera model of "
    "the stream, with where each number came from (docs/cameras.md)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count
    from qrfield.camera import add_camera_arguments
    from qrfield.settings import add_arguments as add_setting_arguments
    from qrfield.sources import Picamera2Settings, UsbCameraSettings

    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    listing = sub.add_parser("list", help="the cameras found and their sensor modes")
    listing.add_argument(
        "--simulated", action="store_true", help="also list the picamera2 stand-ins (SIMULATED cameras)"
    )
    check = sub.add_parser(
        "check", help="open a camera as qrfield run would and show the camera model of its stream"
    )
    check.add_argument(
        "--source",
        default="picamera2",
        metavar="SRC",
        help="picamera2 (default), picamera2-sim[:imx219|imx708|imx477] (SIMULATED) or usb:N",
    )
    add_camera_arguments(check, default=None)
    check.add_argument(
        "--frames", type=count("--frames", 1), default=3, metavar="N", help="frames to read (default 3)"
    )
    group = check.add_argument_group("Raspberry Pi camera (as qrfield run's --picamera-* options)")
    add_setting_arguments(group, Picamera2Settings, prefix="picamera_")
    group = check.add_argument_group("USB camera (as qrfield run's --usb-* options)")
    add_setting_arguments(group, UsbCameraSettings, prefix="usb_")


def run(args: argparse.Namespace) -> int:
    if args.action == "list":
        return _list(args)
    return _check(args)


def _list(args: argparse.Namespace) -> int:
    from qrfield.sources.discovery import list_cameras

    found, reasons = list_cameras(include_simulated=args.simulated)
    real = [c for c in found if not c.simulated]
    if not real:
        print("no cameras found: " + "; ".join(reasons))
    for camera in found:
        print(f"{camera.title}  [--source {camera.source}]")
        for line in camera.lines:
            print(f"  {line}")
    if real and reasons:
        for reason in reasons:
            print(f"({reason})")
    return 0


def _check(args: argparse.Namespace) -> int:
    from qrfield.camera import camera_from_args
    from qrfield.settings import from_arguments
    from qrfield.sources import (
        Picamera2Settings,
        SourceError,
        UsbCameraSettings,
        VirtualBenchSettings,
        make_source,
    )
    from qrfield.sources.discovery import check_lines

    if args.frames < 1:
        raise ValueError(f"--frames must be at least 1, got {args.frames}")
    spec = args.source.strip()
    if not (spec == "picamera2" or spec.startswith(("picamera2-sim", "usb"))):
        raise ValueError(f"--source {spec!r}: check a camera: picamera2, picamera2-sim[:SENSOR] or usb:N")
    named = args.camera or args.focal_px is not None or args.size is not None
    profile = camera_from_args(args) if named else None
    base = Picamera2Settings(width=profile.width, height=profile.height) if profile else Picamera2Settings()
    picamera = from_arguments(Picamera2Settings, args, prefix="picamera_", base=base)
    usb = from_arguments(UsbCameraSettings, args, prefix="usb_")
    try:
        source = make_source(
            spec, camera=profile, picamera=picamera, usb=usb, virtual=VirtualBenchSettings(noise_sigma=1.0)
        )
        with source:
            lines = check_lines(source, profile, frames=args.frames)
    except SourceError as exc:
        print(f"qrfield camera check: {exc}", file=sys.stderr)
        return 1
    for line in lines:
        print(line)
    return 0
