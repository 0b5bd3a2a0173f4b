"""Run a simulation study: every grid point x combination x swept angle, projected, degraded, solved.

For each combination the tilt magnitude t is swept 0, step, ... up to the limit; the card's angles
are t times the combination's multipliers and its centre is at each grid point (x, y, z) of the
camera frame. The four vertices are projected through the camera model (exact pixels, the truth),
optionally rounded to whole pixels or given Gaussian noise, and each solver finds the pose from
them (its batch path: numpy-vectorised for the numerical model). A sample passes when the pose
meets the acceptance criteria: |error| <= angle_deg on each of alpha, beta, gamma (wrapped), the
Euclidean position error < position_mm, and the solver stopped within n_max iterations (it met its
tolerance, or settled at its optimum earlier: a run that reaches n_max without meeting its
tolerance fails). Counting a settled run as "within n_max" is our reading, not the seed's: with
rounded or noisy corners no depths meet a 0.01 mm tolerance, and the pose criteria then decide.
Out-of-view poses (see :mod:`qrfield.simulation.view`) are neither passes nor
failures.

Work is done in chunks of whole sweeps (a few grid points, all angles, all solvers), so a stop
request (Ctrl-C, the app's Stop button) loses at most the chunk in progress and every kept grid
point has complete sweeps.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import angle_difference, angles_from_rotation, rotation_matrix
from qrfield.simulation.combinations import Combination
from qrfield.simulation.study import SolverSpec, StudyConfig
from qrfield.simulation.view import poses_in_view

#: Poses per chunk (a chunk is whole sweeps of a few grid points); bounds the loss on a stop.
CHUNK_POSES = 2048

# Sample status codes (per solver, combination, grid point, angle).
NOT_RUN, OUT_OF_VIEW, FAILED, PASSED = -1, 0, 1, 2
# How a sweep ended (per solver, combination, grid point).
END_NOT_RUN, END_LIMIT, END_FAILED, END_OUT_OF_VIEW = 0, 1, 2, 3
END_NAMES = {END_NOT_RUN: "not run", END_LIMIT: "limit", END_FAILED: "failed", END_OUT_OF_VIEW: "out of view"}

#: solve_fn(spec, corners (N, 4, 2), camera, side_mm) -> an object with numpy arrays position_mm
#: (N, 3), angles_deg (N, 3), converged (N,) and iterations (N,), like qrfield.solvers.BatchResult.
SolveFn = Callable[[SolverSpec, np.ndarray, CameraModel, float], Any]


@dataclass(frozen=True)
class Progress:
    """What a progress callback receives after each chunk."""

    done_poses: int
    total_poses: int
    combination: str
    seconds: float

    @property
    def fraction(self) -> float:
        return self.done_poses / self.total_poses if self.total_poses else 1.0

    @property
    def poses_per_second(self) -> float:
        return self.done_poses / self.seconds if self.seconds > 0 else 0.0


@dataclass
class StudyResult:
    """Every sample of a study and what follows from them.

    Axes: S solvers (``solvers``), C combinations, G grid points in the order (z, y, x) with x
    fastest (``grid_index(ix, iy, iz)``), A swept angles (``sweep_deg``).

    Attributes:
        config: the study.
        camera: the camera model used.
        x_mm, y_mm, z_mm: grid values (mm); sweep_deg: (A,) swept magnitudes t (degrees).
        combinations: the C combinations; solvers: the S solver keys.
        truth_angles_deg: (C, A, 3) true alpha, beta, gamma of each combination and angle.
        done: (C, G) bool, the grid point's sweeps were run (all angles, all solvers).
        in_view: (C, G, A) bool.
        status: (S, C, G, A) int8: NOT_RUN, OUT_OF_VIEW, FAILED or PASSED.
        position_mm, angles_deg: (S, C, G, A, 3) the solvers' poses (NaN where none).
        converged: (S, C, G, A) bool; iterations: (S, C, G, A) int32.
        position_error_mm: (S, C, G, A) Euclidean; angle_error_deg: (S, C, G, A) the largest
            |error| of alpha, beta, gamma (NaN where no pose).
        seconds: wall time; partial: stopped before the end.
    """

    config: StudyConfig
    camera: CameraModel
    x_mm: np.ndarray
    y_mm: np.ndarray
    z_mm: np.ndarray
    sweep_deg: np.ndarray
    combinations: list[Combination]
    solvers: list[str]
    truth_angles_deg: np.ndarray
    done: np.ndarray
    in_view: np.ndarray
    status: np.ndarray
    position_mm: np.ndarray
    angles_deg: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    position_error_mm: np.ndarray
    angle_error_deg: np.ndarray
    seconds: float = 0.0
    partial: bool = False

    # ------------------------------------------------------------------ grid
    @property
    def grid_shape(self) -> tuple[int, int, int]:
        """(nz, ny, nx)."""
        return (self.z_mm.size, self.y_mm.size, self.x_mm.size)

    def grid_index(self, ix: int, iy: int, iz: int) -> int:
        return (iz * self.y_mm.size + iy) * self.x_mm.size + ix

    def grid_positions(self) -> np.ndarray:
        """(G, 3) QR centres in mm, in grid order."""
        return grid_positions(self.x_mm, self.y_mm, self.z_mm)

    # ------------------------------------------------------------------ counts
    @property
    def poses_done(self) -> int:
        """Simulated poses (grid point, combination, angle), each solved by every solver."""
        return int(self.done.sum()) * self.sweep_deg.size

    def coverage(self, solver: str, combination: int | None = None) -> float | None:
        """Share of in-view samples that pass, over one combination (or all pooled); None if none ran."""
        s = self.solvers.index(solver)
        status = self.status[s] if combination is None else self.status[s, combination]
        passed = int(np.count_nonzero(status == PASSED))
        judged = passed + int(np.count_nonzero(status == FAILED))
        return passed / judged if judged else None

    def mean_coverage(self, solver: str) -> float | None:
        """Mean of the per-combination coverages (the seed's 'average'); None if none ran."""
        values = [self.coverage(solver, c) for c in range(len(self.combinations))]
        values = [v for v in values if v is not None]
        return float(np.mean(values)) if values else None

    def max_angle_deg(self) -> tuple[np.ndarray, np.ndarray]:
        """The largest solvable angle of every sweep and how the sweep ended.

        Returns (S, C, G) float: the largest swept magnitude t such that every step 0..t passed
        (NaN when the sweep did not pass at t = 0, or was not run), and (S, C, G) int8 END_* codes:
        END_LIMIT (every step passed), END_FAILED (a step failed the criteria), END_OUT_OF_VIEW (a
        step left the view before any failure; the sweep stops there too), END_NOT_RUN.
        """
        ok = self.status == PASSED
        first_bad = np.where(ok.all(axis=-1), ok.shape[-1], np.argmin(ok, axis=-1))
        angles = np.concatenate([[np.nan], self.sweep_deg])
        best = angles[first_bad]  # index 0 -> NaN, k -> sweep_deg[k - 1]
        stopper = np.take_along_axis(
            self.status, np.minimum(first_bad, ok.shape[-1] - 1)[..., None], axis=-1
        )[..., 0]
        end = np.where(
            first_bad == ok.shape[-1],
            END_LIMIT,
            np.where(stopper == OUT_OF_VIEW, END_OUT_OF_VIEW, END_FAILED),
        ).astype(np.int8)
        not_run = ~self.done[None, :, :] | np.any(self.status == NOT_RUN, axis=-1)
        end[not_run] = END_NOT_RUN
        best = np.where(not_run, np.nan, best)
        return best, end

    def summary(self) -> dict[str, Any]:
        """The summary.json content (see :mod:`qrfield.simulation.outputs`)."""

        def rounded(value: float | None) -> float | None:
            return None if value is None else round(value, 6)

        return {
            "combinations": [
                {"name": combo.name, "coverage": {k: rounded(self.coverage(k, c)) for k in self.solvers}}
                for c, combo in enumerate(self.combinations)
            ],
            "mean_coverage": {k: rounded(self.mean_coverage(k)) for k in self.solvers},
            "samples": self.poses_done,
            "seconds": round(self.seconds, 3),
            "partial": self.partial,
        }


def grid_positions(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(G, 3) positions in the order (z, y, x), x fastest."""
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    return np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1)


def default_solve(spec: SolverSpec, corners: np.ndarray, camera: CameraModel, side_mm: float) -> Any:
    """The project's solvers: qrfield.solvers.solve_batch with the spec's method and settings."""
    from qrfield.solvers import solve_batch

    return solve_batch(corners, camera, side_mm, settings=spec.settings, method=spec.method)


def degrade(corners: np.ndarray, config: StudyConfig, noise: np.ndarray | None) -> np.ndarray:
    """Corners as the solvers get them: exact, rounded to whole pixels, or plus ``noise`` (px)."""
    if config.degradation == "round":
        return np.round(corners)
    if config.degradation == "noise":
        assert noise is not None
        return corners + noise
    return corners


def combination_noise(
    config: StudyConfig, combination_index: int, shape: tuple[int, ...]
) -> np.ndarray | None:
    """Gaussian pixel noise of one combination's samples (G, A, 4, 2): seeded by (noise_seed, index)."""
    if config.degradation != "noise":
        return None
    rng = np.random.default_rng([config.noise_seed, combination_index])
    return rng.normal(0.0, config.noise_px, size=shape)


def judge(
    result: Any, truth_position: np.ndarray, truth_angles: np.ndarray, config: StudyConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(passed, position error mm, largest angle error deg) of N solved samples against the truth."""
    position = np.asarray(result.position_mm, dtype=float)
    angles = np.asarray(result.angles_deg, dtype=float)
    with np.errstate(invalid="ignore"):
        pos_err = np.linalg.norm(position - truth_position, axis=1)
        ang_err = np.max(np.abs(angle_difference(angles, truth_angles)), axis=1)
        c = config.criteria
        within = np.asarray(result.converged, bool) | (np.asarray(result.iterations) < c.n_max)
        passed = c.acceptance.meets(pos_err, ang_err) & within
    return passed & np.isfinite(pos_err) & np.isfinite(ang_err), pos_err, ang_err


def _should_stop(stop: threading.Event | Callable[[], bool] | None) -> bool:
    if stop is None:
        return False
    if isinstance(stop, threading.Event):
        return stop.is_set()
    return bool(stop())


def run_study(
    config: StudyConfig,
    progress: Callable[[Progress], None] | None = None,
    stop: threading.Event | Callable[[], bool] | None = None,
    solve_fn: SolveFn | None = None,
) -> StudyResult:
    """Run ``config``; safe to call from a background thread.

    Args:
        config: the study (see :mod:`qrfield.simulation.study`).
        progress: called after every chunk with a :class:`Progress` (from the running thread).
        stop: a threading.Event or a callable; when set/true the run stops after the current
            solver call, drops the unfinished chunk and returns with ``partial`` True.
        solve_fn: replaces the project's solvers (tests only); see :data:`SolveFn`.

    Returns the :class:`StudyResult` (partial or complete).
    """
    solve = solve_fn or default_solve
    t0 = time.perf_counter()
    camera = config.camera_model()
    combos = config.combination_list()
    specs = config.solver_specs()
    x, y, z = config.x_values(), config.y_values(), config.z_values()
    sweep = config.sweep_values()
    positions = grid_positions(x, y, z)
    S, C, G, A = len(specs), len(combos), positions.shape[0], sweep.size
    result = StudyResult(
        config=config,
        camera=camera,
        x_mm=x,
        y_mm=y,
        z_mm=z,
        sweep_deg=sweep,
        combinations=combos,
        solvers=[s.key for s in specs],
        truth_angles_deg=np.zeros((C, A, 3)),
        done=np.zeros((C, G), bool),
        in_view=np.zeros((C, G, A), bool),
        status=np.full((S, C, G, A), NOT_RUN, np.int8),
        position_mm=np.full((S, C, G, A, 3), np.nan),
        angles_deg=np.full((S, C, G, A, 3), np.nan),
        converged=np.zeros((S, C, G, A), bool),
        iterations=np.zeros((S, C, G, A), np.int32),
        position_error_mm=np.full((S, C, G, A), np.nan),
        angle_error_deg=np.full((S, C, G, A), np.nan),
    )
    per_chunk = max(1, CHUNK_POSES // A)
    total = C * G * A
    done_poses = 0
    stopped = False
    for ci, combo in enumerate(combos):
        rotation = rotation_matrix(combo.angles_deg(sweep))
        truth_angles = angles_from_rotation(rotation)
        result.truth_angles_deg[ci] = truth_angles
        noise = combination_noise(config, ci, (G, A, 4, 2))
        for g0 in range(0, G, per_chunk):
            g1 = min(G, g0 + per_chunk)
            if _should_stop(stop):
                stopped = True
                break
            chunk = _run_chunk(
                config,
                camera,
                specs,
                solve,
                rotation,
                truth_angles,
                positions[g0:g1],
                None if noise is None else noise[g0:g1],
                stop,
            )
            if chunk is None:
                stopped = True
                break
            in_view, per_solver = chunk
            result.in_view[ci, g0:g1] = in_view
            for si, arrays in enumerate(per_solver):
                for name, value in arrays.items():
                    getattr(result, name)[si, ci, g0:g1] = value
            result.done[ci, g0:g1] = True
            done_poses += (g1 - g0) * A
            result.seconds = time.perf_counter() - t0
            if progress is not None:
                progress(Progress(done_poses, total, combo.name, result.seconds))
        if stopped:
            break
    result.partial = stopped
    result.seconds = time.perf_counter() - t0
    return result


def _run_chunk(
    config: StudyConfig,
    camera: CameraModel,
    specs: list[SolverSpec],
    solve: SolveFn,
    rotation: np.ndarray,
    truth_angles: np.ndarray,
    positions: np.ndarray,
    noise: np.ndarray | None,
    stop: threading.Event | Callable[[], bool] | None,
) -> tuple[np.ndarray, list[dict[str, np.ndarray]]] | None:
    """Sweeps of a few grid points for every solver; None when a stop was requested midway."""
    g, a = positions.shape[0], rotation.shape[0]
    in_view, corners = poses_in_view(camera, config.side_mm, rotation, positions, config.max_view_angle_deg)
    observed = degrade(corners, config, noise)
    idx = np.flatnonzero(in_view.ravel())
    flat_corners = observed.reshape(-1, 4, 2)[idx]
    truth_pos = np.broadcast_to(positions[:, None, :], (g, a, 3)).reshape(-1, 3)[idx]
    truth_ang = np.broadcast_to(truth_angles[None, :, :], (g, a, 3)).reshape(-1, 3)[idx]
    out = []
    for spec in specs:
        if _should_stop(stop):
            return None
        arrays = {
            "status": np.full(g * a, OUT_OF_VIEW, np.int8),
            "position_mm": np.full((g * a, 3), np.nan),
            "angles_deg": np.full((g * a, 3), np.nan),
            "converged": np.zeros(g * a, bool),
            "iterations": np.zeros(g * a, np.int32),
            "position_error_mm": np.full(g * a, np.nan),
            "angle_error_deg": np.full(g * a, np.nan),
        }
        if idx.size:
            res = solve(spec, flat_corners, camera, config.side_mm)
            passed, pos_err, ang_err = judge(res, truth_pos, truth_ang, config)
            arrays["status"][idx] = np.where(passed, PASSED, FAILED)
            arrays["position_mm"][idx] = res.position_mm
            arrays["angles_deg"][idx] = res.angles_deg
            arrays["converged"][idx] = res.converged
            arrays["iterations"][idx] = res.iterations
            arrays["position_error_mm"][idx] = pos_err
            arrays["angle_error_deg"][idx] = ang_err
        out.append({k: v.reshape(g, a, *v.shape[1:]) for k, v in arrays.items()})
    return in_view, out
