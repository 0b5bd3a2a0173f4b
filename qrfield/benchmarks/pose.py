"""``qrfield benchmark pose``: is the pose's uncertainty honest, and how often is the pose right?

1. Uncertainty calibration with injected corner noise (independent truth): seeded poses (sides
   30/50/100 mm, z 150-1000 mm, tilt <= 60 deg, pinhole and a distorted lens), the exact vertex
   pixels plus Gaussian noise of a known, per-corner anisotropic covariance (0.01-1 px), solved
   with that covariance. Per method and component: RMS of (estimate - truth) / std and the share
   within 2 (targets 0.7-1.4 and 90-99 %), over the views the mirror test leaves unflagged (near
   the planar ambiguity the linearisation fails: that is what the flag is for) and over all.
2. The flip flag on the same views: recall and precision of ``ambiguous`` on flips (an angle more
   than 10 deg off), for the chi-square test and, for comparison, the fallback without covariance.
3. End to end on pictures (``--view-set``, default "hard": benchmark detect's hard set,
   qrfield/testing/hardset.py; "render": qrfield.render views), through the default pipeline:
   share of views that meet the thesis' criteria (2 deg, 5 mm) by module size and lens, for each
   qrfield method beside OpenCV's QRCodeDetectorAruco + IPPE_SQUARE + RefineLM and zxing-cpp
   corners + SQPNP, and the ceiling (true corners + 0.05 px noise); why qrfield's views miss; the
   calibration of the std and the flip flag on the pictures (qrfield/benchmarks/_pose_pictures.py).
4. Real optics: squares of 4 inner corners of the real Bumblebee2 chessboard frames
   (../shared/data/calibration), solved through BoofCV's calibration, against cv2.solvePnP on the
   whole board (qrfield/testing/real_squares.py, printed by qrfield/benchmarks/_pose_real.py).
5. Cost: CPU microseconds per solve with and without a covariance (baseline: without).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.geometry import POSE_NAMES
from qrfield.methods import IPPE, NUMERICAL
from qrfield.testing.corner_noise import draw_noise, random_corner_cov

HELP = "pose uncertainty calibration, flip flag recall/precision, end to end vs OpenCV and zxing, real optics"

#: Angle error beyond which a pose counts as a flip (the issue's definition), degrees.
FLIP_DEG = 10.0
#: The calibration targets (docs/conventions.md "Pose uncertainty"; docs/benchmarks.md, "pose").
RMS_RANGE = (0.7, 1.4)
WITHIN_2_RANGE = (0.90, 0.99)
#: Module-size bands of the end-to-end table, px.
BANDS = ((0.0, 1.2), (1.2, 2.0), (2.0, 3.0), (3.0, math.inf))
COMPONENTS = POSE_NAMES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, seed
    from qrfield.limits import MAX_BENCHMARK_COUNT
    from qrfield.testing.pose_views import VIEW_SETS

    parser.add_argument(
        "--poses",
        type=count("--poses", 0, MAX_BENCHMARK_COUNT),
        default=3000,
        help="corner-level views for 1-2 (default 3000)",
    )
    parser.add_argument(
        "--views",
        type=count("--views", 0, MAX_BENCHMARK_COUNT),
        default=400,
        help="pictures for 3 (default 400)",
    )
    parser.add_argument(
        "--view-set",
        choices=sorted(VIEW_SETS),
        default="hard",
        help="picture set for 3 (default hard: benchmark detect's hard set)",
    )
    parser.add_argument(
        "--view-seed",
        type=seed("--view-seed"),
        default=2024,
        help="seed of the picture set (default 2024, as benchmark detect)",
    )
    parser.add_argument(
        "--cost-views",
        type=count("--cost-views", 0, MAX_BENCHMARK_COUNT),
        default=400,
        help="views timed for 5 (default 400)",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=1)
    parser.add_argument("--data", type=Path, default=None, help="shared data folder (default ../shared/data)")


# ---------------------------------------------------------------------- helpers


def pose_errors(result: Any, truth: Any) -> np.ndarray:
    """(6,) estimate minus truth: x, y, z in mm, alpha, beta, gamma in degrees (wrapped)."""
    from qrfield.geometry import angle_difference

    return np.concatenate(
        [result.position_mm - truth.position_mm, angle_difference(result.angles_deg, truth.angles_deg)]
    )


def z_scores(result: Any, truth: Any) -> np.ndarray:
    """(6,) (estimate - truth) / std per component."""
    return pose_errors(result, truth) / np.concatenate([result.position_std_mm, result.angles_std_deg])


def calibration_line(label: str, z: np.ndarray) -> tuple[str, bool]:
    """One table line of RMS z and share within 2 per component, and whether both targets hold."""
    if z.size == 0:
        return f"{label:<34}{'-':>7}", False
    rms = np.sqrt(np.nanmean(z**2, axis=0))
    within = np.nanmean(np.abs(z) < 2.0, axis=0)
    ok = bool(
        np.all((rms >= RMS_RANGE[0]) & (rms <= RMS_RANGE[1]))
        and np.all((within >= WITHIN_2_RANGE[0]) & (within <= WITHIN_2_RANGE[1]))
    )
    cells = "".join(f"{r:>6.2f}/{100 * w:>4.1f}" for r, w in zip(rms, within, strict=True))
    return f"{label:<34}{len(z):>7}{cells}", ok


def recall_precision(flag: np.ndarray, flip: np.ndarray) -> tuple[float, float]:
    hits = float(np.sum(flag & flip))
    return hits / max(float(np.sum(flip)), 1.0), hits / max(float(np.sum(flag)), 1.0)


# ---------------------------------------------------------------------- 1 + 2: injected noise


def _methods() -> list[tuple[str, str, Any]]:
    from qrfield.solvers import SEED_SETTINGS, IppeSettings

    return [
        ("numerical (defaults)", NUMERICAL, None),
        ("ippe (LM refined)", IPPE, None),
        ("numerical, thesis settings", NUMERICAL, SEED_SETTINGS),
        ("ippe, not refined", IPPE, IppeSettings(refine="none")),
    ]


def injected_noise(count: int, seed: int) -> bool:
    from qrfield.solvers import solve
    from qrfield.testing.pose_views import corner_set

    views = corner_set(count, seed)
    rng = np.random.default_rng(seed + 7)
    draws = []
    for _ in views:
        cov = random_corner_cov(rng)
        draws.append((cov, draw_noise(rng, cov)))
    print(
        f"1. uncertainty calibration, injected noise: {len(views)} seeded poses (sides 30/50/100 mm, "
        "z 150-1000 mm, tilt <= 60 deg; pinhole picam-v2@640x480 and a distorted lens alternately),\n"
        "   exact vertex pixels + Gaussian noise of a known per-corner covariance (0.01-1 px, aspect "
        "<= 3:1), solved with that covariance."
    )
    print("   per component: RMS of (estimate - truth) / std / % within 2 (targets 0.70-1.40 / 90-99 %)")
    header = "".join(f"{c:>12}" for c in COMPONENTS)
    print(f"{'method, views':<34}{'n':>7}{header}")
    all_ok = True
    flips: dict[str, tuple[np.ndarray, ...]] = {}
    for label, method, settings in _methods():
        z, flagged, flip, chi2, chi2_m, fallback = [], [], [], [], [], []
        converged = 0
        for view, (cov, noise) in zip(views, draws, strict=True):
            corners = view.corners_px + noise
            r = solve(corners, view.camera, view.side_mm, method, settings, corners_cov=cov)
            if not r.converged:
                continue
            converged += 1
            z.append(z_scores(r, view.truth))
            flagged.append(r.ambiguous)
            flip.append(np.max(np.abs(pose_errors(r, view.truth)[3:])) > FLIP_DEG)
            chi2.append(r.chi2)
            chi2_m.append(r.mirror_chi2)
            plain = solve(corners, view.camera, view.side_mm, method, settings)
            fallback.append(plain.ambiguous)
        zs, amb = np.array(z).reshape(-1, 6), np.array(flagged, dtype=bool)
        line, ok = calibration_line(f"{label}, unflagged", zs[~amb])
        print(line + ("  meets" if ok else "  MISSES") + " the targets")
        print(calibration_line(f"{label}, all converged", zs)[0])
        share = f"{amb.mean():.1%}" if amb.size else "-"
        print(f"   converged {converged}/{len(views)}, flagged ambiguous {share}")
        if settings is None:  # the defaults of each method carry the targets
            all_ok &= ok
        flips[label] = (amb, np.array(flip, bool), np.array(chi2), np.array(chi2_m), np.array(fallback, bool))
    print(
        "   (thesis settings stop early at the tolerance, not at the least-squares optimum the std "
        "describes; 'not refined' is the closed form, not the least-squares fit)"
    )
    _flip_table(flips)
    return all_ok


def _flip_table(flips: dict[str, tuple[np.ndarray, ...]]) -> None:
    from qrfield.solvers.uncertainty import AMBIGUITY_FALLBACK, FLIP_DELTA_CHI2

    print(
        f"\n2. flip flag on the same views: flip = an angle more than {FLIP_DEG:g} deg off; "
        f"ambiguous = mirror chi-square - answer chi-square < {FLIP_DELTA_CHI2:g} (the default)"
    )
    print("   target: recall >= 90 % at precision >= 50 %")
    print(
        f"{'method':<30}{'flips':>7}{'flagged':>9}{'recall':>9}{'precision':>11}"
        "  other thresholds (recall/precision)"
    )
    for label, (amb, flip, chi2, chi2_m, fallback) in flips.items():
        if not flip.any():
            print(f"{label:<30}{0:>7}{int(amb.sum()):>9}   (no flip among these views)")
            continue
        recall, precision = recall_precision(amb, flip)
        others = []
        for delta in (2.0, 4.0, 6.0, 16.0):
            r, p = recall_precision(chi2_m - chi2 < delta, flip)
            others.append(f"{delta:g}: {100 * r:.0f}/{100 * p:.0f}")
        r_fb, p_fb = recall_precision(fallback, flip)
        print(
            f"{label:<30}{int(flip.sum()):>7}{int(amb.sum()):>9}"
            f"{100 * recall:>8.1f}%{100 * precision:>10.1f}%  "
            + ", ".join(others)
            + f"; no covariance (ratio >= {AMBIGUITY_FALLBACK:g}): {100 * r_fb:.0f}/{100 * p_fb:.0f}"
        )
    print(
        "   The best-fitting branch is the wrong one at most about half the time when both fit (the\n"
        "   posterior of each branch is exp(-chi2 / 2)), so for a solver that reports the better fit\n"
        "   no flag can reach a precision of 50 %; the numerical model sometimes reports the worse fit."
    )


# ---------------------------------------------------------------------- 3: end to end


def end_to_end(count: int, seed: int, view_set: str) -> bool:
    """Section 3 (qrfield/benchmarks/_pose_pictures.py); True when qrfield meets the issue's targets."""
    from qrfield.benchmarks import _pose_pictures
    from qrfield.testing.pose_views import VIEW_SETS

    print(
        f"\n3. end to end on pictures: view set {view_set!r}, {count} seeded views (seed {seed}), each "
        "through the default pipeline (tracker, DetectorSettings(), the camera model, every method with the "
        f"detection's covariance); the ceiling: true corners + {_pose_pictures.CEILING_NOISE_PX:g} px"
    )
    t0 = time.perf_counter()
    views = VIEW_SETS[view_set](count, seed)
    print(f"   ({time.perf_counter() - t0:.1f} s to make them)")
    t0 = time.perf_counter()
    outcomes = _pose_pictures.evaluate(views, seed)
    print(f"   ({time.perf_counter() - t0:.1f} s to measure them)")
    return _pose_pictures.print_report(outcomes)


# ---------------------------------------------------------------------- 5: cost


def cost(count: int, seed: int) -> None:
    from qrfield.solvers import METHODS, solve, solve_methods
    from qrfield.testing.pose_views import corner_set

    views = corner_set(count, seed)
    rng = np.random.default_rng(seed)
    covs = [random_corner_cov(rng) for _ in views]
    noisy = [v.corners_px + draw_noise(rng, c) for v, c in zip(views, covs, strict=True)]
    print(f"\n5. CPU time per solve (time.process_time; {count} seeded noisy views; the machine is shared)")
    for method in METHODS:
        times = []
        for with_cov in (False, True):
            t0 = time.process_time()
            for view, corners, cov in zip(views, noisy, covs, strict=True):
                solve(corners, view.camera, view.side_mm, method, corners_cov=cov if with_cov else None)
            times.append((time.process_time() - t0) * 1e6 / len(views))
        print(
            f"   {method:<10} without covariance {times[0]:7.1f} us (baseline), with {times[1]:7.1f} us "
            f"({times[1] / times[0]:.2f}x)"
        )
    times = []
    for with_cov in (False, True):
        t0 = time.process_time()
        for view, corners, cov in zip(views, noisy, covs, strict=True):
            solve_methods(corners, view.camera, view.side_mm, METHODS, None, cov if with_cov else None)
        times.append((time.process_time() - t0) * 1e6 / len(views))
    print(
        f"   {'both':<10} without covariance {times[0]:7.1f} us (baseline), with {times[1]:7.1f} us "
        f"({times[1] / times[0]:.2f}x): solve_methods, as the pipeline runs them (what they share done once)"
    )


def run(args: argparse.Namespace) -> int:
    from qrfield.benchmarks._pose_real import real_optics

    ok = injected_noise(args.poses, args.seed)
    pictures = end_to_end(args.views, args.view_seed, args.view_set) if args.views > 0 else None
    real_optics(args.data)
    cost(args.cost_views, args.seed)
    print(f"\ninjected-noise calibration of the default methods: {'meets' if ok else 'MISSES'} the targets")
    if pictures is not None:
        print(
            "end to end on the pictures, share meeting 2 deg / 5 mm: "
            f"{'meets' if pictures else 'MISSES'} the targets"
        )
    return 0
