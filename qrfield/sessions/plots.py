"""The analysis figures of a session, drawn with OpenCV: as images (the report embeds them) or PNG files.

- errors_vs_tilt.png: |angle errors| (deg) and the position error (mm) against the tilt (the largest
  |ground-truth angle|), with the acceptance limits as dashed lines (in the report also the
  simulation's errors at the same poses, grey crosses);
- measured_vs_truth.png: measured x, y, z (mm) and alpha, beta, gamma (deg) against the ground
  truth, passes and fails in two colours, with the line measured = truth.
Withdrawn rows are not drawn (the caller passes the active rows).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from qrfield.sessions.analysis import row_errors, row_tilt_deg
from qrfield.sessions.plotting import (
    BLACK,
    BLUE,
    GREEN,
    GREY,
    ORANGE,
    PURPLE,
    RED,
    Panel,
    figure,
    padded_range,
)
from qrfield.sessions.store import LoggedRow, SessionInfo

#: The files ``analyze --out DIR`` writes into DIR, in order.
ERRORS_VS_TILT = "errors_vs_tilt.png"
MEASURED_VS_TRUTH = "measured_vs_truth.png"
PLOT_FILES = (ERRORS_VS_TILT, MEASURED_VS_TRUTH)


def _write(path: Path, img: np.ndarray) -> Path:
    from qrfield.images import write_image

    return write_image(path, img)


def plot_errors_vs_tilt(rows: Sequence[LoggedRow], info: SessionInfo, path: Path) -> Path:
    """Two panels: angle errors and position error against tilt; returns ``path``."""
    return _write(path, errors_vs_tilt_image(rows, info))


def plot_measured_vs_truth(rows: Sequence[LoggedRow], info: SessionInfo, path: Path) -> Path:
    """Six panels (x, y, z, alpha, beta, gamma): measured against ground truth; returns ``path``."""
    return _write(path, measured_vs_truth_image(rows, info))


def errors_vs_tilt_image(
    rows: Sequence[LoggedRow], info: SessionInfo, predicted: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """The errors-against-tilt figure (BGR). ``predicted``: the simulation's (largest |angle error|
    in deg, position error in mm) for each row, (N,) each, drawn as grey crosses beside the rows."""
    tilt = np.array([row_tilt_deg(r) for r in rows], dtype=float)
    errors = [row_errors(r) for r in rows]
    crit = info.criteria
    img, rects = figure(2, 1, f"Errors against tilt - session {info.name} ({len(rows)} rows, {info.solver})")
    xlim = padded_range(np.append(tilt, 0.0))

    angle_sets = [
        ("|alpha error|", BLUE, "circle", "alpha_deg"),
        ("|beta error|", ORANGE, "square", "beta_deg"),
        ("|gamma error|", PURPLE, "triangle", "gamma_deg"),
    ]
    angle_values = [e[key] for e in errors for *_, key in angle_sets]
    predicted_values: tuple[list[float], list[float]] = ([], [])
    if predicted is not None:
        predicted_values = ([float(v) for v in predicted[0]], [float(v) for v in predicted[1]])
        if len(predicted_values[0]) != len(rows) or len(predicted_values[1]) != len(rows):
            raise ValueError(f"predicted errors: one value per row ({len(rows)}) expected")
    angle_range = [*angle_values, *predicted_values[0]]
    left = _error_panel(img, rects[0], xlim, angle_range, crit.max_angle_error_deg, "deg", "angle errors")
    for label, colour, marker, key in angle_sets:
        left.scatter(tilt, [e[key] for e in errors], colour, marker, label)
    if predicted is not None:
        left.scatter(tilt, predicted[0], GREY, "cross", "simulation: largest |angle error|")
    left.draw_legend()

    pos = [e["pos_mm"] for e in errors]
    right = _error_panel(
        img, rects[1], xlim, [*pos, *predicted_values[1]], crit.max_position_error_mm, "mm", "position error"
    )
    right.scatter(tilt, pos, BLUE, "circle", "position error")
    if predicted is not None:
        right.scatter(tilt, predicted[1], GREY, "cross", "simulation: position error")
    right.draw_legend()
    return img


def _error_panel(
    img: np.ndarray,
    rect: tuple[int, int, int, int],
    xlim: tuple[float, float],
    values: list[float],
    limit: float,
    unit: str,
    title: str,
) -> Panel:
    """A panel of |measured - truth| (``unit``) against tilt (deg) over ``xlim``, its y range holding
    0, 1.2 times ``limit`` and ``values``, with its axes and the criterion ``limit`` drawn (dashed red)."""
    panel = Panel(
        img,
        rect,
        xlim,
        padded_range([0.0, limit * 1.2, *values]),
        title=title,
        xlabel="tilt: largest |ground-truth angle| (deg)",
        ylabel=f"|measured - truth| ({unit})",
    )
    panel.draw_axes()
    panel.line((xlim[0], limit), (xlim[1], limit), RED, label=f"limit {limit:g} {unit}", dashed=True)
    return panel


def measured_vs_truth_image(rows: Sequence[LoggedRow], info: SessionInfo) -> np.ndarray:
    """The measured-against-truth figure (BGR)."""
    img, rects = figure(3, 2, f"Measured against ground truth - session {info.name} ({len(rows)} rows)")
    passed = np.array([r.passed for r in rows], dtype=bool)
    quantities = [("x", "mm"), ("y", "mm"), ("z", "mm"), ("alpha", "deg"), ("beta", "deg"), ("gamma", "deg")]
    for rect, (name, unit) in zip(rects, quantities, strict=True):
        truth = np.array([r.number_or_nan(f"gt_{name}") for r in rows], dtype=float)
        measured = np.array([r.number_or_nan(name) for r in rows], dtype=float)
        lim = padded_range(np.concatenate([truth, measured]))
        panel = Panel(
            img,
            rect,
            lim,
            lim,
            title=name,
            xlabel=f"ground truth {name} ({unit})",
            ylabel=f"measured {name} ({unit})",
        )
        panel.draw_axes()
        panel.line(
            (panel.xlim[0], panel.xlim[0]), (panel.xlim[1], panel.xlim[1]), BLACK, label="measured = truth"
        )
        panel.scatter(truth[passed], measured[passed], GREEN, "circle", "pass")
        panel.scatter(truth[~passed], measured[~passed], RED, "cross", "fail")
        panel.draw_legend()
    return img
