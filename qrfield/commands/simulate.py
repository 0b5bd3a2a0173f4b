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
    "--set solver.numerical.tf=0.8 --set solvers=numerical,ippe). Coverage is printed in two readings: "
    "within criteria, and converged and within criteria (the solver's own flag holds too). The study "
    "runs on every core (--workers); Ctrl-C stops after the tasks in progress and writes what is "
    "done (partial: true in summary.json). Outputs go to a new folder simulation-YYYYmmdd-HHMMSS in "
    "the current folder unless --out names one (the app's Simulation tab writes under the data "
    "folder's simulations/)."
)


#: The name of a run's folder made in the current folder: simulation-YYYYmmdd-HHMMSS.
RUN_PREFIX = "simulation-"


def add_override_argument(parser: argparse.ArgumentParser, help_text: str) -> None:
    """``--set FIELD=VALUE`` (repeatable) into ``args.overrides``, as load_study takes them."""
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help=f"{help_text} (repeatable); tables with dots: criteria.n_max=20, solver.ippe.refine=none",
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import whole_number
    from qrfield.limits import MAX_WORKERS

    parser.add_argument(
        "study", nargs="?", metavar="STUDY.toml", help="study file (default: the shipped study)"
    )
    add_override_argument(parser, "override a study field")
    parser.add_argument(
        "--out",
        metavar="DIR",
        help="output folder, relative to the current folder (default: a new folder "
        "simulation-YYYYmmdd-HHMMSS in the current folder)",
    )
    parser.add_argument(
        "--force", action="store_true", help="write into an existing, non-empty output folder"
    )
    parser.add_argument(
        "--show", action="store_true", help="print the resolved study (TOML) and its size, then exit"
    )
    parser.add_argument("--no-heatmaps", action="store_true", help="skip the heatmap PNGs")
    parser.add_argument(
        "--csv",
        action="store_true",
        help="also write samples.csv (every sample as text; samples.npz is always written)",
    )
    parser.add_argument("--no-csv", action="store_true", help=argparse.SUPPRESS)  # the default now
    parser.add_argument(
        "--workers",
        type=whole_number("--workers", 1, MAX_WORKERS),
        metavar="N",
        help="processes to run the study on (default: every core for a large study; 1 = this process)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    import contextlib
    import os
    import shlex
    import signal
    import sys
    import threading
    from pathlib import Path

    from qrfield.files import make_folder
    from qrfield.simulation import load_study, run_study
    from qrfield.simulation.outputs import new_run_folder, write_outputs
    from qrfield.simulation.progress import TerminalProgress

    config = load_study(args.study, args.overrides)
    if args.show:
        print(config.to_toml(), end="")
        print(f"# size: {config.describe_size()}")
        return 0
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be 1 or more, got {args.workers}")
    if args.out:
        out = Path(args.out).expanduser()
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out {out}: exists and is not a folder")
        if out.is_dir() and any(out.iterdir()) and not args.force:
            raise ValueError(
                f"--out {out}: folder is not empty (choose another, or --force to write into it)"
            )
        # Make the folder now: a study can run for hours, and its results must not be lost at the
        # end for want of a writable output folder.
        created = not out.exists()
        make_folder(out, "--out folder")  # the folder named, never the folders above it
    else:
        out = new_run_folder(Path.cwd(), prefix=RUN_PREFIX)  # never outside the current folder
        created = True
    if not os.access(out, os.W_OK):
        raise OSError(f"--out {out}: the folder is not writable")

    stop = threading.Event()

    def on_sigint(signum, frame):  # type: ignore[no-untyped-def]
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()
        print(
            "\nstopping after the tasks in progress (Ctrl-C again to abort without writing)", file=sys.stderr
        )

    print(f"qrfield simulate: {config.describe_size()}", file=sys.stderr)
    bar = None if args.quiet else TerminalProgress()
    previous = (
        signal.signal(signal.SIGINT, on_sigint)
        if threading.current_thread() is threading.main_thread()
        else None
    )
    try:
        result = run_study(config, progress=bar, stop=stop, workers=args.workers)
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
    print(coverage_table(result), end="")
    command = ["qrfield", "simulate", *([args.study] if args.study else [])]
    for override in args.overrides:
        command += ["--set", override]
    command += ["--out", str(out)]
    written = write_outputs(
        result, out, csv_samples=args.csv, heatmaps=not args.no_heatmaps, command=shlex.join(command)
    )
    size = sum(p.stat().st_size for p in written if p.is_file())
    names = sorted({p.name if p.parent == out else p.parent.name + "/" for p in written})
    print(f"wrote {out.resolve()}/ ({', '.join(names)}; {size / 1e6:.1f} MB)", file=sys.stderr)
    return 130 if result.partial else 0


def coverage_table(result) -> str:  # type: ignore[no-untyped-def]
    """The terminal's coverage table: per combination and solver, both readings, the mean, the seed."""
    from qrfield.simulation.outputs import SEED_COVERAGE_PERCENT, percent

    summary = result.summary()
    keys = result.solvers
    width = max([len(c.name) for c in result.combinations] + [16]) + 2
    col = max(13, (max(len(k) for k in keys) + 3) // 2)
    lines = [
        f"{'coverage':<{width}}" + "".join(f"{k:>{2 * col}}" for k in keys),
        f"{'':<{width}}" + "".join(f"{'within':>{col}}{'conv+within':>{col}}" for _ in keys),
    ]
    rows = [(e["name"], e["coverage"], e["coverage_converged"]) for e in summary["combinations"]]
    rows.append(("mean", summary["mean_coverage"], summary["mean_coverage_converged"]))
    for name, within, converged in rows:
        lines.append(
            f"{name:<{width}}"
            + "".join(f"{percent(within[k]):>{col}}{percent(converged[k]):>{col}}" for k in keys)
        )
    lines.append(f"{'seed (thesis)':<{width}}{SEED_COVERAGE_PERCENT:>{col}.2f} %  (numerical model, MATLAB)")
    lines.append(
        "within = the pose meets the criteria and the solver stopped before n_max; "
        "conv+within = its own converged flag holds too"
    )
    return "\n".join(lines) + "\n"
