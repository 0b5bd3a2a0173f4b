"""``qrfield benchmark sessions``: milliseconds to log one confirmed row (average, judge, append, fsync).

Baseline, measured in the same run in the same folder: one raw ``os.write`` of a line of the
same length on an O_APPEND descriptor followed by ``os.fsync`` (the least any crash-safe logger
must do), so the ratio shows what averaging, formatting and the checks add.
"""

from __future__ import annotations

import argparse
import time

from qrfield.methods import NUMERICAL

HELP = "time logging one session row (with fsync) against a raw write + fsync"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count
    from qrfield.limits import MAX_BENCHMARK_COUNT

    parser.add_argument(
        "--rows", type=count("--rows", 0, MAX_BENCHMARK_COUNT), default=200, help="rows to log (default 200)"
    )
    parser.add_argument(
        "--frames",
        type=count("--frames", 0, MAX_BENCHMARK_COUNT),
        default=10,
        help="frames averaged per row (default 10)",
    )
    parser.add_argument("--dir", default=None, help="folder to log in (default: a temporary folder)")


def run(args: argparse.Namespace) -> int:
    import os
    import tempfile

    import numpy as np

    from qrfield.camera import resolve_camera
    from qrfield.sessions import GroundTruth, Session, measure

    if args.rows < 1 or args.frames < 1:
        raise ValueError("--rows and --frames must be at least 1")
    camera = resolve_camera("picam-v2@640x480")
    rng = np.random.default_rng(1)
    with tempfile.TemporaryDirectory(dir=args.dir) as root:
        session = Session.create(root, "bench", camera=camera, side_mm=60.0, solver=NUMERICAL)
        truth = GroundTruth(10.0, -5.0, 350.0, 20.0, -10.0, 5.0, "alpha+beta-")
        frames = [
            {
                "position_mm": np.array([10.0, -5.0, 350.0]) + rng.normal(0, 0.5, 3),
                "angles_deg": np.array([20.0, -10.0, 5.0]) + rng.normal(0, 0.2, 3),
                "converged": True,
                "iterations": 4,
                "reprojection_px": 0.1,
            }
            for _ in range(args.frames)
        ]
        # The first row gives the line length for the baseline; then log and baseline alternate
        # so that both see the same state of the disk and its caches.
        session.log(measure(frames, truth, method=NUMERICAL))
        line = session.rows_path.read_bytes().split(b"\n")[1] + b"\n"
        fd = os.open(os.path.join(root, "baseline.csv"), os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        log_s = base_s = 0.0
        try:
            for _ in range(args.rows):
                t0 = time.perf_counter()
                outcome = session.log(measure(frames, truth, method=NUMERICAL))
                t1 = time.perf_counter()
                os.write(fd, line)
                os.fsync(fd)
                t2 = time.perf_counter()
                if not outcome.ok:
                    raise OSError(outcome.message)
                log_s += t1 - t0
                base_s += t2 - t1
        finally:
            os.close(fd)
            session.close()
        log_ms, base_ms = log_s * 1e3 / args.rows, base_s * 1e3 / args.rows
    print(f"qrfield benchmark sessions: {args.rows} rows of {args.frames} frames, {len(line)} bytes per line")
    print(f"{'log row ms':>11}{'write+fsync ms':>16}{'ratio':>8}")
    print(f"{log_ms:>11.3f}{base_ms:>16.3f}{log_ms / base_ms:>8.2f}")
    return 0
