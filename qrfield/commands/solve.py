"""``qrfield solve``: the pose of a QR code from its four corner pixels."""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from typing import Any

from qrfield.arguments import add_side_argument, number, parse_numbers
from qrfield.camera import add_camera_arguments
from qrfield.geometry import VERTEX_NAMES
from qrfield.methods import BOTH, METHOD_CHOICES, methods_from_choice

HELP = "compute a QR code's position (mm) and orientation (degrees) from images or its four corner pixels"
DESCRIPTION = (
    "Compute the pose of one QR code of known side, found in each IMAGE (detected, sub-pixel corners) "
    "or given by --corners V1..V4 (top-left, top-right, bottom-right, bottom-left of the code, clockwise "
    "on screen), with the thesis' numerical model, OpenCV's IPPE, or both. Positions are the code's "
    "centre in the camera frame (mm, +X right, +Y down, +Z forward); angles alpha, beta, gamma "
    "(degrees) with R = Rx(alpha) Ry(beta) Rz(gamma)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.images import ImageSettings
    from qrfield.settings import add_arguments as add_setting_arguments
    from qrfield.solvers.ippe import IppeSettings
    from qrfield.solvers.numerical import NumericalSettings

    parser.add_argument(
        "images",
        nargs="*",
        metavar="IMAGE",
        help="image files, folders (their images, by name) or quoted glob patterns ('shots/*.png', "
        "'**/*.jpg') to detect the code in and solve (instead of --corners); one process for all",
    )
    parser.add_argument(
        "--corners",
        metavar='"U1,V1 U2,V2 U3,V3 U4,V4"',
        help="pixels of V1..V4 (OpenCV convention: the top-left pixel's centre is 0,0); 8 numbers "
        "separated by commas or spaces; --corners=-3,5,... works too",
    )
    parser.add_argument(
        "--corner-std-px",
        type=number("--corner-std-px", 0.0, 1000.0, "px"),
        metavar="S",
        help="with --corners: the corners' standard uncertainty, px per coordinate (independent "
        "corners), propagated to the pose's std and used by the flip test; without it the std "
        "fields are null (with IMAGE the detector's own corner covariance is used)",
    )
    add_camera_arguments(parser, focal_only=True)
    add_side_argument(parser)
    parser.add_argument("--method", choices=METHOD_CHOICES, default=BOTH, help="solver (default: both)")
    parser.add_argument(
        "--json",
        action="store_true",
        help="print a JSON list, one object per method (with IMAGE: per image, code and method, each with "
        '"image", "text" and "status"; "corners": null where no code was found)',
    )
    parser.add_argument(
        "--all-codes",
        action="store_true",
        help="with IMAGE: solve every code found, not only the one selected "
        "(--detect-select-text, or the largest)",
    )
    from qrfield.detect import DetectorSettings

    group = parser.add_argument_group("detection settings (with IMAGE)")
    add_setting_arguments(group, DetectorSettings, prefix="detect-")  # type: ignore[arg-type]
    group = parser.add_argument_group("image files (with IMAGE)")
    add_setting_arguments(group, ImageSettings)  # type: ignore[arg-type]
    group = parser.add_argument_group("numerical model settings")
    add_setting_arguments(group, NumericalSettings)  # type: ignore[arg-type]
    group = parser.add_argument_group("IPPE settings")
    add_setting_arguments(group, IppeSettings)  # type: ignore[arg-type]


def parse_corners(text: str) -> list[list[float]]:
    """``"u1,v1 u2,v2 u3,v3 u4,v4"`` (pairs separated by spaces or ';'), or 8 numbers separated by
    commas, -> [[u1, v1], ...]. ValueError naming --corners and what is malformed."""
    pairs = re.split(r"[;\s]+", text.strip()) if text.strip() else []
    if len(pairs) == 1:  # "u1,v1,u2,v2,...": 8 numbers, paired in order
        values = parse_numbers(pairs[0], "--corners")
        pairs = [f"{values[k]!r},{values[k + 1]!r}" for k in range(0, len(values) - 1, 2)]
        if len(values) % 2:
            pairs.append(repr(values[-1]))
    if len(pairs) != 4:
        raise ValueError(
            "--corners needs 4 pixel pairs 'u,v' separated by spaces (V1 V2 V3 V4), or 8 numbers "
            f"separated by commas; got {len(pairs)} pairs: {text!r}"
        )
    return [
        parse_numbers(pair, "--corners", names=(f"{name} u", f"{name} v"))
        for name, pair in zip(VERTEX_NAMES, pairs, strict=True)
    ]


def _fmt(value: float | None, digits: int) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def misfit_warning(result: Any) -> str:
    """The warning for a PoseResult whose fit's chi-square exceeds FIT_CHI2 (``result.misfit``)."""
    from qrfield.solvers.uncertainty import FIT_CHI2

    return (
        f"WARNING {result.method}: the corners do not fit the pose: {result.reprojection_px:.2f} px RMS off "
        f"its projection, chi-square {result.chi2:.3g}, above {FIT_CHI2}, the 99 % bar of the corners' own "
        "uncertainty; the std assumes a right camera model, QR side and corners and is too small: check "
        "--camera / --focal-px, --side-mm and the corners (docs/uncertainty.md)"
    )


def format_table(results: list) -> str:  # type: ignore[type-arg]
    """A human-readable table of PoseResults: one row per result (and one per mirror candidate)."""
    header = (
        f"{'method':<18}{'x mm':>9}{'y mm':>9}{'z mm':>9}{'alpha':>9}{'beta':>9}{'gamma':>9}"
        f"{'conv':>6}{'iter':>6}{'reproj px':>11}{'resid mm':>10}{'ambig':>8}{'flip?':>7}"
    )
    lines = [header, "-" * len(header)]
    notes = []
    for r in results:
        rows = [(r.method, r)]
        if r.alternative is not None:
            rows.append((f"  {r.method} mirror", r.alternative))
        for label, p in rows:
            x, y, z = p.position_mm
            a, b, g = p.angles_deg
            amb = r.ambiguity if p is r else None
            flip = ("yes" if r.ambiguous else "no") if p is r else ""
            lines.append(
                f"{label:<18}{_fmt(x, 1):>9}{_fmt(y, 1):>9}{_fmt(z, 1):>9}{_fmt(a, 2):>9}{_fmt(b, 2):>9}"
                f"{_fmt(g, 2):>9}{'yes' if p.converged else 'no':>6}{p.iterations:>6}"
                f"{_fmt(p.reprojection_px, 4):>11}{_fmt(p.residual_mm, 4):>10}{_fmt(amb, 3):>8}{flip:>7}"
            )
            stds = [*p.position_std_mm, *p.angles_std_deg]
            if any(math.isfinite(v) for v in stds):
                cells = "".join(f"{'+-' + _fmt(v, 2):>9}" for v in stds)
                lines.append(f"{'  std':<18}{cells}")
            if p.reason:
                notes.append(f"{label.strip()}: {p.reason}")
            if p is r and r.misfit:
                notes.append(misfit_warning(r))
    lines.append("angles in degrees: R = Rx(alpha) Ry(beta) Rz(gamma); position = QR centre, camera frame")
    if any(r.ambiguous for r in results):
        lines.append(
            "flip? yes: the mirror pose also fits the corners within their uncertainty; the pose may be "
            "its mirror image (docs/uncertainty.md)"
        )
    lines.extend(notes)
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from qrfield.camera import camera_from_args, say_camera
    from qrfield.limits import check_corners_in_view
    from qrfield.settings import from_arguments
    from qrfield.solvers import settings_classes, solve

    if bool(args.images) == (args.corners is not None):
        raise ValueError("give either IMAGE files or --corners (one of them)")
    if args.images and args.corner_std_px is not None:
        raise ValueError(
            "--corner-std-px goes with --corners; with IMAGE the corner uncertainty comes from the detector"
        )
    camera = camera_from_args(args, focal_only=bool(args.images))
    methods = methods_from_choice(args.method)
    settings = {method: from_arguments(cls, args) for method, cls in settings_classes().items()}
    if args.images:
        from qrfield.commands._solve_images import solve_images

        if camera is not None:
            say_camera(camera, "solve")
        return solve_images(args, camera, methods, settings)
    if camera is None:  # pragma: no cover - camera_from_args gives None only with images
        raise ValueError("--focal-px without --size needs IMAGE files")
    corners = parse_corners(args.corners)
    check_corners_in_view(corners, camera.width, camera.height)
    say_camera(camera, "solve")
    cov = None
    if args.corner_std_px is not None:
        from qrfield.solvers.uncertainty import isotropic_cov

        cov = isotropic_cov(args.corner_std_px)  # ValueError naming the number when it is unusable
    results = [solve(corners, camera, args.side_mm, method, settings[method], cov) for method in methods]
    if args.json:
        json.dump([r.to_json_dict() for r in results], sys.stdout, allow_nan=False)
        print()
    else:
        print(f"camera {camera.name} ({camera.width}x{camera.height}), QR side {args.side_mm:g} mm")
        print(format_table(results))
    return 0 if all(r.converged for r in results) else 1
