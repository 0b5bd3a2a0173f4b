"""A session's report: one self-contained ``report.html`` a supervisor opens offline in any browser.

What it holds (docs/conventions.md, "Guided experiments and the session report"): the session's
settings (camera model, QR side, solver and its settings, criteria, frames per row, operator,
notes, the plan and where it stands); the pass rate per rotation combination and tilt; the two
analysis figures (errors against tilt, with the simulation's prediction beside the rows, and
measured against truth); every row with its per-frame standard uncertainty and frame scatter;
and the simulation's prediction for exactly those poses (:func:`qrfield.simulation.targets.predict_poses`
at each row's ground truth, with the session's camera model, QR side, solver, solver settings and
criteria, and the study's corner degradation, named in the report).

Self-contained: the figures are PNGs in ``data:`` URIs, the style is inline, there is no script,
and a Content-Security-Policy forbids every other load (``default-src 'none'; img-src data:``), so
the page draws the same without a network and cannot reach one. Only rows in force count
(withdrawn rows are named, not drawn), as in :mod:`qrfield.sessions.analysis`.
"""

from __future__ import annotations

import base64
import datetime as dt
import html
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import qrfield
from qrfield.geometry import ANGLE_NAMES, POSE_NAMES, POSITION_NAMES
from qrfield.sessions.analysis import row_tilt_deg, summarize
from qrfield.sessions.store import LoggedRow, SessionInfo, read_session

REPORT_FILE = "report.html"
#: The page's Content-Security-Policy: nothing is loaded but the page itself and its data: images.
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
#: Tilt values closer than this (deg) share a column of the pass-rate table.
TILT_DECIMALS = 1
PASS_RATES = "Pass rates by combination and tilt"
PREDICTION = "The simulation's prediction"
STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em auto; max-width: 1200px; color: #222;
       padding: 0 1em; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { margin-top: 1.6em; border-bottom: 1px solid #ccc; }
.lead { font-size: 1.15em; } .muted { color: #666; }
table { border-collapse: collapse; margin: 0.5em 0; } td, th { border: 1px solid #ccc; padding: 2px 6px; }
th { background: #f2f2f2; text-align: left; } td.n { text-align: right; font-variant-numeric: tabular-nums; }
.wide { overflow-x: auto; } .wide table { font-size: 12px; white-space: nowrap; }
.all { background: #d9f0d9; } .some { background: #fdf0c8; } .none { background: #f7d4d4; }
.fail td { background: #fbe9e9; }
figure { margin: 1em 0; } img { max-width: 100%; height: auto; border: 1px solid #ddd; }
@media print { .wide { overflow: visible; } }
"""


@dataclass(frozen=True)
class ReportSummary:
    """What a report says in a few numbers (the command prints them)."""

    path: Path
    rows: int
    passed: int
    withdrawn: int
    images: int
    predicted_pass_rate: float | None = None
    agreement: float | None = None
    noise: str = ""
    warnings: list[str] = field(default_factory=list)


def _esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _num(value: float | None, decimals: int = 2) -> str:
    if value is None or not math.isfinite(float(value)):
        return "–"
    return f"{float(value):.{decimals}f}"


def _pct(value: float | None) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{100.0 * value:.0f} %"


def _png_uri(image: np.ndarray) -> str:
    import cv2

    ok, encoded = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - OpenCV always encodes a BGR uint8 image
        raise OSError("OpenCV could not encode a figure as PNG")
    return "data:image/png;base64," + base64.b64encode(encoded.tobytes()).decode("ascii")


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], classes: Sequence[str] = ()) -> str:
    """An HTML table; cells are HTML already (escape text with _esc)."""
    head = "".join(f"<th>{h}</th>" for h in header)
    body = []
    for k, cells in enumerate(rows):
        css = f' class="{classes[k]}"' if k < len(classes) and classes[k] else ""
        body.append(f"<tr{css}>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _td(text: str, numeric: bool = False, css: str = "") -> str:
    classes = " ".join(c for c in ("n" if numeric else "", css) if c)
    return f'<td class="{classes}">{text}</td>' if classes else f"<td>{text}</td>"


def _truth(rows: Sequence[LoggedRow]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) positions mm, (N, 3) angles deg of the rows' ground truth, and (N,) which are complete."""
    v = np.array([[r.number_or_nan(f"gt_{k}") for k in POSE_NAMES] for r in rows])
    v = v.reshape(-1, 6)
    return v[:, :3], v[:, 3:], np.all(np.isfinite(v), axis=1)


def _prediction(rows: Sequence[LoggedRow], info: SessionInfo, noise: Any, draws: int | None) -> Any:
    """The simulation at the rows' complete ground truths (None entries for incomplete ones)."""
    from qrfield.settings import from_dict
    from qrfield.simulation.targets import predict_poses
    from qrfield.solvers import settings_class

    position, angles, complete = _truth(rows)
    settings = from_dict(settings_class(info.solver), info.solver_settings, strict=False)
    prediction = predict_poses(
        position[complete],
        angles[complete],
        info.camera,
        info.side_mm,
        info.solver,
        settings,
        info.criteria,
        noise,
        draws=draws,
    )
    return prediction, complete


def build_report(
    session_dir: str | os.PathLike[str],
    *,
    noise: Any = None,
    draws: int | None = None,
    simulate: bool = True,
    out: Path | None = None,
    now: dt.datetime | None = None,
) -> tuple[str, ReportSummary]:
    """The report's HTML and its summary. ``noise``: the study's corner degradation
    (:class:`qrfield.simulation.targets.NoiseModel`; default: the shipped study's); ``draws``: noise
    draws per pose; ``simulate`` False leaves the prediction out."""
    from qrfield.sessions.plan import PlanError
    from qrfield.sessions.progress import PlanProgress
    from qrfield.sessions.store import SessionError

    folder = Path(session_dir)
    info, content = read_session(folder)
    active = [r for r in content.rows if not r.withdrawn]
    withdrawn = [r for r in content.rows if r.withdrawn]
    warnings = list(content.warnings)
    progress = None
    try:
        progress = PlanProgress.load(folder, content.rows)
    except (PlanError, SessionError, OSError) as exc:
        warnings.append(f"the session's plan cannot be read: {exc}")
    if progress is not None:
        warnings += progress.warnings
    if noise is None:
        from qrfield.simulation import load_study
        from qrfield.simulation.targets import NoiseModel

        noise = NoiseModel.of_study(load_study())
    prediction, complete = (None, None)
    if simulate and active:
        prediction, complete = _prediction(active, info, noise, draws)
    per_row = _per_row_prediction(active, prediction, complete)
    overall = summarize(active)
    sections = [
        _summary_section(
            info, overall, withdrawn, per_row, noise if prediction is not None else None, progress, active
        ),
        _settings_section(info, folder, progress, content.rows),
        _pass_rate_section(active, per_row, progress),
        _figures_section(active, info, per_row),
        _simulation_section(info, prediction, per_row, noise, simulate),
        _rows_section(active, withdrawn, per_row, progress),
    ]
    if progress is not None:
        sections.append(_plan_section(progress, content.rows))
    if warnings:
        items = "".join(f"<li>{_esc(w)}</li>" for w in warnings)
        sections.append(f'<section id="warnings"><h2>Warnings</h2><ul>{items}</ul></section>')
    stamp = (now or dt.datetime.now().astimezone()).isoformat(timespec="seconds")
    footer = (
        f'<footer class="muted"><p>Written by qrfield {_esc(qrfield.__version__)} at {_esc(stamp)} from '
        f"{_esc(folder.resolve())}. This page loads nothing from anywhere: its figures are embedded."
        "</p></footer>"
    )
    title = f"qrfield report: {info.name}"
    page = (
        '<!doctype html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta http-equiv="Content-Security-Policy" content="{CSP}">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_esc(title)}</title><style>{STYLE}</style></head><body>"
        f"<h1>Session {_esc(info.name)}</h1>" + "\n".join(sections) + footer + "</body></html>\n"
    )
    shares = [p["share"] for p in per_row if p is not None and math.isfinite(p["share"])]
    agree = [p["agrees"] for p in per_row if p is not None and p["agrees"] is not None]
    summary = ReportSummary(
        path=out or folder / REPORT_FILE,
        rows=len(active),
        passed=overall["passed"],
        withdrawn=len(withdrawn),
        images=page.count("<img "),
        predicted_pass_rate=float(np.mean(shares)) if shares else None,
        agreement=float(np.mean(agree)) if agree else None,
        noise=noise.describe() if prediction is not None else "",
        warnings=warnings,
    )
    return page, summary


def write_report(
    session_dir: str | os.PathLike[str], out: str | os.PathLike[str] | None = None, **options: Any
) -> ReportSummary:
    """Write the report (default ``<session>/report.html``), all or nothing; its summary."""
    from qrfield.files import atomic_write

    target = Path(out) if out is not None else Path(session_dir) / REPORT_FILE
    page, summary = build_report(session_dir, out=target, **options)
    atomic_write(target, page)
    return summary


# ------------------------------------------------------------------------------------ sections
def _per_row_prediction(
    rows: Sequence[LoggedRow], prediction: Any, complete: Any
) -> list[dict[str, Any] | None]:
    """For each row: the predicted pass share, mean errors and whether the row's pass agrees."""
    if prediction is None:
        return [None] * len(rows)
    pos, ang = prediction.mean_abs_errors()
    share = prediction.pass_share
    out: list[dict[str, Any] | None] = []
    k = 0
    for row, ok in zip(rows, complete, strict=True):
        if not ok:
            out.append(None)
            continue
        in_view = bool(prediction.in_view[k])
        s = float(share[k])
        out.append(
            {
                "in_view": in_view,
                "share": s,
                "position_mm": float(pos[k]),
                "angle_deg": float(np.max(ang[k])) if np.any(np.isfinite(ang[k])) else math.nan,
                "agrees": (row.passed == (s >= 0.5)) if in_view else None,
            }
        )
        k += 1
    return out


def _summary_section(
    info: SessionInfo,
    overall: dict[str, Any],
    withdrawn: Sequence[LoggedRow],
    per_row: Sequence[dict[str, Any] | None],
    noise: Any,
    progress: Any,
    rows: Sequence[LoggedRow],
) -> str:
    n = overall["rows"]
    lines = [
        f'<p class="lead"><b>{overall["passed"]} of {n} rows pass</b> ({_pct(overall["pass_rate"])}) '
        f"the acceptance criteria {_esc(info.criteria.label())}"
        + (f"; {len(withdrawn)} withdrawn row(s) not counted" if withdrawn else "")
        + ".</p>"
    ]
    shares = [p["share"] for p in per_row if p is not None and math.isfinite(p["share"])]
    agree = [p["agrees"] for p in per_row if p is not None and p["agrees"] is not None]
    if noise is not None and shares:
        lines.append(
            f"<p>The simulation predicts a pass rate of {_pct(float(np.mean(shares)))} for the same poses "
            f"({_esc(noise.describe())}); the measured verdict agrees with the predicted one in "
            f"{sum(agree)} of {len(agree)} rows ({_pct(float(np.mean(agree)) if agree else None)}).</p>"
        )
    if progress is not None:
        counts = progress.counts(list(rows) + list(withdrawn))
        lines.append(
            f"<p>Plan: {counts['done']} of {len(progress.targets)} targets done, "
            f"{counts['skipped']} skipped, "
            f"{counts['todo']} to do.</p>"
        )
    mean, mx = overall["mean_abs_error"], overall["max_abs_error"]
    if n:
        lines.append(
            "<p>Mean / largest absolute error: position "
            f"{_num(mean['pos_mm'])} / {_num(mx['pos_mm'])} mm, alpha {_num(mean['alpha_deg'])} / "
            f"{_num(mx['alpha_deg'])}°, beta {_num(mean['beta_deg'])} / {_num(mx['beta_deg'])}°, gamma "
            f"{_num(mean['gamma_deg'])} / {_num(mx['gamma_deg'])}°.</p>"
        )
    return '<section id="summary">' + "".join(lines) + "</section>"


def _settings_section(info: SessionInfo, folder: Path, progress: Any, all_rows: Sequence[LoggedRow]) -> str:
    cam = info.camera
    dist = ", ".join(f"{float(d):g}" for d in cam.dist)
    solver = (
        ", ".join(f"{_esc(k)} = {_esc(v)}" for k, v in sorted(info.solver_settings.items())) or "defaults"
    )
    items = [
        ("session folder", _esc(folder.resolve())),
        ("created", _esc(info.created)),
        ("operator", _esc(info.operator or "–")),
        ("notes", _esc(info.notes or "–").replace("\n", "<br>")),
        ("app version", _esc(info.app_version)),
        ("camera", f"{_esc(cam.name)}, {cam.width} x {cam.height} px"),
        (
            "intrinsics",
            f"fx {cam.fx:.2f}, fy {cam.fy:.2f}, cx {cam.cx:.2f}, cy {cam.cy:.2f} px; "
            "distortion k1, k2, p1, p2, k3 = "
            f"{_esc(dist)}",
        ),
        ("QR side", f"{info.side_mm:g} mm (the symbol, quiet zone excluded)"),
        ("solver", f"{_esc(info.solver)} ({solver})"),
        (
            "acceptance criteria",
            f"each of alpha, beta, gamma within {info.criteria.max_angle_error_deg:g}° and the position "
            f"within {info.criteria.max_position_error_mm:g} mm (Euclidean) of the ground truth",
        ),
        ("frames per row", f"{info.frames_per_row} (means; angles as circular means)"),
    ]
    if progress is not None:
        items.append(
            (
                "plan",
                f"{len(progress.targets)} targets"
                + (f", from {_esc(progress.source)}" if progress.source else ""),
            )
        )
    body = "".join(f"<tr><th>{_esc(k)}</th><td>{v}</td></tr>" for k, v in items)
    return f'<section id="settings"><h2>Settings</h2><table>{body}</table></section>'


def _section(name: str, title: str, body: str) -> str:
    return f'<section id="{name}"><h2>{_esc(title)}</h2>{body}</section>'


def _tilt_key(row: LoggedRow) -> float:
    tilt = row_tilt_deg(row)
    return round(tilt, TILT_DECIMALS) if math.isfinite(tilt) else math.nan


def _pass_rate_section(
    rows: Sequence[LoggedRow], per_row: Sequence[dict[str, Any] | None], progress: Any
) -> str:
    if not rows:
        return _section("pass-rates", PASS_RATES, "<p>No rows yet.</p>")
    order: list[str] = []
    if progress is not None:
        order = list(dict.fromkeys(t.combo for t in progress.targets))
    for row in rows:
        if row.combo not in order:
            order.append(row.combo)
    tilts = sorted({_tilt_key(r) for r in rows if math.isfinite(_tilt_key(r))})
    cells: dict[tuple[str, float], list[int]] = {}
    for k, row in enumerate(rows):
        cells.setdefault((row.combo, _tilt_key(row)), []).append(k)
    table_rows = []
    for combo in order:
        members = [k for k, r in enumerate(rows) if r.combo == combo]
        if not members:
            continue
        line = [f"<th>{_esc(combo or '(none)')}</th>"]
        for tilt in tilts:
            line.append(
                _rate_cell(
                    [rows[k] for k in cells.get((combo, tilt), [])],
                    [per_row[k] for k in cells.get((combo, tilt), [])],
                )
            )
        line.append(_rate_cell([rows[k] for k in members], [per_row[k] for k in members]))
        table_rows.append(line)
    total = _rate_cell(list(rows), list(per_row))
    table_rows.append(
        ["<th>all</th>"]
        + [
            _rate_cell(
                [r for r in rows if _tilt_key(r) == t],
                [p for r, p in zip(rows, per_row, strict=True) if _tilt_key(r) == t],
            )
            for t in tilts
        ]
        + [total]
    )
    header = ["combination", *(f"tilt {t:g}°" for t in tilts), "all"]
    note = (
        '<p class="muted">Each cell: rows that pass / rows, and in brackets the simulation\'s predicted pass '
        "rate for the same poses. Tilt = the largest |ground-truth angle| (the magnitude the study "
        "sweeps).</p>"
    )
    return _section("pass-rates", PASS_RATES, _table(header, table_rows) + note)


def _rate_cell(rows: Sequence[LoggedRow], predicted: Sequence[dict[str, Any] | None]) -> str:
    if not rows:
        return "<td></td>"
    passed = sum(1 for r in rows if r.passed)
    css = "all" if passed == len(rows) else ("none" if passed == 0 else "some")
    shares = [p["share"] for p in predicted if p is not None and math.isfinite(p["share"])]
    sim = f" <span class='muted'>({_pct(float(np.mean(shares)))})</span>" if shares else ""
    return f'<td class="n {css}">{passed}/{len(rows)}{sim}</td>'


def _figures_section(
    rows: Sequence[LoggedRow], info: SessionInfo, per_row: Sequence[dict[str, Any] | None]
) -> str:
    from qrfield.sessions.plots import errors_vs_tilt_image, measured_vs_truth_image

    predicted = None
    if any(p is not None for p in per_row):
        predicted = (
            np.array([p["angle_deg"] if p is not None else math.nan for p in per_row], dtype=float),
            np.array([p["position_mm"] if p is not None else math.nan for p in per_row], dtype=float),
        )
    figures = [
        (
            "errors-against-tilt",
            errors_vs_tilt_image(rows, info, predicted),
            "Absolute errors against tilt, with the acceptance limits (dashed)"
            + (
                " and the simulation's mean errors at the same poses (grey crosses)"
                if predicted is not None
                else ""
            ),
        ),
        (
            "measured-against-truth",
            measured_vs_truth_image(rows, info),
            "Measured against ground truth, per DOF",
        ),
    ]
    parts = [
        f'<figure id="{name}"><img src="{_png_uri(image)}" alt="{_esc(caption)}" width="{image.shape[1]}" '
        f'height="{image.shape[0]}"><figcaption>{_esc(caption)}.</figcaption></figure>'
        for name, image, caption in figures
    ]
    return '<section id="figures"><h2>Figures</h2>' + "".join(parts) + "</section>"


def _simulation_section(
    info: SessionInfo, prediction: Any, per_row: Sequence[dict[str, Any] | None], noise: Any, simulate: bool
) -> str:
    if not simulate:
        return _section("simulation", PREDICTION, "<p>Not computed (--no-simulation).</p>")
    if prediction is None:
        return _section("simulation", PREDICTION, "<p>No rows to predict.</p>")
    n_max = info.solver_settings.get("n_max")
    out_of_view = int(np.count_nonzero(~prediction.in_view))
    draws = f", {prediction.draws} draws per pose" if prediction.draws > 1 else ""
    stop = f", and a solver that stopped before n_max = {_esc(n_max)}" if n_max is not None else ""
    cam = info.camera
    text = (
        "<p>For each row's ground truth, the simulation study's steps (docs/simulation.md): the four "
        f"vertices projected through the session's camera model ({_esc(cam.name)}, {cam.width} x "
        f"{cam.height}) for a {info.side_mm:g} mm code, then <b>{_esc(noise.describe())}</b> (the "
        f"study's corner degradation{draws}), solved by <b>{_esc(info.solver)}</b> with the session's "
        f"settings and judged by the session's criteria ({_esc(info.criteria.label())}{stop}). Each "
        f"prediction is one view solved once, where a row averages {info.frames_per_row} frames. A card "
        f"seen more than {noise.max_view_angle_deg:g}° from face-on is out of view"
        + (f": {out_of_view} pose(s) are." if out_of_view else ".")
        + " The measured rows also carry what the simulation leaves out: the detector, blur, lighting, "
        "the jig.</p>"
    )
    return _section("simulation", PREDICTION, text)


def _rows_section(
    rows: Sequence[LoggedRow],
    withdrawn: Sequence[LoggedRow],
    per_row: Sequence[dict[str, Any] | None],
    progress: Any,
) -> str:
    header = [
        "row",
        "target",
        "combination",
        "truth x, y, z (mm)",
        "truth α, β, γ (°)",
        *(f"{k} ± σ" for k in ("x mm", "y mm", "z mm", "α °", "β °", "γ °")),
        "scatter x, y, z / α, β, γ",
        "err pos mm",
        "err α, β, γ °",
        "frames",
        "pass",
        "simulation: pass, err pos mm / largest angle °",
        "note",
    ]
    body = []
    classes = []
    for row, predicted in zip(rows, per_row, strict=True):
        v = row.values
        target = progress.target_of_row(row.number) if progress is not None else None
        measured = [
            _td(f"{_esc(v.get(k) or '–')} ± {_esc(v.get(f'sigma_{k}') or '–')}", numeric=True)
            for k in POSE_NAMES
        ]
        scatter = (
            " ".join(v.get(f"std_{k}") or "–" for k in POSITION_NAMES)
            + " / "
            + " ".join(v.get(f"std_{k}") or "–" for k in ANGLE_NAMES)
        )
        if predicted is None:
            sim = "–"
        elif not predicted["in_view"]:
            sim = "out of view"
        else:
            errors = f"{_num(predicted['position_mm'])} / {_num(predicted['angle_deg'])}"
            sim = f"{_pct(predicted['share'])}, {errors}"
        body.append(
            [
                _td(str(row.number), numeric=True),
                _td(str(target.number) if target is not None else "–", numeric=True),
                _td(_esc(row.combo)),
                _td(" ".join(_esc(v.get(f"gt_{k}", "")) for k in POSITION_NAMES), numeric=True),
                _td(" ".join(_esc(v.get(f"gt_{k}", "")) for k in ANGLE_NAMES), numeric=True),
                *measured,
                _td(_esc(scatter), numeric=True),
                _td(_esc(v.get("err_pos") or "–"), numeric=True),
                _td(" ".join(_esc(v.get(f"err_{k}") or "–") for k in ANGLE_NAMES), numeric=True),
                _td(f"{_esc(v.get('n_converged', ''))}/{_esc(v.get('n_frames', ''))}", numeric=True),
                _td("pass" if row.passed else "fail"),
                _td(_esc(sim), numeric=True),
                _td(_esc(v.get("note", ""))),
            ]
        )
        classes.append("" if row.passed else "fail")
    explain = (
        '<p class="muted">Measured values are the means over the row\'s converged frames; ± σ is the mean '
        'per-frame standard uncertainty from the image evidence (docs/conventions.md, "Pose uncertainty"; '
        "frames of a still card share their error, so the mean is not σ/√n more certain); scatter is the "
        "frame-to-frame sample standard deviation. Errors are measured minus truth.</p>"
    )
    gone = ""
    if withdrawn:
        gone = f"<p>Withdrawn (not counted): row(s) {', '.join(str(r.number) for r in withdrawn)}.</p>"
    table = _table(header, body, classes) if rows else "<p>No rows yet.</p>"
    return f'<section id="rows"><h2>Rows</h2><div class="wide">{table}</div>{explain}{gone}</section>'


def _plan_section(progress: Any, all_rows: Sequence[LoggedRow]) -> str:
    states = progress.states(all_rows)
    open_ = [s for s in states if s.state != "done"]
    if not open_:
        return '<section id="plan"><h2>Plan</h2><p>Every target of the plan has a row.</p></section>'
    rows = [
        [
            _td(str(s.target.number), numeric=True),
            _td(_esc(s.state)),
            _td(_esc(s.target.combo)),
            _td(" ".join(f"{v:g}" for v in s.target.truth.position_mm), numeric=True),
            _td(" ".join(f"{v:g}" for v in s.target.truth.angles_deg), numeric=True),
            _td(_esc(s.target.note)),
        ]
        for s in open_
    ]
    header = ["target", "state", "combination", "x, y, z (mm)", "α, β, γ (°)", "note"]
    return f'<section id="plan"><h2>Plan: targets without a row</h2>{_table(header, rows)}</section>'
