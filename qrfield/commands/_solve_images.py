"""``qrfield solve IMAGE...``: detect the QR code in each image and solve its pose.

One entry per (image, code, method); an image without a usable code, or a file that cannot be
read, gets one entry with ``"corners": null`` and a ``"status"`` saying why (never a traceback).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from qrfield.camera import CameraModel, CameraModelError


def _read(path: str) -> tuple[Any, str]:
    """(BGR or grey uint8 image, "") or (None, why not)."""
    import cv2
    import numpy as np

    file = Path(path)
    if not file.is_file():
        return (
            None,
            "cannot read image: no such file" if not file.exists() else "cannot read image: not a file",
        )
    try:
        data = np.fromfile(file, dtype=np.uint8)
    except OSError as exc:
        return None, f"cannot read image: {exc.strerror or exc}"
    image = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if image is None:
        return None, "cannot read image: not an image format OpenCV can decode"
    return image, ""


def _camera_for(camera: CameraModel, image: Any) -> tuple[CameraModel | None, str]:
    """The camera at the image's size (a rescaled profile of the same sensor mode), or why not."""
    height, width = image.shape[:2]
    if (width, height) == (camera.width, camera.height):
        return camera, ""
    try:
        return camera.scaled(width, height), ""
    except CameraModelError as exc:
        return (
            None,
            f"image is {width}x{height}, camera {camera.name} is {camera.width}x{camera.height}: {exc}",
        )


def solve_images(
    args: argparse.Namespace, camera: CameraModel, methods: tuple[str, ...], settings: dict[str, Any]
) -> int:
    """Detect and solve each of ``args.images``; print a table or JSON; exit 0 when all converged."""
    from qrfield.commands.solve import format_table
    from qrfield.detect import Detector, DetectorSettings, select_code
    from qrfield.settings import from_arguments
    from qrfield.solvers import SolverError, solve

    detector_settings = from_arguments(DetectorSettings, args, prefix="detect-")
    detector = Detector(detector_settings)
    entries: list[dict[str, Any]] = []
    all_ok = True
    for path in args.images:
        image, status = _read(path)
        cam = None
        if image is not None:
            cam, status = _camera_for(camera, image)
        detections = []
        if cam is not None:
            detector.set_camera(cam)  # the whole-symbol fit goes through this camera's lens
            detections = detector.detect(image)
            if not args.all_codes:
                chosen = select_code(detections, detector_settings.select_text)
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
