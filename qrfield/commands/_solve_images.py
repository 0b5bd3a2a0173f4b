"""``qrfield solve IMAGE...``: detect the QR code in each image and solve its pose.

One entry per (image, code, method); an image without a usable code, or a file that cannot be
read, gets one entry with ``"corners": null`` and a ``"status"`` saying why (never a traceback).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from qrfield.camera import CameraModel, CameraModelError


def _camera_for(
    camera: CameraModel | None, focal_px: float | None, image: Any
) -> tuple[CameraModel | None, str]:
    """The camera at the image's size (a rescaled profile of the same sensor mode; or, given only
    ``focal_px``, the focal-only model at the image's own size), or why not."""
    height, width = image.shape[:2]
    if camera is None:
        try:
            return CameraModel.from_focal(float(focal_px or 0.0), width, height), ""
        except CameraModelError as exc:
            return None, f"image is {width}x{height}: {exc}"
    if (width, height) == (camera.width, camera.height):
        return camera, ""
    try:
        return camera.scaled(width, height), ""
    except CameraModelError as exc:
        return (
            None,
            f"image is {width}x{height}, camera {camera.name} is {camera.width}x{camera.height}: {exc}",
        )


def _say_several(path: str, detections: list[Any], chosen: Any, select_text: str) -> None:
    """One stderr line: how many codes ``path`` shows and which one is solved (select_code's rule)."""
    rule = f"the largest with text {select_text!r}" if select_text else f"the largest, text {chosen.text!r}"
    others = sorted({repr(d.text) for d in detections if d is not chosen})
    print(
        f"qrfield solve: {path}: {len(detections)} codes in view (others: {', '.join(others)}); "
        f"solving {rule}; --all-codes solves each, --detect-select-text TEXT picks one",
        file=sys.stderr,
    )


def solve_images(
    args: argparse.Namespace, camera: CameraModel | None, methods: tuple[str, ...], settings: dict[str, Any]
) -> int:
    """Detect and solve each of ``args.images`` (files, folders, globs); print a table or JSON;
    exit 0 when all converged. ``camera`` None: ``args.focal_px`` at each image's own size."""
    from qrfield.commands.solve import format_table
    from qrfield.detect import Detector, DetectorSettings, select_code
    from qrfield.images import ImageError, ImageSettings, expand_image_paths, read_image
    from qrfield.settings import from_arguments
    from qrfield.solvers import SolverError, solve

    detector_settings = from_arguments(DetectorSettings, args, prefix="detect-")
    image_settings = from_arguments(ImageSettings, args)
    detector = Detector(detector_settings)
    entries: list[dict[str, Any]] = []
    all_ok = True
    for path in expand_image_paths(args.images):
        cam, status = None, ""
        try:
            # A grey file stays grey (a third of the memory; the detector's grey of it is the same).
            image = read_image(path, image_settings, mode="any")
        except ImageError as exc:
            image, status = None, str(exc).removeprefix(f"{path}: ")
        if image is not None:
            cam, status = _camera_for(camera, args.focal_px, image)
        detections = []
        if cam is not None:
            detector.set_camera(cam)  # the whole-symbol fit goes through this camera's lens
            detections = detector.detect(image)
            if not args.all_codes:
                chosen = select_code(detections, detector_settings.select_text)
                if chosen is not None and len(detections) > 1:
                    # Said, not done silently: the pose printed may be of another code than meant.
                    _say_several(path, detections, chosen, detector_settings.select_text)
                detections = [chosen] if chosen is not None else []
            if not detections:
                status = (
                    f"no QR code with text {detector_settings.select_text!r} found"
                    if detector_settings.select_text
                    else "no QR code found"
                )
        if not detections:
            all_ok = False
            entries.append({"image": path, "text": None, "corners": None, "status": status})
            if not args.json:
                print(f"{path}: {status}")
            continue
        for d in detections:
            results = []
            for method in methods:
                try:
                    results.append(
                        solve(d.corners_px, cam, args.side_mm, method, settings[method], d.pose_cov)
                    )
                except SolverError as exc:
                    entries.append(
                        {
                            "image": path,
                            "text": d.text,
                            "corners": d.to_json_dict()["corners"],
                            "method": method,
                            "status": f"cannot solve: {exc}",
                        }
                    )
                    all_ok = False
            for r in results:
                entry = {"image": path, "text": d.text, **r.to_json_dict()}
                if d.untrusted:
                    entry["status"] = f"not trusted: {d.untrusted}"
                else:
                    entry["status"] = "ok" if r.converged else f"not converged: {r.reason}"
                entry["detection"] = {
                    k: v for k, v in d.to_json_dict().items() if k not in ("corners", "text")
                }
                entries.append(entry)
                all_ok &= bool(r.converged) and not d.untrusted
            if not args.json:
                kind = "sub-pixel" if d.refined else "backend corners, not refined"
                print(
                    f"{path}: text {d.text!r}, quality {d.quality:.2f} ({kind}, {d.backend}); "
                    f"camera {cam.name} ({cam.width}x{cam.height}), QR side {args.side_mm:g} mm"
                )
                print(format_table(results))
                if d.untrusted:
                    print(f"  not trusted: {d.untrusted}")
    if args.json:
        json.dump(entries, sys.stdout, allow_nan=False)
        print()
    return 0 if all_ok else 1
