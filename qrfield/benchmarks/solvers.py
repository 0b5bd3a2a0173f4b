"""``qrfield benchmark solvers``: microseconds per pose of each solver beside raw OpenCV, from one run.

Times are CPU time of this process (time.process_time), so that other work on a shared machine
does not inflate them; the solvers are single-threaded. Baseline, measured in the same run on the
same corners: one raw cv2.solvePnP call with
SOLVEPNP_IPPE_SQUARE (no refinement, no conversion), so the ratios are comparable across machines.
Targets: a single numerical solve at most 10x the baseline; the batch at least 200,000 poses/s.
Poses: seeded random visible poses (qrfield.sampling), z 150-800 mm, tilt up to 60 degrees, any
in-plane rotation, exact corners (and, for the converged shares, also 0.5 px Gaussian noise).
"""

from __future__ import annotations

import argparse
import time

from qrfield.camera import DEFAULT_CAMERA
from qrfield.methods import IPPE, NUMERICAL

HELP = "time the numerical and IPPE solvers (single and batch) against a raw cv2.solvePnP call"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, limited, seed
    from qrfield.limits import MAX_BENCHMARK_COUNT, SIDE_MM

    parser.add_argument(
        "--poses",
        type=count("--poses", 0, MAX_BENCHMARK_COUNT),
        default=2000,
        help="seeded poses for single solves (default 2000)",
    )
    parser.add_argument(
        "--batch",
        type=count("--batch", 0, MAX_BENCHMARK_COUNT),
        default=100_000,
        help="poses in the batch (default 100000)",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=1)
    parser.add_argument("--camera", default=DEFAULT_CAMERA, help=f"camera profile (default {DEFAULT_CAMERA})")
    parser.add_argument(
        "--side-mm", type=limited(SIDE_MM, "--side-mm"), default=50.0, help="QR side, mm (default 50)"
    )


def _per_call_us(fn, items) -> float:  # type: ignore[no-untyped-def]
    fn(items[0])  # warm caches
    t0 = time.process_time()
    for item in items:
        fn(item)
    return (time.process_time() - t0) * 1e6 / len(items)


def run(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from qrfield.camera import resolve_camera
    from qrfield.geometry import ippe_object_points
    from qrfield.sampling import random_visible_poses
    from qrfield.sessions.criteria import AcceptanceCriteria
    from qrfield.solvers import SEED_SETTINGS, IppeSettings, NumericalSettings, solve, solve_batch

    camera = resolve_camera(args.camera)
    side = args.side_mm
    poses = random_visible_poses(camera, side, args.poses, seed=args.seed, max_tilt_deg=60.0)
    corners = np.array([p.corners_px(camera, side) for p in poses])
    truth_pos = np.array([p.position_mm for p in poses])
    truth_ang = np.array([p.angles_deg for p in poses])
    rng = np.random.default_rng(args.seed)
    noisy = corners + rng.normal(0.0, 0.5, corners.shape)

    obj = ippe_object_points(side).reshape(4, 1, 3)
    k = camera.K
    dist = camera.dist if camera.has_distortion else None
    base = _per_call_us(
        lambda c: cv2.solvePnP(obj, c.reshape(4, 1, 2), k, dist, flags=cv2.SOLVEPNP_IPPE_SQUARE), corners
    )
    default = NumericalSettings()
    no_mirror = NumericalSettings(mirror=False)
    seed_single = NumericalSettings(initial_guess="seed", tolerance_mm=0.01, stop="seed", mirror=False)
    rows = [
        ("raw cv2.solvePnP IPPE_SQUARE (baseline)", base),
        (
            "numerical single, defaults (+ mirror search)",
            _per_call_us(lambda c: solve(c, camera, side, NUMERICAL, default), corners),
        ),
        (
            "numerical single, no mirror search",
            _per_call_us(lambda c: solve(c, camera, side, NUMERICAL, no_mirror), corners),
        ),
        (
            "numerical single, thesis settings",
            _per_call_us(lambda c: solve(c, camera, side, NUMERICAL, seed_single), corners),
        ),
        (
            "numerical single, defaults, 0.5 px noise",
            _per_call_us(lambda c: solve(c, camera, side, NUMERICAL, default), noisy),
        ),
        (
            "numerical single, no mirror search, 0.5 px noise",
            _per_call_us(lambda c: solve(c, camera, side, NUMERICAL, no_mirror), noisy),
        ),
        (
            "ippe single (both candidates, LM refined)",
            _per_call_us(lambda c: solve(c, camera, side, IPPE), corners),
        ),
        (
            "ippe single (both candidates, VVS refined)",
            _per_call_us(lambda c: solve(c, camera, side, IPPE, IppeSettings(refine="vvs")), corners),
        ),
        (
            "ippe single (both candidates, not refined)",
            _per_call_us(lambda c: solve(c, camera, side, IPPE, IppeSettings(refine="none")), corners),
        ),
    ]
    reps = -(-args.batch // len(corners))
    big = np.tile(corners, (reps, 1, 1))[: args.batch]
    for label, settings in (("defaults", default), ("thesis settings", SEED_SETTINGS)):
        solve_batch(big[:1000], camera, side, settings=settings)
        t0 = time.process_time()
        solve_batch(big, camera, side, settings=settings)
        rows.append(
            (f"numerical batch of {len(big)}, {label}, per pose", (time.process_time() - t0) * 1e6 / len(big))
        )

    print(
        f"qrfield benchmark solvers: camera {camera.name}, QR {side:g} mm, {len(corners)} seeded poses "
        "(z 150-800 mm, tilt <= 60 deg, any in-plane turn), exact corners unless marked; CPU time"
    )
    print(f"{'solve':<52}{'us/pose':>10}{'x baseline':>12}{'poses/s':>12}")
    for label, us in rows:
        print(f"{label:<52}{us:>10.2f}{us / base:>12.2f}{1e6 / us:>12.0f}")

    criteria = AcceptanceCriteria()
    print()
    print(
        f"converged share, mean iterations, and share meeting the seed's criteria ({criteria.label()}) "
        "among all poses; numerical by the batch path:"
    )
    print(f"{'settings':<48}{'corners':<10}{'converged':>10}{'iter':>7}{'pass':>8}")
    configs = [
        ("thesis (seed guess, seed stop, tol 0.01 mm)", SEED_SETTINGS),
        ("parallelogram guess, seed stop, tol 0.01 mm", NumericalSettings(stop="seed", tolerance_mm=0.01)),
        ("seed guess, settled stop, tol 1 mm", NumericalSettings(initial_guess="seed")),
        ("defaults (parallelogram, settled, tol 1 mm)", default),
    ]
    for label, settings in configs:
        for data_label, data in (("exact", corners), ("0.5 px", noisy)):
            b = solve_batch(data, camera, side, settings=settings)
            ok = b.converged & criteria.judge(b.position_mm, b.angles_deg, truth_pos, truth_ang)[0]
            print(
                f"{label:<48}{data_label:<10}{b.converged.mean():>10.4f}{b.iterations.mean():>7.2f}{ok.mean():>8.4f}"
            )
    for data_label, data in (("exact", corners), ("0.5 px", noisy)):
        b = solve_batch(data, camera, side, method=IPPE)
        ok = b.converged & criteria.judge(b.position_mm, b.angles_deg, truth_pos, truth_ang)[0]
        label = "ippe (LM refined)"
        print(f"{label:<48}{data_label:<10}{b.converged.mean():>10.4f}{0.0:>7.2f}{ok.mean():>8.4f}")
    print("targets: numerical single <= 10x baseline; batch >= 200000 poses/s")
    return 0
