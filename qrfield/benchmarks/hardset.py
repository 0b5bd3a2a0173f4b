"""``qrfield benchmark hardset``: the make-up of the hard set (:mod:`qrfield.testing.hardset`) that
the detect and pose benchmarks use, and how fast it is made."""

from __future__ import annotations

import numpy as np

from qrfield.testing.hardset import hard_views

HELP = (
    "the hard benchmark set of `qrfield benchmark detect`: its make-up, render time and a check of its truth"
)


def add_arguments(parser) -> None:
    from qrfield.arguments import count, seed
    from qrfield.limits import MAX_BENCHMARK_COUNT

    parser.add_argument(
        "--views",
        type=count("--views", 0, MAX_BENCHMARK_COUNT),
        default=200,
        help="views to describe (default 200)",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=2024)


def run(args) -> int:
    """Print the set's make-up (bands, versions, cameras) and how fast it is made."""
    import collections
    import time

    t0 = time.perf_counter()
    views = list(hard_views(args.views, args.seed))
    ms = (time.perf_counter() - t0) * 1e3 / max(len(views), 1)
    print(f"hard set, seed {args.seed}: {len(views)} views, {ms:.0f} ms a view to make (machine shared)")
    for name, key in (
        ("camera", lambda v: v.camera.name),
        ("module band", lambda v: v.band),
        ("QR version", lambda v: v.version),
        ("side mm", lambda v: v.side_mm),
    ):
        counts = collections.Counter(key(v) for v in views)
        print(f"{name:<12}" + "  ".join(f"{k}: {counts[k]}" for k in sorted(counts)))
    z = np.array([v.pose.position_mm[2] for v in views])
    size = np.array([len(v.text) for v in views])
    print(f"z {z.min():.0f}-{z.max():.0f} mm, payload {size.min()}-{size.max()} bytes")
    return 0
