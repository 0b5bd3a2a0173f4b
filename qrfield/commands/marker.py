"""``qrfield marker``: a printable QR card whose symbol measures exactly L mm at 100 %."""

from __future__ import annotations

import argparse

from qrfield.arguments import add_side_argument, number, text

HELP = "write a printable QR marker of exact size (SVG, PDF or PNG)"
DESCRIPTION = (
    "Write a QR code whose symbol (quiet zone excluded, the L every other command asks for) measures "
    "exactly --side-mm when printed at 100 %, with its 4-module quiet zone, a grey cut line just "
    "outside it, and a caption with a check bar. SVG and PDF are vectors; PNG is rasterised at --dpi "
    "(recorded in the file). The page fits the card and caption with 10 mm margins."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--text", type=text("--text"), required=True, metavar="T", help="the QR payload, e.g. qrfield"
    )
    add_side_argument(parser)
    parser.add_argument(
        "--out",
        required=True,
        metavar="FILE",
        help="FILE.svg, FILE.pdf or FILE.png (in a folder that exists)",
    )
    parser.add_argument(
        "--dpi", type=number("--dpi", 0.0), default=None, metavar="D", help="PNG resolution (default 600)"
    )
    parser.add_argument("--force", action="store_true", help="overwrite --out if it exists")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from qrfield.marker import DEFAULT_DPI, MarkerError, write_marker

    out = Path(args.out)
    if args.dpi is not None and out.suffix.lower() != ".png":
        raise MarkerError(f"--dpi applies to .png only; {out.suffix or out.name} is a vector format")
    dpi = DEFAULT_DPI if args.dpi is None else args.dpi
    layout = write_marker(out, args.text, args.side_mm, dpi=dpi, force=args.force)
    w, h = layout.page_mm
    extra = f", {dpi:g} dpi" if out.suffix.lower() == ".png" else ""
    print(
        f"wrote {out}: symbol {layout.side_mm:g} mm ({layout.n} x {layout.n} modules of "
        f"{layout.pitch_mm:.4f} mm), card {layout.card_side_mm:.2f} mm with quiet zone, "
        f"page {w:.2f} x {h:.2f} mm{extra}; print at 100 % and check the {layout.bar_mm:g} mm bar"
    )
    return 0
