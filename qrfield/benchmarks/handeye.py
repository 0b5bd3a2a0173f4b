"""``qrfield benchmark handeye``: the hand-eye calibration's accuracy and honesty on drawn views.

For each set-up (eye-in-hand, eye-to-hand) and each of ``--sets`` seeded cells: a simulated robot
(:class:`qrfield.handeye.SimulatedRobot`) with a random true transform X (any rotation, up to 100 mm
off the example cell's) and code place Y is driven to ``--views`` tool poses at which the camera
sees a 50 mm code at 250-380 mm, tilted up to 32 degrees from the line of sight and turned up to
90 degrees about its normal. Each view is drawn by the hard set's rasteriser
(:func:`qrfield.testing.hardset.rasterise`, not :func:`qrfield.render.render_view`: segno's
symbol, exact area sampling, blur 0.6 px, noise 2 grey levels), detected and solved by the project's
pipeline (:func:`qrfield.handeye.measure.pose_for_pair`), and the pairs solved.

Printed per cell: pairs used, the error of X against the truth (mm, degrees) beside the closed form
alone (Park-Martin: the baseline, what OpenCV 4's calibrateHandEye(PARK) gives on the same pairs),
the reported std, the z-scores (error / std, per component), the residual RMS against the RMS of
the residuals the true X and Y leave (honest residuals: a ratio near sqrt(1 - 12 / 6N)), and CPU
time of the solve. Then
a degenerate set (turns about the optical axis only) must be refused. Seeds: ``--seed`` + cell
(eye-to-hand: + 1000, so its views differ; the model C = X^-1 M Y is the same for both set-ups).
``--tool-std-mm/--tool-std-deg`` add noise to the robot's reported poses (and tell the solve).
"""

from __future__ import annotations

import argparse
import math
import os
import time

from qrfield.methods import NUMERICAL

HELP = "hand-eye calibration: accuracy against the known transform and honesty of its uncertainty"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, limited, seed
    from qrfield.limits import MAX_BENCHMARK_COUNT, SIDE_MM, TOOL_STD_DEG, TOOL_STD_MM

    parser.add_argument(
        "--sets", type=count("--sets", 1, MAX_BENCHMARK_COUNT), default=5, help="cells per set-up (default 5)"
    )
    parser.add_argument(
        "--views",
        type=count("--views", 1, MAX_BENCHMARK_COUNT),
        default=15,
        help="robot poses per cell (default 15)",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=28, help="seed of the first cell (default 28)")
    parser.add_argument(
        "--camera", default="picam-v2@640x480", help="camera profile (default picam-v2@640x480)"
    )
    parser.add_argument(
        "--side-mm", type=limited(SIDE_MM, "--side-mm"), default=50.0, help="QR side, mm (default 50)"
    )
    parser.add_argument("--method", default=NUMERICAL, help="pose method (default numerical)")
    parser.add_argument(
        "--tool-std-mm",
        type=limited(TOOL_STD_MM, "--tool-std-mm"),
        default=0.0,
        help="noise on the robot's reported positions, mm (default 0)",
    )
    parser.add_argument(
        "--tool-std-deg",
        type=limited(TOOL_STD_DEG, "--tool-std-deg"),
        default=0.0,
        help="noise on its reported orientations, deg (default 0)",
    )


def _load() -> str:
    if not hasattr(os, "getloadavg"):
        return "load unknown"
    one, five, _ = os.getloadavg()
    return f"load {one:.1f} (1 min), {five:.1f} (5 min) on {os.cpu_count()} cores"


def _random_cell(setup: str, seed: int):  # type: ignore[no-untyped-def]
    import numpy as np

    from qrfield.handeye import SimulatedRobot
    from qrfield.handeye.rigid import make_transform, rotation_exp

    rng = np.random.default_rng([seed, 28])
    example = SimulatedRobot.example(setup)
    axis = rng.normal(size=3)
    turn = make_transform(
        rotation_exp(axis / np.linalg.norm(axis) * rng.uniform(0, math.pi)), rng.uniform(-100, 100, 3)
    )
    return SimulatedRobot(setup, example.transform @ turn, example.code)


def _draw(camera, pose, side, matrix, rng):  # type: ignore[no-untyped-def]
    import cv2
    import numpy as np

    from qrfield.testing.hardset import rasterise

    image = rasterise(camera, pose, side, matrix, 120.0, 215.0, 35.0)
    image = cv2.GaussianBlur(image, (0, 0), sigmaX=0.6, borderType=cv2.BORDER_REPLICATE)
    return np.clip(np.round(image + rng.normal(0.0, 2.0, image.shape)), 0, 255).astype(np.uint8)


def _cell(robot, camera, args, seed):  # type: ignore[no-untyped-def]
    import numpy as np

    from qrfield.detect import Detector
    from qrfield.handeye import Pair
    from qrfield.handeye.measure import pose_for_pair
    from qrfield.handeye.rigid import difference, perturbed
    from qrfield.testing.hardset import symbol_matrix

    matrix, _ = symbol_matrix(f"hand-eye cell {seed}", "M")
    rng = np.random.default_rng([seed, 2])
    detector = Detector()
    pairs, pose_errors, left_out = [], [], []
    for k, tool in enumerate(robot.viewing_tool_poses(camera, args.side_mm, args.views, seed=seed)):
        truth = robot.code_pose(tool)
        image = _draw(camera, truth, args.side_mm, matrix, rng)
        result, problem = pose_for_pair(image, camera, args.side_mm, detector, method=args.method)
        if problem:
            left_out.append(problem.split(":")[0])
            continue
        # The robot reports its pose with its own noise (the truth stays ``tool``).
        wobble = np.r_[
            rng.normal(size=3) * args.tool_std_mm, np.radians(rng.normal(size=3) * args.tool_std_deg)
        ]
        pair = Pair.from_pose(perturbed(tool, wobble), result, f"view {k}")
        pairs.append(pair)
        # What the true X and Y predict from the pose the robot reported: the residual at the truth.
        pose_errors.append(difference(pair.code_in_camera, robot.code_in_camera(pair.tool_in_base)))
    return pairs, np.array(pose_errors), left_out


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from qrfield.camera import resolve_camera
    from qrfield.handeye import SETUPS, HandEyeError, Pair, solve_handeye
    from qrfield.handeye.rigid import difference, transform_from_pose
    from qrfield.handeye.solve import model_terms, park_martin

    if args.sets < 1 or args.views < 5:
        raise ValueError("--sets must be >= 1 and --views >= 5")
    camera = resolve_camera(args.camera)
    print(
        f"hand-eye benchmark: {args.views} views a cell, {args.sets} cells per set-up (seeds {args.seed}.."
        f"{args.seed + args.sets - 1} eye-in-hand, +1000 eye-to-hand); {camera.name} {camera.width}x"
        f"{camera.height}, {args.side_mm:g} mm code, z 250-380 mm, tilt <= 32 deg; views by the hard set's "
        f"rasteriser; robot noise {args.tool_std_mm:g} mm, {args.tool_std_deg:g} deg; {_load()}"
    )
    worst_mm = worst_deg = 0.0
    all_z, ratios = [], []
    for setup in SETUPS:
        print(f"\n{setup}: cell  pairs  error mm  error deg | Park-Martin mm deg | std mm  std deg |"
              "  max|z|  residual/true  solve ms")  # fmt: skip
        for cell in range(args.sets):
            seed = args.seed + cell + (1000 if setup == "eye-to-hand" else 0)
            robot = _random_cell(setup, seed)
            pairs, pose_errors, left_out = _cell(robot, camera, args, seed)
            t0 = time.process_time()
            result = solve_handeye(pairs, setup, tool_std_mm=args.tool_std_mm, tool_std_deg=args.tool_std_deg)
            solve_ms = (time.process_time() - t0) * 1e3
            err = difference(result.transform, robot.transform)
            mm, deg = float(np.linalg.norm(err[:3])), math.degrees(float(np.linalg.norm(err[3:])))
            tools = np.array([p.tool_in_base for p in pairs])
            codes = np.array([p.code_in_camera for p in pairs])
            park = difference(park_martin(model_terms(tools, setup), codes), robot.transform)
            err[3:] = np.degrees(err[3:])
            z = err / np.sqrt(np.diag(result.covariance))
            all_z.append(z)
            true_rms = float(np.sqrt(np.mean(np.sum(pose_errors[:, :3] ** 2, axis=1))))
            ratio = result.residual_mm / true_rms
            ratios.append(ratio)
            worst_mm, worst_deg = max(worst_mm, mm), max(worst_deg, deg)
            std_mm = float(np.linalg.norm(result.translation_std_mm))
            std_deg = float(np.linalg.norm(result.rotation_std_deg))
            out = f" ({len(left_out)} left out: {', '.join(sorted(set(left_out)))})" if left_out else ""
            print(f"  {seed:>10d}  {len(pairs):>5d}  {mm:8.3f}  {deg:9.4f} | {np.linalg.norm(park[:3]):8.3f} "
                  f"{math.degrees(np.linalg.norm(park[3:])):8.4f} | {std_mm:6.3f}  {std_deg:7.4f} | "
                  f"{np.abs(z).max():6.2f}  {ratio:13.2f}  {solve_ms:8.1f}{out}")  # fmt: skip
    z = np.array(all_z)
    rms = np.sqrt(np.mean(z**2, axis=0))
    print(f"\nlargest error {worst_mm:.3f} mm, {worst_deg:.4f} deg (must hold: < 2 mm, < 0.3 deg): "
          f"{'met' if worst_mm < 2.0 and worst_deg < 0.3 else 'NOT met'}")  # fmt: skip
    print(
        f"z = error / reported std over {len(z)} cells: RMS per component (tx ty tz rx ry rz) "
        f"{' '.join(f'{v:.2f}' for v in rms)}, largest |z| {np.abs(z).max():.2f} "
        "(honest: RMS <= ~1, none > 4)"
    )
    print(
        f"residual RMS / RMS of the residuals at the true transform: {min(ratios):.2f}..{max(ratios):.2f} "
        f"(expected ~{math.sqrt(1 - 12 / (6 * args.views)):.2f} for {args.views} exact-covariance pairs)"
    )
    # A degenerate cell: every view turned about the optical axis only.
    robot = _random_cell("eye-in-hand", args.seed)
    views = [transform_from_pose([5.0, -3.0, 300.0], [0.0, 0.0, g]) for g in np.linspace(-80, 80, args.views)]
    tools = robot.tool_for_view(np.array(views))
    degenerate = [Pair(t, robot.code_in_camera(t), np.eye(6) * 1e-4) for t in tools]
    try:
        solve_handeye(degenerate, "eye-in-hand")
        print("degenerate set (turns about the optical axis only): NOT refused")
        return 1
    except HandEyeError as exc:
        print(f"degenerate set (turns about the optical axis only): refused: {exc}")
    return 0
