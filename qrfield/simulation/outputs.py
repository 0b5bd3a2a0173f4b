"""Write a study's results to a folder: samples, largest-angle maps, heatmaps, summary.

Files (mm and degrees throughout):
  study.toml         the study as run (every field explicit; ``qrfield simulate study.toml`` reruns it)
  summary.json       {"combinations": [{"name", "coverage": {solver: f}, "coverage_converged": {solver: f}}],
                     "mean_coverage": {solver: f}, "mean_coverage_converged": {solver: f},
                     "samples", "seconds", "partial"}; coverage is a fraction 0..1 (null if nothing ran):
                     "coverage" = within criteria, "coverage_converged" = converged and within criteria
                     (see :meth:`qrfield.simulation.runner.StudyResult.coverage`)
  summary.md         the same as a table with the seed's 77.28 % beside it, plus the study's size
  samples.npz        every sample (arrays named as in :class:`qrfield.simulation.runner.StudyResult`,
                     plus max_angle_deg and sweep_end), compressed; poses and errors as float32
                     (7 significant digits: 0.05 micrometre at 400 mm)
  samples.csv        only on request (``csv_samples``, ``qrfield simulate --csv``): one row per solver
                     and sample (the default study: 174,000 rows, 20 MB)
  max_angles.csv     one row per solver, combination and grid point: the largest solvable angle
  heatmaps/COMBINATION_zZ.png   per combination and z: a panel per solver

A run's folder, when the caller names none, is a new ``<YYYYmmdd-HHMMSS>`` folder under
:func:`qrfield.paths.simulations_dir` (:func:`new_run_folder`), outside any source checkout.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.files import atomic_file, atomic_write, make_folder
from qrfield.images import write_image
from qrfield.methods import IPPE, NUMERICAL
from qrfield.simulation import heatmap
from qrfield.simulation.runner import (
    END_FAILED,
    END_LIMIT,
    END_NAMES,
    END_NOT_RUN,
    END_OUT_OF_VIEW,
    FAILED,
    NOT_RUN,
    OUT_OF_VIEW,
    PASSED,
    StudyResult,
)
from qrfield.solvers.registry import POSE_METHODS

#: The seed's figure: mean share of the simulated plane that converged within the criteria (percent).
SEED_COVERAGE_PERCENT = 77.28
#: Arrays of samples.npz stored as float32 (the rest keep their own type).
FLOAT32_ARRAYS = ("position_mm", "angles_deg", "position_error_mm", "angle_error_deg")
#: One line per solver key of the study that names a method alone (IPPE's is the registry's title).
SOLVER_NOTES = {
    NUMERICAL: "the thesis' model as docs/conventions.md reads it (seed initial guess, seed stop rule)",
    IPPE: POSE_METHODS[IPPE].title,
}


def solver_note(key: str, result: StudyResult) -> str:
    if key in SOLVER_NOTES:
        return SOLVER_NOTES[key]
    spec = next(s for s in result.config.solver_specs() if s.key == key)
    if spec.method == NUMERICAL:
        return f"the numerical model with initial guess '{spec.settings.initial_guess}' (ours)"
    return "OpenCV IPPE_SQUARE"


def percent(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.2f} %"


def write_outputs(
    result: StudyResult,
    out_dir: str | Path,
    *,
    csv_samples: bool = False,
    heatmaps: bool = True,
    command: str = "",
) -> list[Path]:
    """Write every output file into ``out_dir`` (created if needed); returns the paths written.

    ``csv_samples`` adds samples.csv (every sample as text; large). ``command``, if given, is the
    command line that made the study (quoted in summary.md).
    """
    out = make_folder(Path(out_dir), "output folder")  # never the folders above it
    written = [
        _write_text(out / "study.toml", result.config.to_toml()),
        _write_text(out / "summary.json", json.dumps(result.summary(), indent=2) + "\n"),
        _write_text(out / "summary.md", summary_markdown(result, command)),
        write_npz(result, out / "samples.npz"),
        write_max_angles_csv(result, out / "max_angles.csv"),
    ]
    if csv_samples:
        written.append(write_samples_csv(result, out / "samples.csv"))
    if heatmaps:
        written += write_heatmaps(result, out / "heatmaps")
    return written


def new_run_folder(base: str | Path | None = None, prefix: str = "") -> Path:
    """Create and return a new, empty folder ``<base>/<prefix><YYYYmmdd-HHMMSS>`` for one run's outputs.

    ``base`` defaults to :func:`qrfield.paths.simulations_dir` (created with its parents); a base
    the user named is created only if its own parent exists (:func:`qrfield.files.make_folder`). A
    second run in the same second gets ``-2``, ``-3``, ... Raises OSError (naming the folder) if it
    cannot be made.
    """
    from qrfield.paths import simulations_dir

    parent = make_folder(Path(base).expanduser() if base is not None else simulations_dir(), "output folder")
    stamp = prefix + time.strftime("%Y%m%d-%H%M%S")
    for n in range(1, 1000):
        folder = parent / (stamp if n == 1 else f"{stamp}-{n}")
        try:
            folder.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            raise OSError(f"cannot create the output folder {folder}: {exc.strerror or exc}") from None
        return folder
    raise OSError(f"cannot create a new output folder in {parent}: too many runs in one second")


def _write_text(path: Path, text: str) -> Path:
    return atomic_write(path, text)


def write_npz(result: StudyResult, path: Path) -> Path:
    best, end = result.max_angle_deg()
    with atomic_file(path, "wb") as handle:
        _savez(handle, result, best, end)
    return path


def _savez(handle: Any, result: StudyResult, best: np.ndarray, end: np.ndarray) -> None:
    np.savez_compressed(
        handle,
        x_mm=result.x_mm,
        y_mm=result.y_mm,
        z_mm=result.z_mm,
        sweep_deg=result.sweep_deg,
        combinations=np.array([c.name for c in result.combinations]),
        multipliers=np.array([c.multipliers for c in result.combinations], float).reshape(-1, 3),
        solvers=np.array(result.solvers),
        truth_angles_deg=result.truth_angles_deg,
        done=result.done,
        in_view=result.in_view,
        status=result.status,
        converged=result.converged,
        iterations=result.iterations,
        **{name: getattr(result, name).astype(np.float32) for name in FLOAT32_ARRAYS},
        max_angle_deg=best,
        sweep_end=end,
        seconds=np.array(result.seconds),
        partial=np.array(result.partial),
    )


STATUS_NAMES = {NOT_RUN: "not run", OUT_OF_VIEW: "out of view", FAILED: "failed", PASSED: "passed"}


SAMPLE_COLUMNS = (
    "solver,combination,x_mm,y_mm,z_mm,t_deg,alpha_true,beta_true,gamma_true,status,"
    "x,y,z,alpha,beta,gamma,converged,iterations,position_error_mm,angle_error_deg"
)


def _column(values: np.ndarray, fmt: str) -> np.ndarray:
    """Text of a numeric column ("" for NaN), formatted by numpy in one pass."""
    values = np.asarray(values, dtype=float)
    text = np.char.mod(fmt, np.nan_to_num(values))
    return np.where(np.isfinite(values), text, "")


def write_samples_csv(result: StudyResult, path: Path) -> Path:
    """One row per solver and done sample (out-of-view samples included, with empty pose fields)."""
    positions = result.grid_positions()
    c_idx, g_idx = np.nonzero(result.done)
    n_a = result.sweep_deg.size
    c_all = np.repeat(c_idx, n_a)
    g_all = np.repeat(g_idx, n_a)
    a_all = np.tile(np.arange(n_a), c_idx.size)
    names = np.array([c.name for c in result.combinations])
    shared = [
        names[c_all],
        *(_column(positions[g_all, k], "%.6g") for k in range(3)),
        _column(result.sweep_deg[a_all], "%.6g"),
        *(_column(result.truth_angles_deg[c_all, a_all, k], "%.6g") for k in range(3)),
    ]
    status_names = np.array([STATUS_NAMES[k] for k in (NOT_RUN, 0, 1, PASSED)])
    with atomic_file(path, "w", newline="") as fh:
        fh.write(SAMPLE_COLUMNS + "\n")
        for s, key in enumerate(result.solvers):
            sel = (s, c_all, g_all, a_all)
            columns = [
                np.full(c_all.size, key),
                *shared,
                status_names[result.status[sel].astype(int) + 1],
                *(_column(result.position_mm[(*sel, k)], "%.4f") for k in range(3)),
                *(_column(result.angles_deg[(*sel, k)], "%.4f") for k in range(3)),
                result.converged[sel].astype(int).astype(str),
                result.iterations[sel].astype(str),
                _column(result.position_error_mm[sel], "%.4g"),
                _column(result.angle_error_deg[sel], "%.4g"),
            ]
            rows = columns[0].astype(object)
            for column in columns[1:]:
                rows = rows + "," + column.astype(object)
            if rows.size:
                fh.write("\n".join(rows.tolist()) + "\n")
    return path


def write_max_angles_csv(result: StudyResult, path: Path) -> Path:
    best, end = result.max_angle_deg()
    positions = result.grid_positions()
    with atomic_file(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["solver", "combination", "x_mm", "y_mm", "z_mm", "max_angle_deg", "sweep_end"])
        for s, key in enumerate(result.solvers):
            for c, combo in enumerate(result.combinations):
                for g in range(positions.shape[0]):
                    w.writerow(
                        [
                            key,
                            combo.name,
                            *(f"{v:g}" for v in positions[g]),
                            "" if np.isnan(best[s, c, g]) else f"{best[s, c, g]:g}",
                            END_NAMES[int(end[s, c, g])],
                        ]
                    )
    return path


def cell_kinds(result: StudyResult, best: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(S, C, G) str: "" (a value), or why a cell has none (see heatmap.CELL_*)."""
    kinds = np.full(best.shape, "", dtype=object)
    first_status = result.status[..., 0]
    kinds[np.isnan(best) & (first_status == 0)] = heatmap.CELL_OUT_OF_VIEW
    kinds[np.isnan(best) & (first_status == 1)] = heatmap.CELL_NONE
    kinds[end == END_NOT_RUN] = heatmap.CELL_NOT_RUN
    return kinds


def write_heatmaps(result: StudyResult, folder: Path) -> list[Path]:
    """One PNG per combination and z (a panel per solver); returns the paths."""
    make_folder(folder, "heatmaps folder")
    maps = result.max_angle_deg()
    paths = []
    for c, combo in enumerate(result.combinations):
        if not result.done[c].any():
            continue
        for iz, z in enumerate(result.z_mm):
            path = folder / heatmap_name(combo.name, z)
            paths.append(write_image(path, heatmap_image(result, c, iz, maps)))
    return paths


def heatmap_name(combination: str, z_mm: float) -> str:
    """File name of the heatmap of a combination at one z: ``COMBINATION_zZ.png``."""
    return f"{_safe(combination)}_z{z_mm:g}.png"


def heatmap_image(
    result: StudyResult, combination: int, iz: int, maps: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """The heatmap of one combination at the iz-th z (a panel per solver) as a BGR image.

    ``maps``: result.max_angle_deg(), when the caller has it already.
    """
    best, end = maps if maps is not None else result.max_angle_deg()
    kinds = cell_kinds(result, best, end)
    nz, ny, nx = result.grid_shape
    cfg = result.config
    combo, z = result.combinations[combination], result.z_mm[iz]
    solvers = range(len(result.solvers))
    panels = [best[s, combination].reshape(nz, ny, nx)[iz] for s in solvers]
    kind = [kinds[s, combination].reshape(nz, ny, nx)[iz] for s in solvers]
    by_view = [(end[s, combination] == END_OUT_OF_VIEW).reshape(nz, ny, nx)[iz] for s in solvers]
    title = f"{combo.name} ({combo.describe()}), z = {z:g} mm: largest solvable angle t (deg)"
    subtitle = (
        f"{result.camera.name}, L = {cfg.side_mm:g} mm, degradation {cfg.degradation}"
        + (f" {cfg.noise_px:g} px" if cfg.degradation == "noise" else "")
        + f"; pass: <= {cfg.criteria.angle_deg:g} deg, < {cfg.criteria.position_mm:g} mm, "
        f"n <= {cfg.criteria.n_max}; sweep 0..{cfg.sweep_limit_deg:g} step {cfg.sweep_step_deg:g}"
    )
    return heatmap.draw_heatmap(
        panels,
        kind,
        list(result.solvers),
        result.x_mm,
        result.y_mm,
        cfg.sweep_limit_deg,
        title,
        subtitle,
        view_ended=by_view,
    )


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "+-_." else "_" for ch in name)


def sweep_end_shares(result: StudyResult) -> dict[str, dict[str, float]]:
    """Per solver, the share of run sweeps that reached the limit, failed, or left the view."""
    _, end = result.max_angle_deg()
    out = {}
    for s, key in enumerate(result.solvers):
        run = end[s] != END_NOT_RUN
        n = int(run.sum())
        out[key] = {
            END_NAMES[code]: (float(np.count_nonzero(end[s] == code)) / n if n else 0.0)
            for code in (END_LIMIT, END_FAILED, END_OUT_OF_VIEW)
        }
    return out


def summary_markdown(result: StudyResult, command: str = "") -> str:
    """summary.md: coverage table, the seed's 77.28 % beside it, size and time."""
    cfg = result.config
    cam = result.camera
    summary = result.summary()
    keys = result.solvers
    lines = [
        "# qrfield simulation study: summary",
        "",
        f"Study: {cfg.describe_size()}.",
        f"Camera {cam.name} ({cam.width}x{cam.height}, fx {cam.fx:.1f} px), QR side {cfg.side_mm:g} mm; "
        f"x {_range(cfg.x_range)}, y {_range(cfg.y_range)}, z {_range(cfg.z_range)} mm; "
        f"tilt t swept 0..{cfg.sweep_limit_deg:g} deg in {cfg.sweep_step_deg:g} deg steps.",
        f"Corners: {_degradation(cfg)}. "
        f"Acceptance (the seed's): angle error <= {cfg.criteria.angle_deg:g} deg "
        f"on each of alpha, beta, gamma, position error < {cfg.criteria.position_mm:g} mm, "
        f"within n_max = {cfg.criteria.n_max} iterations.",
        "",
        "Coverage = share of in-view samples (grid point, swept angle) that meet the criteria; "
        f"out-of-view samples (a vertex outside the image, the card facing away or seen more than "
        f"{cfg.max_view_angle_deg:g} deg from its normal) are left out of the denominator. "
        "The mean is over combinations. Two readings per solver: **within criteria** (the pose meets "
        "the criteria and the solver stopped before n_max: it met its tolerance, or settled at its "
        "least-squares optimum above it) and **converged and within criteria** (the solver's own "
        "converged flag holds too: for the numerical model, every side and diagonal within its "
        "tolerance). The largest solvable angle (heatmaps/, max_angles.csv) of a grid "
        "point is the largest t such that every step 0..t met the criteria (first reading): its sweep "
        "stops at the first failure, or when the card leaves the view.",
        "",
        "| combination | "
        + " | ".join(f"{k}: within criteria | {k}: converged and within criteria" for k in keys)
        + " |",
        "|---|" + "---|---|" * len(keys),
    ]
    for entry in summary["combinations"]:
        cells = [f"{percent(entry['coverage'][k])} | {percent(entry['coverage_converged'][k])}" for k in keys]
        lines.append(f"| {entry['name']} | " + " | ".join(cells) + " |")
    means = [
        f"**{percent(summary['mean_coverage'][k])}** | **{percent(summary['mean_coverage_converged'][k])}**"
        for k in keys
    ]
    lines.append("| **mean** | " + " | ".join(means) + " |")
    lines.append(
        f"| seed (Teoh 2022, MATLAB, numerical model) | {SEED_COVERAGE_PERCENT:.2f} % |"
        + " |" * (2 * len(keys) - 1)
    )
    lines += ["", "Solvers:"]
    lines += [f"- `{k}`: {solver_note(k, result)}" for k in keys]
    lines += [
        "",
        "How the sweeps ended (share of sweeps: every step passed / a step failed / "
        "the card left the view first):",
    ]
    for key, shares in sweep_end_shares(result).items():
        lines.append(
            f"- `{key}`: limit {percent(shares['limit'])}, failed {percent(shares['failed'])}, "
            f"out of view {percent(shares['out of view'])}"
        )
    in_view = int(result.in_view[result.done].sum())
    rate = summary["samples"] / result.seconds if result.seconds > 0 else 0.0
    lines += [
        "",
        f"Samples: {summary['samples']} poses ({in_view} in view), each solved by {len(keys)} solvers, "
        f"in {summary['seconds']:.1f} s ({rate:.0f} poses/s).",
    ]
    if command:
        lines += ["", f"Command: `{command}`"]
    if result.partial:
        lines.append(
            "**Partial**: the run was stopped; the figures cover the grid points whose sweeps were done."
        )
    return "\n".join(lines) + "\n"


def _range(r: tuple[float, float, float]) -> str:
    return f"{r[0]:g}" if r[0] == r[1] else f"{r[0]:g}..{r[1]:g} step {r[2]:g}"


def _degradation(cfg: Any) -> str:
    if cfg.degradation == "round":
        return "rounded to whole pixels"
    if cfg.degradation == "noise":
        return f"Gaussian noise sigma {cfg.noise_px:g} px per coordinate (seed {cfg.noise_seed})"
    return "exact (noise-free)"
