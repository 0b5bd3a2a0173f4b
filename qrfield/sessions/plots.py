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
    left = Panel(
        img,
        rects[0],
        xlim,
        padded_range([0.0, crit.max_angle_error_deg * 1.2, *angle_values, *predicted_values[0]]),
        title="angle errors",
        xlabel="tilt: largest |ground-truth angle| (deg)",
        ylabel="|measured - truth| (deg)",
    )
    left.draw_axes()
    left.line(
        (xlim[0], crit.max_angle_error_deg),
        (xlim[1], crit.max_angle_error_deg),
        RED,
        label=f"limit {crit.max_angle_error_deg:g} deg",
        dashed=True,
    )
    for label, colour, marker, key in angle_sets:
        left.scatter(tilt, [e[key] for e in errors], colour, marker, label)
    if predicted is not None:
        left.scatter(tilt, predicted[0], GREY, "cross", "simulation: largest |angle error|")
    left.draw_legend()

    pos = [e["pos_mm"] for e in errors]
    right = Panel(
        img,
        rects[1],
        xlim,
        padded_range([0.0, crit.max_position_error_mm * 1.2, *pos, *predicted_values[1]]),
        title="position error",
        xlabel="tilt: largest |ground-truth angle| (deg)",
        ylabel="|measured - truth| (mm)",
    )
    right.draw_axes()
    right.line(
        (xlim[0], crit.max_position_error_mm),
        (xlim[1], crit.max_position_error_mm),
        RED,
        label=f"limit {crit.max_position_error_mm:g} mm",
        dashed=True,
    )
    right.scatter(tilt, pos, BLUE, "circle", "position error")
    if predicted is not None:
        right.scatter(tilt, predicted[1], GREY, "cross", "simulation: position error")
    right.draw_legend()
    return img


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
