"""``qrfield report SESSION``: a self-contained report.html of a session, with the simulation's prediction."""

from __future__ import annotations

import argparse

HELP = "write a session's report.html: settings, pass rates, figures, rows, and the simulation's prediction"
DESCRIPTION = (
    "Writes report.html in the session folder (or --out): one file that opens offline in any browser "
    "(figures embedded, nothing loaded from anywhere): the session's settings, pass rates per combination "
    "and tilt, errors against tilt, measured against truth, every row with its uncertainty, and the "
    "simulation's prediction for exactly those poses: the session's camera, QR side, solver and criteria, "
    "with the simulation study's corner degradation (the shipped study's unless STUDY or --set say "
    "otherwise: --set degradation=noise --set noise_px=0.3, or degradation=round)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.commands.simulate import add_override_argument

    parser.add_argument("session", metavar="SESSION", help="the session folder")
    parser.add_argument("--out", metavar="FILE", help="the HTML file to write (default: SESSION/report.html)")
    parser.add_argument(
        "--study",
        metavar="STUDY.toml",
        help="the study whose corner degradation (degradation, noise_px, noise_seed) and max_view_angle_deg "
        "the prediction uses (default: the shipped study)",
    )
    add_override_argument(parser, "override a field of that study")
    parser.add_argument(
        "--draws",
        type=int,
        default=None,
        metavar="N",
        help="noise draws per pose with degradation = noise (200)",
    )
    parser.add_argument("--no-simulation", action="store_true", help="leave the prediction out")


def run(args: argparse.Namespace) -> int:
    from qrfield.sessions.report import write_report
    from qrfield.simulation import load_study
    from qrfield.simulation.targets import NoiseModel

    if args.draws is not None and not 1 <= args.draws <= 100_000:
        raise ValueError(f"--draws must be 1..100000, got {args.draws}")
    noise = NoiseModel.of_study(load_study(args.study, args.overrides))
    summary = write_report(
        args.session, args.out, noise=noise, draws=args.draws, simulate=not args.no_simulation
    )
    rate = f"{100.0 * summary.passed / summary.rows:.1f} %" if summary.rows else "-"
    line = f"{summary.rows} rows, {summary.passed} pass ({rate})"
    if summary.withdrawn:
        line += f", {summary.withdrawn} withdrawn not counted"
    if summary.predicted_pass_rate is not None:
        line += f"; simulation ({summary.noise}): {100.0 * summary.predicted_pass_rate:.1f} % predicted"
        if summary.agreement is not None:
            line += f", verdicts agree in {100.0 * summary.agreement:.1f} % of rows"
    print(line)
    for warning in summary.warnings:
        print(f"warning: {warning}")
    print(f"wrote {summary.path}")
    return 0
