"""Section 4 of ``qrfield benchmark pose``: the real-optics cases of :mod:`qrfield.testing.real_squares`
(squares of four inner chessboard corners against the whole board), printed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from qrfield.methods import METHODS
from qrfield.testing.real_squares import FOLDER, SquareCase, square_cases
from qrfield.testing.shared_data import shared_data_dir


def real_optics(data: Path | None) -> None:
    """Print section 4 of ``qrfield benchmark pose`` (skipped with a reason when the data is absent)."""
    from qrfield.benchmarks.pose import COMPONENTS, calibration_line

    root = shared_data_dir(data)
    folder = None if root is None else root / FOLDER
    print("\n4. real optics: squares of 4 inner chessboard corners vs cv2.solvePnP on all 24 (Bumblebee2)")
    if folder is None or not folder.is_dir():
        print(f"   {FOLDER} not found under ../shared/data (give --data): skipped")
        return
    cases = square_cases(folder)
    frames = sorted({c.frame for c in cases})
    print(
        f"   {len(frames)} frames, squares of 60 and 90 mm (2 and 3 board squares), through BoofCV's "
        f"intrinsics; z {min(c.distance_mm for c in cases):.0f}-{max(c.distance_mm for c in cases):.0f} mm"
    )
    header = "".join(f"{c:>12}" for c in COMPONENTS)
    print(f"{'   source, method (RMS z / % within 2)':<34}{'n':>7}{header}")
    for source in ("cornerSubPix", "hand labels"):
        sigmas = sorted({c.frame: c.corner_std_px for c in cases if c.source == source}.values())
        for method in METHODS:
            sel = [c for c in cases if c.source == source and c.method == method and c.converged]
            if not sel:
                continue
            z = np.array([c.errors / c.std for c in sel])
            line = calibration_line(f"   {source}, {method}", z)[0]
            print(line + f"  flagged {np.mean([c.ambiguous for c in sel]):.0%}")
        if sigmas:
            print(
                f"      corner std from the board residual: median {np.median(sigmas):.3f} px "
                f"(range {sigmas[0]:.3f}-{sigmas[-1]:.3f})"
            )
    sel = [c for c in cases if c.source == "cornerSubPix" and c.converged]
    ratio = np.median([np.max(c.ref_std / c.std) for c in sel]) if sel else math.nan
    print(f"   the reference's own std is at most {ratio:.2f} of the square's (median over cases)")
    _per_frame(sel)
    print("   median |error| per component, cornerSubPix corners, 90 mm squares:")
    for method in METHODS:
        big = [c for c in sel if c.method == method and c.size == 3]
        if big:
            med = np.median(np.abs([c.errors for c in big]), axis=0)
            print(
                f"      {method:<10}"
                + "  ".join(f"{n} {v:.2f}" for n, v in zip(COMPONENTS, med, strict=True))
                + "  (mm, deg)"
            )


def _per_frame(cases: list[SquareCase]) -> None:
    """One line per frame for its middle 90 mm square (board rows 1-4): the errors and how many of
    the six components lie within 2 reported stds."""
    print("   per frame, the middle 90 mm square: |position error| mm; alpha, beta, gamma errors deg;")
    print("   components within 2 std")
    print(f"   {'frame':<9}{'z mm':>6}{'std px':>8}   {'numerical':<34}{'ippe':<34}")
    for frame in sorted({c.frame for c in cases}):
        middle = [c for c in cases if c.frame == frame and c.size == 3]
        cells = []
        for method in METHODS:
            # Made row by row: the middle one of the three 3 x 3 squares is the second.
            mine = [c for c in middle if c.method == method]
            if len(mine) != 3:
                cells.append(f"{'-':<34}")
                continue
            e, z = mine[1].errors, mine[1].errors / mine[1].std
            covered = int(np.sum(np.abs(z) < 2.0))
            cells.append(
                f"{np.linalg.norm(e[:3]):5.2f}; {e[3]:+5.2f} {e[4]:+5.2f} {e[5]:+5.2f}  {covered}/6".ljust(34)
            )
        first = middle[0]
        print(f"   {frame:<9}{first.distance_mm:>6.0f}{first.corner_std_px:>8.3f}   " + "".join(cells))
