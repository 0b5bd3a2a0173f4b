"""``qrfield analyze SESSION``: per-combination figures, plots and the resemblance to the simulation."""

from __future__ import annotations

import argparse
import json
import sys

HELP = (
    "analyse an experiment session: pass rates, errors per combination, plots, resemblance to the simulation"
)
DESCRIPTION = (
    "Reads SESSION (a folder <YYYYmmdd-HHMMSS>-<name>/ with session.json and rows.csv) and prints, per "
    "rotation combination, the rows, pass rate and mean / max absolute error per axis (withdrawn rows "
    "excluded), and the resemblance to the simulation: the share of rows whose pass agrees with the "
    "simulation's verdict at the same ground-truth pose (same camera, side and solver, corners rounded to "
    "whole pixels), in two readings: within criteria, and converged and within criteria (the solver's own "
    "converged flag holds too), beside the seed's 73.15 %."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("session", metavar="SESSION", help="session folder")
    parser.add_argument(
        "--json",
        action="store_true",
        help='print {"rows", "pass_rate", "per_combination": [...], "resemblance", ...} as JSON '
        "(pass rates as fractions 0..1; resemblance null with resemblance_reason when not computed)",
    )
    parser.add_argument(
        "--out", metavar="DIR", help="write errors_vs_tilt.png and measured_vs_truth.png into DIR"
    )
    parser.add_argument("--force", action="store_true", help="overwrite the plots in --out if they exist")
    parser.add_argument(
        "--no-simulation", action="store_true", help="skip the comparison with the simulation"
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from qrfield.arguments import refuse_existing
    from qrfield.sessions.analysis import analyze, format_report
    from qrfield.sessions.plots import PLOT_FILES

    if args.out:
        for name in PLOT_FILES:
            refuse_existing(Path(args.out) / name, args.force, "--out:")
    result = analyze(args.session, out_dir=args.out, compare=not args.no_simulation)
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        print()
    else:
        print(format_report(result))
    return 0
