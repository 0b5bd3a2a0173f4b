"""``qrfield render``: write a rendered virtual-bench view and print its exact vertex pixels."""

from __future__ import annotations

import argparse
import json
import sys

from qrfield.arguments import add_side_argument, number, refuse_existing, seed, text
from qrfield.camera import DEFAULT_CAMERA, add_camera_arguments
from qrfield.geometry import VERTEX_NAMES

HELP = "render a QR card at a known pose through a camera model (test images with exact corners)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_camera_arguments(parser, default=DEFAULT_CAMERA)
    add_side_argument(parser)
    parser.add_argument(
        "--pose",
        required=True,
        metavar="X,Y,Z,A,B,G",
        help="QR centre in the camera frame (mm) and alpha,beta,gamma (degrees), e.g. 0,0,300,10,20,0; "
        "a negative first value works as it is: --pose -10,5,300,0,0,0",
    )
    parser.add_argument(
        "--noise",
        type=number("--noise", 0.0, 255.0, "grey levels"),
        default=0.0,
        metavar="SIGMA",
        help="Gaussian noise, grey levels (0..255)",
    )
    parser.add_argument(
        "--blur",
        type=number("--blur", 0.0, 100.0, "px"),
        default=0.0,
        metavar="PX",
        help="Gaussian blur sigma, pixels (0..100)",
    )
    parser.add_argument(
        "--gradient",
        type=number("--gradient", 0.0, 1.0),
        default=0.0,
        help="brightness gradient across the image (0..1; 0.3 = +-30%%)",
    )
    parser.add_argument("--seed", type=seed(), default=None, help="noise seed (repeatable images)")
    parser.add_argument(
        "--text", type=text("--text"), default="qrfield", help="QR payload (default: qrfield)"
    )
    parser.add_argument("--color", action="store_true", help="write a 3-channel colour image")
    parser.add_argument(
        "--out", required=True, metavar="FILE", help="image file to write (.png, .jpg, .bmp, ...)"
    )
    parser.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    parser.add_argument("--json", action="store_true", help='print {"corners": [[u,v],...], ...} as JSON')


def run(args: argparse.Namespace) -> int:
    from qrfield.camera import camera_from_args, say_camera
    from qrfield.files import check_target
    from qrfield.geometry import Pose
    from qrfield.images import ImageSettings, check_pixels, write_image
    from qrfield.render import render_view

    camera = camera_from_args(args)
    assert camera is not None
    pose = Pose.parse(args.pose, "--pose")
    check_pixels(camera.width, camera.height, ImageSettings(), f"camera {camera.name}")
    out = check_target(args.out, "--out")
    refuse_existing(out, args.force)
    view = render_view(
        camera,
        args.side_mm,
        pose,
        text=args.text,
        noise_sigma=args.noise,
        blur_px=args.blur,
        gradient=args.gradient,
        seed=args.seed,
        color=args.color,
    )
    write_image(out, view.image, overwrite=args.force)
    say_camera(camera, "render")
    corners = [[round(float(u), 4), round(float(v), 4)] for u, v in view.corners_px]
    if args.json:
        json.dump(
            {
                "corners": corners,
                "image": args.out,
                "camera": camera.to_dict(),
                "side_mm": args.side_mm,
                "pose": {
                    "position_mm": view.pose.position_mm.tolist(),
                    "angles_deg": view.pose.angles_deg.tolist(),
                },
                "text": args.text,
            },
            sys.stdout,
        )
        print()
    else:
        print(f"wrote {args.out} ({camera.width}x{camera.height}, camera {camera.name})")
        for name, (u, v) in zip(VERTEX_NAMES, corners, strict=True):
            print(f"{name}: u={u:.3f} v={v:.3f} px")
    return 0
