"""``qrfield plan``: write an experiment plan (the study's combinations at chosen tilts), or check one."""

from __future__ import annotations

import argparse
import sys

HELP = "write an experiment plan of target poses (the study's combinations at chosen angles), or check one"
DESCRIPTION = (
    "Writes a plan: a CSV of target poses (x, y, z in mm; alpha, beta, gamma in degrees; combo; note), "
    "one per rotation combination of the simulation study and tilt magnitude t, the angles being t "
    "times the combination's multipliers, at one position. A session follows it with the app's guided "
    "logging or 'qrfield session run-plan'. --check reads a plan (e.g. written by hand) and names the "
    "line, target and column of every problem."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--combos",
        default="all",
        metavar="all|LIST",
        help="'all' (default) or comma-separated combination names of the study's file, e.g. alpha,beta",
    )
    parser.add_argument("--angles", metavar="T1,T2,...", help="tilt magnitudes t in degrees, e.g. 10,20,30")
    parser.add_argument("--z-mm", type=float, default=None, metavar="Z", help="z of every target, mm")
    parser.add_argument("--x-mm", type=float, default=0.0, metavar="X", help="x of every target, mm (0)")
    parser.add_argument("--y-mm", type=float, default=0.0, metavar="Y", help="y of every target, mm (0)")
    parser.add_argument(
        "--combinations",
        default="default",
        metavar="FILE",
        help="the combinations file (default: the simulation study's shipped 12)",
    )
    parser.add_argument("--out", metavar="PLAN.csv", help="the plan to write")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument(
        "--check", metavar="PLAN.csv", help="read this plan and report its targets or its problems"
    )


def run(args: argparse.Namespace) -> int:
    from qrfield.arguments import parse_numbers
    from qrfield.sessions.plan import PlanError, generate_plan, read_plan, write_plan

    if args.check:
        try:
            targets = read_plan(args.check, args.combinations)
        except PlanError as exc:
            for problem in exc.problems:
                print(f"qrfield plan: error: {problem}", file=sys.stderr)
            return 2
        combos = sorted({t.combo for t in targets})
        print(f"{args.check}: {len(targets)} targets, {len(combos)} combinations: {', '.join(combos)}")
        return 0
    if not args.out or not args.angles or args.z_mm is None:
        raise ValueError("give --angles, --z-mm and --out (or --check PLAN.csv)")
    angles = parse_numbers(args.angles, "--angles")
    targets = generate_plan(args.combos, angles, args.z_mm, args.x_mm, args.y_mm, args.combinations)
    try:
        path = write_plan(args.out, targets, overwrite=args.force)
    except FileExistsError:
        raise ValueError(f"--out {args.out} exists; give --force to replace it") from None
    combos = len({t.combo for t in targets})
    print(f"wrote {len(targets)} targets ({combos} combinations x {len(angles)} angles) to {path}")
    return 0
