"""Analysis of a session: per-combination figures, plots, and the resemblance to the simulation.

Only measurement rows count; withdrawn rows (and withdrawal records) are left out. A row without
a converged frame counts as a fail in the pass rates and is left out of the error figures
(``no_pose`` counts them). Errors are absolute values: position per axis |x - gt_x| ... and
err_pos (Euclidean, mm); angles |err_alpha| ... (wrapped, degrees).

Tilt (the plots' x axis) = the largest |ground-truth angle| of the row: the magnitude the
simulation sweeps for a combination (each angle = magnitude x its sign).

Resemblance to the simulation: for each row, the simulation's verdict at its ground-truth pose
with the session's camera, QR side and solver: project the four vertices V1..V4 through the
camera model, round them to whole pixels, solve, and apply the session's acceptance criteria to
that single solve (a card turned away from the camera, or with a vertex outside the image, is a
fail). The verdict comes in the study's two readings (docs/simulation.md): **within criteria**
(the pose meets the criteria and the solver stopped before n_max, converged or settled above its
tolerance) and **converged and within criteria** (the solver's own converged flag holds too).
The resemblance is the share of rows whose logged pass equals the verdict, in each reading
(``percent`` and ``percent_converged``), printed beside the seed's 73.15 %.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.geometry import POSE_NAMES
from qrfield.methods import METHODS
from qrfield.sessions.averaging import judge_row
from qrfield.sessions.groundtruth import GroundTruth
from qrfield.sessions.store import LoggedRow, SessionInfo, read_session

#: The seed's figure for the agreement between experiment and simulation, percent.
SEED_RESEMBLANCE_PERCENT = 73.15
#: Error figures per axis: key -> (CSV column(s), unit).
AXES = {
    "x_mm": ("x", "gt_x"),
    "y_mm": ("y", "gt_y"),
    "z_mm": ("z", "gt_z"),
    "pos_mm": ("err_pos", None),
    "alpha_deg": ("err_alpha", None),
    "beta_deg": ("err_beta", None),
    "gamma_deg": ("err_gamma", None),
}


def row_truth(row: LoggedRow) -> GroundTruth:
    v = row.number_or_nan
    return GroundTruth(v("gt_x"), v("gt_y"), v("gt_z"), v("gt_alpha"), v("gt_beta"), v("gt_gamma"), row.combo)


def row_errors(row: LoggedRow) -> dict[str, float]:
    """Absolute errors of one row by axis (NaN when the row has no pose)."""
    out = {}
    for key, (column, truth_column) in AXES.items():
        value = row.number_or_nan(column)
        if truth_column is not None:
            value = value - row.number_or_nan(truth_column)
        out[key] = abs(value)
    return out


def row_tilt_deg(row: LoggedRow) -> float:
    """The largest |ground-truth angle| (the simulation's swept magnitude), degrees."""
    return max(abs(row.number_or_nan(c)) for c in ("gt_alpha", "gt_beta", "gt_gamma"))


def _has_pose(row: LoggedRow) -> bool:
    return all(math.isfinite(row.number_or_nan(c)) for c in POSE_NAMES)


def summarize(rows: Sequence[LoggedRow]) -> dict[str, Any]:
    """Rows, passes, pass rate (0..1), mean and max absolute error per axis over rows with a pose."""
    n = len(rows)
    passed = sum(1 for r in rows if r.passed)
    with_pose = [r for r in rows if _has_pose(r)]
    errors = [row_errors(r) for r in with_pose]
    mean_err: dict[str, float | None] = {}
    max_err: dict[str, float | None] = {}
    for key in AXES:
        values = np.array([e[key] for e in errors], dtype=float)
        values = values[np.isfinite(values)]
        mean_err[key] = round(float(values.mean()), 6) if values.size else None
        max_err[key] = round(float(values.max()), 6) if values.size else None
    return {
        "rows": n,
        "passed": passed,
        "pass_rate": passed / n if n else None,
        "no_pose": n - len(with_pose),
        "mean_abs_error": mean_err,
        "max_abs_error": max_err,
    }


# ------------------------------------------------------------------------------- simulation
def simulated_verdict(truth: GroundTruth, info: SessionInfo) -> tuple[bool, bool, str]:
    """The simulation's verdicts at a ground-truth pose with the session's camera, side and solver.

    Returns (within criteria, converged and within criteria, reason): the first needs the pose to
    meet the session's criteria and the solver to stop before its n_max (converged, or settled at
    its optimum above its tolerance); the second needs the solver's converged flag as well.
    ``reason`` says why a verdict is a fail ("" when both pass).
    """
    from qrfield import solvers
    from qrfield.geometry import Pose
    from qrfield.settings import from_dict
    from qrfield.visibility import view_problem

    pose = Pose(truth.position_mm, truth.angles_deg)
    problem = view_problem(info.camera, info.side_mm, pose.rotation, pose.position_mm)
    if problem:
        return False, False, problem
    corners = pose.corners_px(info.camera, info.side_mm)
    rounded = np.round(corners)
    settings = from_dict(solvers.settings_class(info.solver), info.solver_settings, strict=False)
    try:
        result = solvers.solve(rounded, info.camera, info.side_mm, info.solver, settings)
    except ValueError as exc:  # SolverError: the rounded corners are degenerate
        return False, False, f"solver refused the corners: {exc}"
    if not np.all(np.isfinite(result.position_mm)):
        return False, False, f"no pose: {result.reason}"
    n_max = getattr(settings, "n_max", None)
    stopped_in_time = result.converged or n_max is None or result.iterations < n_max
    verdict = judge_row(result.position_mm, result.angles_deg, truth, info.criteria)
    within = verdict.passed and stopped_in_time
    converged = within and result.converged
    reasons = [verdict.reason] if verdict.reason else []
    if not stopped_in_time:
        reasons.append(f"reached n_max = {n_max} without converging")
    elif not result.converged:
        reasons.append(f"not converged (settled: {result.reason})")
    return within, converged, "; ".join(reasons)


def resemblance(rows: Sequence[LoggedRow], info: SessionInfo) -> tuple[dict[str, Any] | None, str]:
    """({share, percent, matches, share_converged, percent_converged, matches_converged, compared,
    not_compared, seed_percent, solver, rounding, per_row}, "") or (None, reason).

    ``share``/``percent``/``matches``: the "within criteria" verdict; ``*_converged``: the
    "converged and within criteria" verdict (see :func:`simulated_verdict`).
    """
    if info.solver not in METHODS:
        return None, f"the session names no known solver ({info.solver!r})"
    per_row = []
    matches = matches_converged = compared = 0
    for row in rows:
        truth = row_truth(row)
        if not (np.all(np.isfinite(truth.position_mm)) and np.all(np.isfinite(truth.angles_deg))):
            # A hand-edited or damaged row: no pose to simulate; left out of the share, not fatal.
            per_row.append(
                {
                    "row": row.number,
                    "pass": row.passed,
                    "simulation_pass": None,
                    "simulation_pass_converged": None,
                    "match": None,
                    "match_converged": None,
                    "simulation_reason": "not compared: its ground truth is incomplete or not a number",
                }
            )
            continue
        compared += 1
        within, converged, reason = simulated_verdict(truth, info)
        match, match_converged = within == row.passed, converged == row.passed
        matches += match
        matches_converged += match_converged
        per_row.append(
            {
                "row": row.number,
                "pass": row.passed,
                "simulation_pass": within,
                "simulation_pass_converged": converged,
                "match": match,
                "match_converged": match_converged,
                "simulation_reason": reason,
            }
        )
    if not compared:
        return None, "no rows to compare" if not rows else "no row has a complete ground truth"
    share, share_converged = matches / compared, matches_converged / compared
    return {
        "share": share,
        "percent": round(100.0 * share, 2),
        "matches": matches,
        "share_converged": share_converged,
        "percent_converged": round(100.0 * share_converged, 2),
        "matches_converged": matches_converged,
        "compared": compared,
        "not_compared": len(rows) - compared,
        "seed_percent": SEED_RESEMBLANCE_PERCENT,
        "solver": info.solver,
        "rounding": "whole pixels",
        "per_row": per_row,
    }, ""


# ------------------------------------------------------------------------------- analyze
def analyze(
    session_dir: str | os.PathLike[str],
    *,
    out_dir: str | os.PathLike[str] | None = None,
    compare: bool = True,
) -> dict[str, Any]:
    """Figures of a session (see the module doc); with ``out_dir`` also the PNG plots.

    Returns a JSON-ready dict: rows (counted, withdrawn excluded), withdrawn, passed, pass_rate
    (0..1, None without rows), mean_abs_error / max_abs_error (per axis: x_mm, y_mm, z_mm,
    pos_mm, alpha_deg, beta_deg, gamma_deg), per_combination (a list of the same figures with
    ``combo``), resemblance (dict or None) with resemblance_reason, plots (paths), warnings.
    """
    info, content = read_session(session_dir)
    active = [r for r in content.rows if not r.withdrawn]
    overall = summarize(active)
    combos: dict[str, list[LoggedRow]] = {}
    for row in active:
        combos.setdefault(row.combo, []).append(row)
    per_combination = [{"combo": name, **summarize(rows)} for name, rows in combos.items()]
    result: dict[str, Any] = {
        "session": str(Path(session_dir)),
        "name": info.name,
        "solver": info.solver,
        "criteria": {
            "max_angle_error_deg": info.criteria.max_angle_error_deg,
            "max_position_error_mm": info.criteria.max_position_error_mm,
        },
        **overall,
        "withdrawn": sum(1 for r in content.rows if r.withdrawn),
        "per_combination": per_combination,
        "resemblance": None,
        "resemblance_reason": "not computed",
        "plots": [],
        "warnings": list(content.warnings),
    }
    if compare:
        result["resemblance"], result["resemblance_reason"] = resemblance(active, info)
    if out_dir is not None:
        from qrfield.files import make_folder
        from qrfield.sessions.plots import (
            ERRORS_VS_TILT,
            MEASURED_VS_TRUTH,
            plot_errors_vs_tilt,
            plot_measured_vs_truth,
        )

        out = make_folder(Path(out_dir), "--out folder")  # never the folders above it
        result["plots"] = [
            str(plot_errors_vs_tilt(active, info, out / ERRORS_VS_TILT)),
            str(plot_measured_vs_truth(active, info, out / MEASURED_VS_TRUTH)),
        ]
    return result


def format_report(result: dict[str, Any]) -> str:
    """The text ``qrfield analyze`` prints."""

    def pct(x: float | None) -> str:
        return "-" if x is None else f"{100.0 * x:.2f}%"

    def num(x: float | None, d: int = 2) -> str:
        return "-" if x is None else f"{x:.{d}f}"

    lines = [
        f"session {result['name']} ({result['session']}), solver {result['solver']}",
        f"rows {result['rows']} (withdrawn {result['withdrawn']} not counted), passed {result['passed']}, "
        f"pass rate {pct(result['pass_rate'])}",
        "",
        f"{'combination':<16}{'rows':>5}{'pass':>9}{'no pose':>8}  "
        + "  ".join(f"{k:>15}" for k in ("pos mm", "alpha deg", "beta deg", "gamma deg")),
        f"{'':<16}{'':>5}{'':>9}{'':>8}  " + "  ".join(f"{'mean / max':>15}" for _ in range(4)),
    ]
    for item in [*result["per_combination"], {"combo": "all", **result}]:
        mean, mx = item["mean_abs_error"], item["max_abs_error"]
        cells = "  ".join(
            f"{num(mean[k]) + ' / ' + num(mx[k]):>15}"
            for k in ("pos_mm", "alpha_deg", "beta_deg", "gamma_deg")
        )
        lines.append(
            f"{item['combo'][:15]:<16}{item['rows']:>5}{pct(item['pass_rate']):>9}"
            f"{item['no_pose']:>8}  {cells}"
        )
    lines.append("")
    res = result["resemblance"]
    if res is None:
        lines.append(
            f"resemblance to the simulation: not computed ({result['resemblance_reason']}); "
            f"seed: {SEED_RESEMBLANCE_PERCENT:.2f}%"
        )
    else:
        lines.append(
            f"resemblance to the simulation (whole-pixel corners, solver {res['solver']}, "
            f"{res['compared']} rows): within criteria {res['percent']:.2f}% "
            f"({res['matches']} rows agree), converged and within criteria "
            f"{res['percent_converged']:.2f}% ({res['matches_converged']} rows agree); "
            f"seed: {res['seed_percent']:.2f}%"
            + (
                f"; {res['not_compared']} row(s) without a complete ground truth not compared"
                if res.get("not_compared")
                else ""
            )
        )
    for path in result["plots"]:
        lines.append(f"wrote {path}")
    for warning in result["warnings"]:
        lines.append(f"warning: {warning}")
    return "\n".join(lines)
