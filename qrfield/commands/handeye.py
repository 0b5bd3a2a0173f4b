"""``qrfield handeye PAIRS.csv``: the hand-eye calibration from robot poses and images (docs/handeye.md).

Each row of PAIRS.csv (x,y,z,qw,qx,qy,qz,image: the tool pose in the base frame, mm and a unit
quaternion, and the image taken there) is detected and solved with the project's detector and
solver; a row whose code is not found, not converged or ambiguous is reported and left out. The
pairs are solved (:func:`qrfield.handeye.solve_handeye`) and the result written to ``--out``
(handeye.json, docs/conventions.md "Hand-eye"). Errors (a bad CSV, too few or too alike poses) are
one line; exit 0 when a calibration was written.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from qrfield.methods import NUMERICAL

HELP = "hand-eye calibration: the camera-to-tool (or camera-to-base) transform from robot poses and images"
DESCRIPTION = (
    "Solve the hand-eye calibration from PAIRS.csv (columns x,y,z,qw,qx,qy,qz,image: the robot's tool "
    "pose in its base frame, mm and a unit quaternion, and the image taken there, relative to the CSV). "
    "eye-in-hand: the camera on the gripper, the code fixed (gives camera_to_tool); eye-to-hand: the "
    "camera fixed, the code in the gripper (gives camera_to_base). Writes handeye.json for --frame."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import add_side_argument, limited
    from qrfield.camera import add_camera_arguments
    from qrfield.detect import DetectorSettings
    from qrfield.handeye.setups import SETUPS
    from qrfield.images import ImageSettings
    from qrfield.limits import TOOL_STD_DEG, TOOL_STD_MM
    from qrfield.methods import METHODS
    from qrfield.settings import add_arguments as add_setting_arguments

    parser.add_argument(
        "pairs", metavar="PAIRS.csv", help="the pairs: x,y,z,qw,qx,qy,qz,image per robot pose"
    )
    parser.add_argument("--setup", required=True, choices=SETUPS, help="where the camera is (see above)")
    add_camera_arguments(parser, focal_only=True)
    add_side_argument(parser)
    parser.add_argument(
        "--out",
        metavar="FILE",
        help="the calibration to write (default: handeye.json in the config folder, the file --frame "
        "tool/base reads; a file it replaces is kept as FILE.previous)",
    )
    parser.add_argument(
        "--method",
        choices=METHODS,
        default=NUMERICAL,
        help="the pose solver for each image (default numerical)",
    )
    parser.add_argument(
        "--tool-std-mm",
        type=limited(TOOL_STD_MM, "--tool-std-mm"),
        default=0.0,
        metavar="S",
        help="the robot's position uncertainty (1 sigma, e.g. its repeatability), mm; default 0",
    )
    parser.add_argument(
        "--tool-std-deg",
        type=limited(TOOL_STD_DEG, "--tool-std-deg"),
        default=0.0,
        metavar="S",
        help="the robot's orientation uncertainty (1 sigma), degrees; default 0",
    )
    group = parser.add_argument_group("detection settings")
    add_setting_arguments(group, DetectorSettings, prefix="detect-")  # type: ignore[arg-type]
    group = parser.add_argument_group("image files")
    add_setting_arguments(group, ImageSettings)  # type: ignore[arg-type]


def _say(text: str) -> None:
    print(f"qrfield handeye: {text}", file=sys.stderr, flush=True)


def _fmt(values: Any, digits: int) -> str:
    return ", ".join(f"{v:.{digits}f}" for v in values)


def run(args: argparse.Namespace) -> int:
    from qrfield import paths
    from qrfield.camera import camera_from_args
    from qrfield.commands._solve_images import _camera_for
    from qrfield.detect import Detector, DetectorSettings
    from qrfield.handeye import HandEyeCalibration, Pair, read_pairs_csv, solve_handeye
    from qrfield.handeye.measure import pose_for_pair
    from qrfield.handeye.store import save_keeping_previous
    from qrfield.images import ImageError, ImageSettings, read_image
    from qrfield.settings import from_arguments

    camera = camera_from_args(args, focal_only=True)
    rows = read_pairs_csv(args.pairs)
    out = Path(args.out).expanduser() if args.out else paths.config_dir() / "handeye.json"
    detector_settings = from_arguments(DetectorSettings, args, prefix="detect-")
    image_settings = from_arguments(ImageSettings, args)
    detector = Detector(detector_settings)
    pairs, left_out = [], 0
    for row in rows:
        name = row.label
        try:
            image = read_image(row.image, image_settings)
        except ImageError as exc:
            print(f"{name}: left out: {str(exc).removeprefix(f'{row.image}: ')}")
            left_out += 1
            continue
        cam, problem = _camera_for(camera, args.focal_px, image)
        result = None
        if cam is not None:
            result, problem = pose_for_pair(
                image,
                cam,
                args.side_mm,
                detector,
                method=args.method,
                select_text=detector_settings.select_text,
            )
        if problem:
            print(f"{name}: left out: {problem}")
            left_out += 1
            continue
        pairs.append(Pair.from_pose(row.tool_in_base, result, name))
        print(
            f"{name}: pair {len(pairs)}: code at ({_fmt(result.position_mm, 1)}) mm, "
            f"({_fmt(result.angles_deg, 2)}) deg; std ({_fmt(result.position_std_mm, 3)}) mm, "
            f"({_fmt(result.angles_std_deg, 3)}) deg"
        )
    print(f"{len(pairs)} pairs from {len(rows)} rows" + (f" ({left_out} left out)" if left_out else ""))
    result = solve_handeye(pairs, args.setup, tool_std_mm=args.tool_std_mm, tool_std_deg=args.tool_std_deg)
    _print_result(result)
    calibration = HandEyeCalibration.from_result(
        result,
        camera=camera.name if camera is not None else f"focal {args.focal_px:g} px",
        side_mm=float(args.side_mm),
        pose_method=args.method,
        pairs_file=str(Path(args.pairs)),
        tool_std_mm=float(args.tool_std_mm),
        tool_std_deg=float(args.tool_std_deg),
    )
    if args.out is None:
        from qrfield.files import make_folder

        make_folder(out.parent, "config folder")
    kept = save_keeping_previous(calibration, out)
    if kept is not None:
        _say(f"the calibration there before is kept as {kept}")
    _say(f"wrote {out}" + ("" if args.out else " (the config folder's: --frame tool/base uses it)"))
    return 0


def _print_result(result: Any) -> None:
    from qrfield.geometry import angles_from_rotation
    from qrfield.handeye.rigid import quaternion_from_rotation
    from qrfield.handeye.setups import TRANSFORM_KEY

    x = result.transform
    key = TRANSFORM_KEY[result.setup]
    angles = angles_from_rotation(x[:3, :3])
    print(f"{key} ({result.setup}; camera coordinates into the {result.target_frame} frame, mm):")
    for row in x:
        print("  " + "  ".join(f"{v:12.6f}" for v in row))
    print(
        f"  position ({_fmt(x[:3, 3], 2)}) mm, std ({_fmt(result.translation_std_mm, 3)}) mm; "
        f"angles ({_fmt(angles, 3)}) deg, rotation std ({_fmt(result.rotation_std_deg, 3)}) deg "
        f"about the {result.target_frame}'s x, y, z"
    )
    print(f"  quaternion qw, qx, qy, qz ({_fmt(quaternion_from_rotation(x[:3, :3]), 6)})")
    worst = int(result.residuals_mm.argmax())
    print(
        f"residuals: RMS {result.residual_mm:.3f} mm, {result.residual_deg:.3f} deg over {result.n_pairs} "
        f"pairs; largest {result.residuals_mm[worst]:.3f} mm ({result.labels[worst]})"
    )
    ratio = result.chi2 / result.dof if result.dof > 0 else math.nan
    if result.weighted:
        verdict = (
            "the residuals are as large as the poses' uncertainty predicts, or smaller"
            if ratio <= 1.5
            else f"the residuals are larger than the poses' uncertainty predicts: the std above is scaled "
            f"up by {math.sqrt(result.scale):.2f}; check the camera model, the QR side and the robot's poses"
        )
    else:
        verdict = "no pose covariances: every pair weighted alike, the std comes from the residuals"
    print(f"chi2/dof {ratio:.2f}: {verdict}; {result.spread.describe()}")
