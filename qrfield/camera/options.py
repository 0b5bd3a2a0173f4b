"""The commands' camera options: `--camera`, `--focal-px`, `--size`, and the model they name."""

from __future__ import annotations

from typing import Any

from qrfield.camera.fields import CameraModelError
from qrfield.camera.model import CameraModel
from qrfield.camera.profiles import parse_size, resolve_camera
from qrfield.limits import FOCAL_PX, LimitError


def add_camera_arguments(parser: Any, default: str | None = None, focal_only: bool = False) -> None:
    """Add ``--camera``, ``--focal-px`` and ``--size`` to an argparse parser.

    ``focal_only``: the command takes images, whose own size serves when ``--size`` is left out
    (see :func:`camera_from_args`).
    """
    parser.add_argument(
        "--camera",
        default=default,
        metavar="CAM",
        help="camera profile NAME[@WxH] (your profiles in ~/.config/qrfield/calib, then the presets "
        "picam-v1, picam-v2, picam-v3, picam-hq-6mm, webcam-60) or PATH.json[@WxH]; the file used is printed",
    )
    from qrfield.arguments import limited

    parser.add_argument(
        "--focal-px",
        type=limited(FOCAL_PX, "--focal-px"),
        metavar="F",
        help=f"focal length in pixels ({FOCAL_PX.describe()}), with --size"
        + (
            " (with IMAGE files, --size may be left out: each image's own size is taken)"
            if focal_only
            else ""
        ),
    )
    parser.add_argument("--size", metavar="WxH", help="image size for --focal-px, e.g. 640x480")
    # Remembered so that camera_from_args can tell a default --camera from one the user typed.
    parser.set_defaults(_camera_default=default)


def camera_from_args(args: Any, focal_only: bool = False) -> CameraModel | None:
    """The camera named by ``--camera`` or ``--focal-px``/``--size``.

    ``--focal-px``/``--size`` win over a default ``--camera``; CameraModelError if neither is
    given, or if both a typed ``--camera`` and ``--focal-px``/``--size`` are (which one was meant?).
    ``focal_only``: ``--focal-px`` without ``--size`` is accepted and gives None: the caller makes
    :meth:`CameraModel.from_focal` at each image's own size (``args.focal_px``).
    """
    focal, size = getattr(args, "focal_px", None), getattr(args, "size", None)
    if focal is not None or size is not None:
        camera = getattr(args, "camera", None)
        if camera and camera != getattr(args, "_camera_default", None):
            raise CameraModelError(f"give either --camera ({camera}) or --focal-px/--size, not both")
        if focal is not None and size is None and focal_only:
            _checked_focal(focal)
            return None
        if focal is None or size is None:
            raise CameraModelError("--focal-px and --size go together, e.g. --focal-px 620 --size 640x480")
        width, height = parse_size(size)
        return CameraModel.from_focal(_checked_focal(focal), width, height)
    if not getattr(args, "camera", None):
        raise CameraModelError("name a camera: --camera NAME[@WxH] or --focal-px F --size WxH")
    return resolve_camera(args.camera)


def _checked_focal(focal: Any) -> float:
    try:
        return FOCAL_PX.check(focal, "--focal-px")
    except LimitError as exc:
        raise CameraModelError(str(exc)) from None
