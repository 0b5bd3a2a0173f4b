"""``qrfield calibrate``: a camera model from photos of a chessboard.

``--json`` prints one object::

    {"fx", "fy", "cx", "cy": px, "dist": [k1, k2, p1, p2, k3], "rms_px": px,
     "used": [image path, ...], "skipped": [{"image": path, "reason": text}, ...],
     "width", "height": px, "per_image": [{"image", "rms_px", "max_px"}, ...],
     "std_px": {"fx", "fy", "cx", "cy"}, "board": "COLSxROWS", "square_mm": mm,
     "coverage": [[views per cell], ...] (3 rows x 3 columns of the image),
     "advice": [hint, ...], "mixed": [why the views may be of two cameras (with --allow-mixed)],
     "out": path written}
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from qrfield.arguments import number

HELP = "calibrate a camera from chessboard photos and write a camera profile (JSON)"
DESCRIPTION = (
    "Find a chessboard in each image (OpenCV, sub-pixel corners), calibrate (cv2.calibrateCamera: "
    "fx, fy, cx, cy and distortion k1, k2, p1, p2, k3), print the RMS and per-image reprojection "
    "errors and the images skipped with their reason, and write a camera profile usable wherever a "
    "camera is named (--camera PATH.json; or --camera NAME when written to your profile folder, "
    "~/.config/qrfield/calib). The folder of --out must exist (your profile folder is created)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "images",
        nargs="+",
        metavar="IMAGE",
        help="photos of the board (10-20 views, spread over the image), folders of them, or quoted "
        "glob patterns ('shots/*.png')",
    )
    parser.add_argument(
        "--board",
        required=True,
        metavar="COLSxROWS",
        help="inner corners per row x per column (OpenCV pattern size), "
        "e.g. 9x6 for a board of 10 x 7 squares",
    )
    parser.add_argument(
        "--square-mm",
        type=number("--square-mm", 0.1, 10_000.0, "mm"),
        required=True,
        metavar="S",
        help="side of one square, mm",
    )
    parser.add_argument(
        "--out",
        required=True,
        metavar="FILE.json",
        help="camera profile to write, e.g. ~/.config/qrfield/calib/NAME.json (then --camera NAME works) "
        "or calib/NAME.json (its folder must exist)",
    )
    parser.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    parser.add_argument(
        "--allow-mixed",
        action="store_true",
        help="calibrate even when the views seem to come from more than one camera (sizes, left/right "
        "or cam0/cam1 names, a cluster of views the model fits far worse): refused otherwise, since one "
        "model of two cameras fits neither",
    )
    parser.add_argument("--fix-k3", action="store_true", help="keep k3 = 0 (few views, or a mild lens)")
    parser.add_argument(
        "--sensor-crop",
        metavar="X,Y,W,H",
        help="the sensor rectangle the photos show, full-resolution pixels (qrfield camera check prints "
        "the stream's ScalerCrop): saved so the profile maps to other sensor modes",
    )
    parser.add_argument(
        "--sensor-resolution", metavar="WxH", help="the sensor's full resolution (with --sensor-crop)"
    )
    parser.add_argument(
        "--lens-position",
        type=number("--lens-position", 0.0, 1000.0, "dioptres"),
        metavar="D",
        help="the autofocus lens position of the photos, dioptres (saved; a run at another one warns)",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object: fx, fy, cx, cy (px), dist [k1, k2, p1, p2, k3], rms_px, "
        "used [paths], skipped [{image, reason}], width, height, per_image [{image, rms_px, max_px}], "
        "std_px, board, square_mm, coverage (3x3 views per cell), advice, out",
    )


def expand_images(items: list[str]) -> list[str]:
    """The image paths given (files, folders, globs: :func:`qrfield.images.expand_image_paths`);
    ValueError for a folder without images or a pattern that matches nothing."""
    from qrfield.images import IMAGE_SUFFIXES, expand_image_paths, is_glob

    paths = expand_image_paths(items)
    for item in items:
        if Path(item).is_dir() and item in paths:
            raise ValueError(f"folder {item} holds no images ({', '.join(IMAGE_SUFFIXES)})")
        if is_glob(item) and item in paths and not Path(item).exists():
            raise ValueError(f"no file matches {item}")
    return paths


def _sensor_geometry(args: argparse.Namespace) -> dict[str, Any]:
    """The camera-model fields --sensor-crop, --sensor-resolution and --lens-position give."""
    from qrfield.arguments import parse_numbers
    from qrfield.camera import CameraModelError, parse_size, sensor_fields

    changes: dict[str, Any] = {}
    if args.sensor_crop:
        try:
            crop = parse_numbers(args.sensor_crop, "--sensor-crop")  # how many: sensor_fields says
        except ValueError as exc:
            raise CameraModelError(f"{exc}; give X,Y,W,H in whole pixels, e.g. 0,2,3280,2460") from None
        # sensor_fields checks for four whole numbers inside the sensor and names what is wrong.
        changes["sensor_crop"] = tuple(int(v) if v.is_integer() else v for v in crop)
    if args.sensor_resolution:
        changes["sensor_resolution"] = parse_size(args.sensor_resolution)
    if args.lens_position is not None:
        changes["lens_position"] = args.lens_position
    return sensor_fields(changes, "calibrate")


def _mixed_refusal(problems: list[str]) -> str:
    return (
        f"the views do not all seem to come from one camera: {'; '.join(problems)}; one model of two "
        "cameras fits neither: calibrate each camera on its own (e.g. 'left*.jpg'), or add "
        "--allow-mixed to use them together"
    )


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from qrfield.calibration import CalibrationError, calibrate, detect_images, mixed_cameras
    from qrfield.camera import distortion_note, user_profile_dirs
    from qrfield.chessboard import Board
    from qrfield.files import check_target, make_folder

    board = Board.parse(args.board, args.square_mm)
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise ValueError(f"--out {out}: a camera profile is a .json file")
    if out.is_dir():
        raise IsADirectoryError(f"--out {out} is a folder; give a file name such as {out / 'NAME.json'}")
    if out.exists() and not args.force:
        raise FileExistsError(f"--out {out} exists; choose another name or add --force to overwrite it")
    geometry = _sensor_geometry(args)  # before the calibration: a typo is found at once
    if any(out.parent == folder for folder in user_profile_dirs()):
        make_folder(out.parent, "profile folder")  # qrfield's own folder: made when needed
    check_target(out, "--out")  # before hours of work: the folder must exist
    images = expand_images(args.images)
    detections = detect_images(images, board)
    mixed = mixed_cameras(detections)  # before the calibration: sizes and names are known now
    if mixed and not args.allow_mixed:
        raise CalibrationError(_mixed_refusal(mixed))
    result = calibrate(detections, board, fix_k3=args.fix_k3, name=out.stem)
    cluster = [p for p in mixed_cameras([], result) if p not in mixed]
    if cluster and not args.allow_mixed:
        raise CalibrationError(_mixed_refusal(cluster))
    for problem in [*mixed, *cluster]:  # allowed: said, and kept in the profile's notes
        print(
            f"qrfield calibrate: warning: the views may come from more than one camera: {problem}",
            file=sys.stderr,
        )
    if mixed or cluster:
        notes = f"{result.camera.notes}; --allow-mixed: {'; '.join([*mixed, *cluster])}"
        result = dataclasses.replace(result, camera=dataclasses.replace(result.camera, notes=notes))
    if geometry:
        result = dataclasses.replace(result, camera=dataclasses.replace(result.camera, **geometry))
    result.camera.save(out, overwrite=args.force)
    note = distortion_note(result.camera)

    if args.json:
        data = {**result.to_json(), "mixed": [*mixed, *cluster]}
        if note:
            data["advice"] = [*data.get("advice", []), note]
        json.dump({**data, "out": str(out)}, sys.stdout)
        print()
        return 0
    cam = result.camera
    print(
        f"calibrated {cam.width}x{cam.height} from {len(result.views)} of {len(images)} images, "
        f"board {board.label} inner corners, {board.square_mm:g} mm squares"
    )
    print(f"RMS reprojection error: {result.rms_px:.3f} px")
    width = max(len("image"), *(len(v.label) for v in result.views))
    print(f"  {'image':<{width}}  RMS px  max px")
    for v in result.views:
        print(f"  {v.label:<{width}}  {v.rms_px:6.3f}  {v.max_px:6.3f}")
    if result.skipped:
        print(f"skipped {len(result.skipped)}:")
        for s in result.skipped:
            print(f"  {s.label}: {s.reason}")
    sd = result.std_px
    print(f"fx = {cam.fx:.2f} +- {sd['fx']:.2f} px   fy = {cam.fy:.2f} +- {sd['fy']:.2f} px")
    print(f"cx = {cam.cx:.2f} +- {sd['cx']:.2f} px   cy = {cam.cy:.2f} +- {sd['cy']:.2f} px")
    print("dist (k1, k2, p1, p2, k3) = " + ", ".join(f"{d:.5f}" for d in cam.dist))
    print("coverage (views per cell, 3x3 grid of the image):")
    for row in result.coverage:
        print("  " + " ".join(f"{n:3d}" for n in row))
    for hint in [*result.advice(), *([note] if note else [])]:
        print(f"advice: {hint}")
    by_name = any(out.parent == folder for folder in user_profile_dirs())
    print(f"wrote {out}: use --camera {out.stem if by_name else out}")
    return 0
