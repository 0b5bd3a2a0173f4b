"""Corner figures of ``qrfield benchmark detect`` on the hard set: errors per corner and band, flags,
and the calibration of the corners' covariance (not a benchmark of its own: the leading
underscore keeps it out of ``qrfield benchmark``)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from qrfield.detect.detection import GOOD_QUALITY
from qrfield.geometry import VERTEX_NAMES
from qrfield.testing.hardset import BANDS, HardView

#: A corner further off than this, px, must not be reported with a good quality.
BAD_CORNER_PX = 0.5
#: Module size bands (px, the view's shortest side over its modules) of the covariance's
#: calibration: finer than BANDS below 2 px, where the stream's far cards are (issue 25).
CALIBRATION_BANDS = (
    ("< 1.5 px", 0.0, 1.5),
    ("1.5-2 px", 1.5, 2.0),
    ("2-3 px", 2.0, 3.0),
    (">= 3 px", 3.0, np.inf),
)


@dataclass(frozen=True)
class CornerResult:
    """One view's outcome: the view's facts and the matched detection's (None when none)."""

    index: int
    distorted: bool
    band: str
    module_px: float
    error_px: np.ndarray | None = None  # (4,) px per corner
    diff_px: np.ndarray | None = None  # (4, 2) detected - true
    cov: np.ndarray | None = None  # (4, 2, 2) px^2
    good: bool = False
    text_right: bool = False
    text_wrong: bool = False


def evaluate(views: Iterable[HardView], detect: Callable[[HardView], list]) -> list[CornerResult]:
    """Run ``detect(view) -> detections`` on each view; the detection nearest the truth counts."""
    out = []
    for view in views:
        found = detect(view)
        if not found:
            out.append(CornerResult(view.index, view.distorted, view.band, view.module_px))
            continue
        best = min(found, key=lambda d: float(np.abs(d.corners_px - view.corners_px).max()))
        diff = best.corners_px - view.corners_px
        good = bool(best.refined and best.quality >= GOOD_QUALITY)
        out.append(
            CornerResult(
                view.index,
                view.distorted,
                view.band,
                view.module_px,
                np.linalg.norm(diff, axis=1),
                diff,
                None if best.corners_cov is None else np.asarray(best.corners_cov),
                good,
                best.text == view.text,
                any(d.text and d.text != view.text for d in found),
            )
        )
    return out


def whiten(diff_px: np.ndarray, cov: np.ndarray) -> list[float]:
    """Whitened errors L^-1 e of corners V1..V4: ``diff_px`` (4, 2) estimate - truth, ``cov``
    (4, 2, 2) px^2, L each corner's Cholesky factor (a corner whose block is not positive
    definite is left out): up to 8 values, x and y of each corner."""
    z: list[float] = []
    for k in range(4):
        try:
            chol = np.linalg.cholesky(cov[k])
        except np.linalg.LinAlgError:
            continue
        z.extend(np.linalg.solve(chol, diff_px[k]).tolist())
    return z


def calibration_text(z: np.ndarray) -> str:
    """ "z RMS r, s % within 2" of whitened errors (calibrated: RMS 0.7-1.4, 90-99 % within 2)."""
    return f"z RMS {np.sqrt(np.mean(z**2)):.2f}, {100 * np.mean(np.abs(z) < 2):.1f} % within 2"


def whitened(results: list[CornerResult]) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate whitened errors (:func:`whiten`) and per-corner radius ratios
    |e| / sqrt(trace cov), over the results that have a covariance."""
    z, ratio = [], []
    for r in results:
        if r.cov is None or r.diff_px is None:
            continue
        for k in range(4):
            try:
                np.linalg.cholesky(r.cov[k])
            except np.linalg.LinAlgError:
                continue
            ratio.append(np.linalg.norm(r.diff_px[k]) / np.sqrt(np.trace(r.cov[k])))
        z.extend(whiten(r.diff_px, r.cov))
    return np.array(z), np.array(ratio)


def print_tables(title: str, results: list[CornerResult]) -> None:
    """Per camera kind and module band: found, good, bad-but-good, and per corner median / p90 / max."""
    print(f"\n{title}")
    print(
        f"{'lens':<10}{'band':<9}{'found':>9}{'good':>6}{'>0.5px':>8}{'good&>0.5':>10}"
        f"{'text ok':>9}{'wrong':>7}   per corner: median / 90th pct / max px"
    )
    for distorted in (False, True):
        for label, _, _ in BANDS:
            rows = [r for r in results if r.distorted == distorted and r.band == label]
            hits = [r for r in rows if r.error_px is not None]
            lens = "distorted" if distorted else "pinhole"
            if not hits:
                print(f"{lens:<10}{label:<9}{0:>5}/{len(rows):<3}")
                continue
            e = np.array([r.error_px for r in hits])
            bad = e.max(axis=1) > BAD_CORNER_PX
            good = np.array([r.good for r in hits])
            corners = "  ".join(
                f"{name} {np.median(e[:, k]):.3f}/{np.percentile(e[:, k], 90):.3f}/{e[:, k].max():.3f}"
                for k, name in enumerate(VERTEX_NAMES)
            )
            right = sum(r.text_right for r in hits)
            wrong = sum(r.text_wrong for r in hits)
            print(
                f"{lens:<10}{label:<9}{len(hits):>5}/{len(rows):<3}{good.sum():>6}{bad.sum():>8}"
                f"{(bad & good).sum():>10}{right:>9}{wrong:>7}   {corners}"
            )


def print_calibration(results: list[CornerResult]) -> None:
    """Calibration of the corners' covariance, all views, by module band (CALIBRATION_BANDS) and by
    lens."""
    print("covariance calibration (whitened corner errors; calibrated: RMS 0.7-1.4, 90-99 % within 2):")
    groups = [("all", results)] + [
        (label, [r for r in results if low <= r.module_px < high]) for label, low, high in CALIBRATION_BANDS
    ]
    groups.append(("pinhole", [r for r in results if not r.distorted]))
    groups.append(("distorted", [r for r in results if r.distorted]))
    for name, rows in groups:
        z, ratio = whitened(rows)
        if len(z) == 0:
            print(f"  {name:<10} no covariance")
            continue
        print(
            f"  {name:<10} {len(ratio):>5} corners: z RMS {np.sqrt(np.mean(z**2)):.2f}, "
            f"{100 * np.mean(np.abs(z) < 2):.1f} % within 2; |e|/std RMS {np.sqrt(np.mean(ratio**2)):.2f}, "
            f"largest {ratio.max():.1f}"
        )
