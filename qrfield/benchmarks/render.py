"""``qrfield benchmark render``: milliseconds per rendered virtual-bench view.

Baseline, measured in the same run: one plain cv2.warpPerspective of a full camera-sized image
(the least any homography renderer must do), so the ratio is comparable across machines.
"""

from __future__ import annotations

import argparse
import time

HELP = "time the virtual bench renderer at 640x480 and 1280x720"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, seed
    from qrfield.limits import MAX_BENCHMARK_COUNT

    parser.add_argument(
        "--views",
        type=count("--views", 0, MAX_BENCHMARK_COUNT),
        default=200,
        help="views per resolution (default 200)",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=1)


def run(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from qrfield.camera import resolve_camera
    from qrfield.render import render_view
    from qrfield.sampling import random_visible_poses

    print(
        f"qrfield benchmark render: {args.views} seeded views per resolution, 50 mm code, noise 2, blur 0.6"
    )
    print(f"{'camera':<22}{'render ms':>11}{'baseline ms':>13}{'ratio':>8}")
    for spec in ("picam-v2@640x480", "picam-v2@1280x960", "webcam-60@1280x720"):
        camera = resolve_camera(spec)
        poses = random_visible_poses(camera, 50.0, args.views, seed=args.seed)
        render_view(camera, 50.0, poses[0])  # warm the caches
        t0 = time.perf_counter()
        for i, pose in enumerate(poses):
            render_view(camera, 50.0, pose, noise_sigma=2.0, blur_px=0.6, seed=i)
        render_ms = (time.perf_counter() - t0) * 1e3 / len(poses)
        src = np.full((camera.height, camera.width), 128, np.uint8)
        h = np.array([[1.01, 0.02, 3.0], [0.01, 0.99, 2.0], [1e-5, 2e-5, 1.0]])
        t0 = time.perf_counter()
        for _ in range(len(poses)):
            cv2.warpPerspective(src, h, (camera.width, camera.height), flags=cv2.INTER_LINEAR)
        base_ms = (time.perf_counter() - t0) * 1e3 / len(poses)
        print(f"{camera.name:<22}{render_ms:>11.2f}{base_ms:>13.2f}{render_ms / base_ms:>8.1f}")
    print("target: under 10 ms per 640x480 view on a 2-core x86_64 machine")
    return 0
