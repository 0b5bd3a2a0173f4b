"""``qrfield benchmark simulation``: the study's time and poses/s, the new path beside the old, in one run.

Measured in this run, on this machine (wall time: the new path uses several processes):
  - the default study (qrfield/data/study-default.toml, with --set overrides) and the app's small
    study (ui's SMALL_STUDY: 5 x 3 x 2 grid, 0..60 deg in 5 deg steps), each by
      new:    batch solvers (numerical and IPPE vectorised in numpy), tasks over every core
              (auto: the app's small study stays in one process);
      serial: the same batch solvers in this process only (workers = 1);
      old:    the per-pose path (docs/benchmarks.md, "simulation"): numerical batch, IPPE one pose
              at a time through OpenCV (qrfield.solvers.ippe.solve_ippe_batch), this process
              only, 2048-pose tasks;
    with the ratio old / new, both readings of the mean coverage per solver for each path, and
    the samples whose verdict differs between the paths (the batch IPPE's LM stops elsewhere than
    OpenCV's: a sample right on a criterion's edge may change side);
  - the batch IPPE against the single path (qrfield.solvers.solve, method "ippe") on seeded
    visible poses, exact and with Gaussian corner noise: the largest differences and poses/s.
The load average is printed before and after: other work on the machine slows every figure.
Targets (docs/benchmarks.md, "simulation"): the default study under 5 s on a 2-core machine; the
app's small study under 1 s.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

from qrfield.methods import IPPE

HELP = "time the simulation study: batch solvers on every core beside the old per-pose IPPE path"

#: Poses per task of the old, per-pose path (docs/benchmarks.md, "simulation").
OLD_CHUNK_POSES = 2048


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, number, seed
    from qrfield.commands.simulate import add_override_argument
    from qrfield.limits import MAX_BENCHMARK_COUNT

    add_override_argument(parser, "override a field of the default study (e.g. degradation=round)")
    parser.add_argument("--no-old", action="store_true", help="skip the old path (it takes 30-70 s)")
    parser.add_argument(
        "--poses",
        type=count("--poses", 0, MAX_BENCHMARK_COUNT),
        default=3000,
        help="seeded poses for the IPPE comparison",
    )
    parser.add_argument(
        "--noise-px",
        type=number("--noise-px", 0.0, 100.0, "px"),
        default=0.5,
        help="corner noise of the IPPE comparison",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=7)


def old_solve(spec: Any, corners: Any, camera: Any, side_mm: float) -> Any:
    """The old path's solvers (docs/benchmarks.md, "simulation"): IPPE one pose at a time through OpenCV."""
    from qrfield.solvers import solve_batch
    from qrfield.solvers.checks import check_corners_batch
    from qrfield.solvers.ippe import solve_ippe_batch

    if spec.method == IPPE:
        checked, valid = check_corners_batch(corners)
        return solve_ippe_batch(checked, valid, camera, side_mm, spec.settings)
    return solve_batch(corners, camera, side_mm, settings=spec.settings, method=spec.method)


def _load() -> str:
    if not hasattr(os, "getloadavg"):
        return "load average n/a"
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} / {five:.2f} / {fifteen:.2f} (1 / 5 / 15 min)"


def _run(config: Any, **kwargs: Any) -> tuple[float, float, Any]:
    """(wall seconds, CPU seconds of this process, result)."""
    from qrfield.simulation import run_study

    t0, c0 = time.perf_counter(), time.process_time()
    result = run_study(config, **kwargs)
    return time.perf_counter() - t0, time.process_time() - c0, result


def _compare_study(label: str, config: Any, skip_old: bool) -> None:
    import numpy as np

    from qrfield.simulation import parallel
    from qrfield.simulation.outputs import percent

    size = config.size()["poses"]
    print(f"\n{label}: {config.describe_size()}")
    rows = []
    auto = parallel.auto_workers(size)
    rows.append((f"new (batch, {auto} process{'es' if auto > 1 else ''})", *_run(config)))
    rows.append(("new, this process only", *_run(config, workers=1)))
    if not skip_old:
        old_path = _run(config, workers=1, solve_fn=old_solve, chunk_poses=OLD_CHUNK_POSES)
        rows.append(("old (per-pose OpenCV IPPE, one process)", *old_path))
    print(f"  {'path':<44}{'seconds':>9}{'poses/s':>10}{'old / this':>12}{'CPU s here':>12}")
    for name, seconds, cpu, _ in rows:
        ratio = f"{rows[-1][1] / seconds:.1f}x" if not skip_old else "-"
        print(f"  {name:<44}{seconds:>9.2f}{size / seconds:>10.0f}{ratio:>12}{cpu:>12.2f}")
    print(
        "  (wall seconds; 'CPU s here' is this process's CPU time: with other work on the machine a "
        "run waits for the CPU, and with several processes the workers' time is not in it)"
    )
    new = rows[0][3]
    keys = new.solvers
    print("  mean coverage (within criteria / converged and within criteria):")
    for name, _, _, result in rows:
        cells = "  ".join(
            f"{k} {percent(result.mean_coverage(k))} / "
            f"{percent(result.mean_coverage(k, converged_only=True))}"
            for k in keys
        )
        print(f"    {name[:24]:<26}{cells}")
    if not skip_old:
        old = rows[-1][3]
        for s, key in enumerate(keys):
            differ = int(np.count_nonzero(new.status[s] != old.status[s]))
            print(f"  samples whose verdict differs, new vs old, {key}: {differ} of {new.status[s].size}")


def _compare_ippe(args: argparse.Namespace) -> None:
    import numpy as np

    from qrfield.camera import resolve_camera
    from qrfield.geometry import angle_difference
    from qrfield.sampling import random_visible_poses
    from qrfield.solvers import solve, solve_batch
    from qrfield.solvers.checks import check_corners_batch

    camera = resolve_camera("picam-v2@640x480")
    poses = random_visible_poses(camera, 50.0, args.poses, seed=args.seed, max_tilt_deg=80.0)
    exact = np.array([p.corners_px(camera, 50.0) for p in poses])
    rng = np.random.default_rng(args.seed)
    noisy = exact + rng.normal(0.0, args.noise_px, exact.shape)
    truth_pos = np.array([p.position_mm for p in poses])
    truth_ang = np.array([p.angles_deg for p in poses])
    print(
        f"\nbatch IPPE vs the single path (solve, method 'ippe'): {len(poses)} seeded visible poses of "
        f"{camera.name}, L = 50 mm, z 150-800 mm, tilt <= 80 deg"
    )
    print(
        f"  {'corners':<12}{'max |dpos| mm':>15}{'max |dang| deg':>16}{'max |dreproj| px':>18}"
        f"{'batch poses/s':>15}{'single poses/s':>16}{'ratio':>8}{'batch err vs truth mm/deg':>28}"
    )
    for label, corners in (("exact", exact), (f"{args.noise_px:g} px", noisy)):
        keep = check_corners_batch(corners)[1]  # noise can make a corner set unusable (concave)
        corners, rows = corners[keep], np.flatnonzero(keep)
        solve_batch(corners[:50], camera, 50.0, method=IPPE)  # warm caches
        t0 = time.perf_counter()
        batch = solve_batch(corners, camera, 50.0, method=IPPE)
        batch_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        single = [solve(c, camera, 50.0, method=IPPE) for c in corners]
        single_s = time.perf_counter() - t0
        pos = np.array([r.position_mm for r in single])
        ang = np.array([r.angles_deg for r in single])
        reproj = np.array([r.reprojection_px for r in single])
        dpos = np.linalg.norm(batch.position_mm - pos, axis=1).max()
        dang = np.abs(angle_difference(batch.angles_deg, ang)).max()
        drep = np.abs(batch.reprojection_px - reproj).max()
        tpos = np.linalg.norm(batch.position_mm - truth_pos[rows], axis=1)
        tang = np.abs(angle_difference(batch.angles_deg, truth_ang[rows])).max(axis=1)
        truth = f"{np.median(tpos):.2g} / {np.median(tang):.2g} (median)"
        print(
            f"  {label:<12}{dpos:>15.2e}{dang:>16.2e}{drep:>18.2e}{rows.size / batch_s:>15.0f}"
            f"{rows.size / single_s:>16.0f}{single_s / batch_s:>7.0f}x{truth:>28}"
        )


def run(args: argparse.Namespace) -> int:
    from qrfield.simulation import config_from_dict, load_study, parallel
    from qrfield.simulation.study import SMALL_STUDY

    print(f"qrfield benchmark simulation: {parallel.cpu_count()} cores; {_load()} before the runs")
    default = load_study(overrides=args.overrides)
    small = config_from_dict(SMALL_STUDY, base=default)
    _compare_study("default study", default, args.no_old)
    _compare_study("the app's small study", small, args.no_old)
    _compare_ippe(args)
    print(f"\n{_load()} after the runs (other work on this machine slows every figure above)")
    print("targets: default study (new) < 5 s on a 2-core machine; the app's small study (new) < 1 s")
    return 0
