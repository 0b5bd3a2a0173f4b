"""``qrfield simulate``: the thesis' simulation study (where each solver finds the pose)."""

from __future__ import annotations

import argparse

HELP = "run the simulation study: largest solvable tilt per grid point, coverage per rotation combination"
DESCRIPTION = (
    "Sweep the tilt of a simulated QR card over a grid of positions for each rotation combination, "
    "solve every pose with each solver and report the largest solvable angle (heatmaps) and the "
    "coverage (share of in-view samples meeting the criteria) next to the seed's 77.28 %. "
    "Without STUDY the shipped default study is run; fields are overridden with --set FIELD=VALUE "
    "(e.g. --set z_range=200,600,100 --set degradation=round --set criteria.angle_deg=1 "
    "--set solver.numerical.tf=0.8 --set solvers=numerical,ippe). Ctrl-C stops after the current "
    "chunk and writes what is done (partial: true in summary.json)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "study", nargs="?", metavar="STUDY.toml", help="study file (default: the shipped study)"
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a study field (repeatable); tables with dots: criteria.n_max=20, "
        "solver.ippe.refine=none",
    )
    parser.add_argument("--out", metavar="DIR", help="output folder (default: simulation-YYYYmmdd-HHMMSS)")
    parser.add_argument(
        "--force", action="store_true", help="write into an existing, non-empty output folder"
    )
    parser.add_argument(
        "--show", action="store_true", help="print the resolved study (TOML) and its size, then exit"
    )
    parser.add_argument("--no-heatmaps", action="store_true", help="skip the heatmap PNGs")
    parser.add_argument(
        "--no-csv", action="store_true", help="skip samples.csv (samples.npz is always written)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    import contextlib
    import os
    import shlex
    import signal
    import sys
    import threading
    import time
    from pathlib import Path

    from qrfield.simulation import load_study, run_study
    from qrfield.simulation.outputs import SEED_COVERAGE_PERCENT, percent, write_outputs
    from qrfield.simulation.progress import TerminalProgress

    config = load_study(args.study, args.overrides)
    if args.show:
        print(config.to_toml(), end="")
        print(f"# size: {config.describe_size()}")
        return 0
    out = Path(args.out or time.strftime("simulation-%Y%m%d-%H%M%S"))
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not args.force:
        raise ValueError(f"--out {out}: folder is not empty (choose another, or --force to write into it)")
    # Make the folder now: a study can run for hours, and its results must not be lost at the end
    # for want of a writable output folder.
    created = not out.exists()
    from qrfield.files import make_folder

    make_folder(out, "--out folder")  # the folder named, never the folders above it
    if not os.access(out, os.W_OK):
        raise OSError(f"--out {out}: the folder is not writable")

    stop = threading.Event()

    def on_sigint(signum, frame):  # type: ignore[no-untyped-def]
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()
        print("\nstopping after the current chunk (Ctrl-C again to abort without writing)", file=sys.stderr)

    print(f"qrfield simulate: {config.describe_size()}", file=sys.stderr)
    bar = None if args.quiet else TerminalProgress()
    previous = (
        signal.signal(signal.SIGINT, on_sigint)
        if threading.current_thread() is threading.main_thread()
        else None
    )
    try:
        result = run_study(config, progress=bar, stop=stop)
    except BaseException:
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()  # only when still empty
        raise
    finally:
        if bar is not None:
            bar.finish()
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
    rate = result.poses_done / result.seconds if result.seconds > 0 else 0.0
    print(
        f"{result.poses_done} poses x {len(result.solvers)} solvers in {result.seconds:.1f} s "
        f"({rate:.0f} poses/s, {rate * len(result.solvers):.0f} solves/s)"
        + (" -- stopped early, partial results" if result.partial else ""),
        file=sys.stderr,
    )
    summary = result.summary()
    keys = result.solvers
    width = max(len(c.name) for c in result.combinations) + 2
    print(f"{'combination':<{width}}" + "".join(f"{k:>26}" for k in keys))
    for entry in summary["combinations"]:
        print(f"{entry['name']:<{width}}" + "".join(f"{percent(entry['coverage'][k]):>26}" for k in keys))
    print(f"{'mean':<{width}}" + "".join(f"{percent(summary['mean_coverage'][k]):>26}" for k in keys))
    print(f"{'seed (thesis)':<{width}}{SEED_COVERAGE_PERCENT:>24.2f} %  (numerical model, MATLAB)")
    command = ["qrfield", "simulate", *([args.study] if args.study else [])]
    for override in args.overrides:
        command += ["--set", override]
    command += ["--out", str(out)]
    write_outputs(
        result, out, csv_samples=not args.no_csv, heatmaps=not args.no_heatmaps, command=shlex.join(command)
    )
    print(f"wrote {out}/ (summary.md, summary.json, samples.npz, max_angles.csv, heatmaps/)", file=sys.stderr)
    return 130 if result.partial else 0
