"""Run a simulation study: every grid point x combination x swept angle, projected, degraded, solved.

For each combination the tilt magnitude t is swept 0, step, ... up to the limit; the card's angles
are t times the combination's multipliers and its centre is at each grid point (x, y, z) of the
camera frame. The four vertices are projected through the camera model (exact pixels, the truth),
optionally rounded to whole pixels or given Gaussian noise, and each solver finds the pose from
them (its batch path: the numerical model and IPPE, both vectorised in numpy).

Two readings of "solved" (both reported: :meth:`StudyResult.coverage`):

- **within criteria** (status PASSED): the pose meets the acceptance criteria (|error| <= angle_deg
  on each of alpha, beta, gamma, wrapped; Euclidean position error < position_mm) and the solver
  stopped before n_max: it met its tolerance, or it *settled* earlier, i.e. its Gauss-Newton step
  fell below STALL_MM at a least-squares optimum whose largest side/diagonal error is still above
  the tolerance. A run that reaches n_max without meeting its tolerance fails. This is our reading:
  with rounded or noisy corners no four depths fit all six lengths to 0.01 mm, so the thesis'
  model settles above its tolerance, and the pose criteria decide;
- **converged and within criteria**: the solver's own converged flag holds as well (the
  numerical model met its tolerance; IPPE found a pose in front of the camera facing it, so for
  IPPE both readings are the same).

Out-of-view poses (see :mod:`qrfield.simulation.view`) are neither passes nor failures.

Work is cut into tasks of whole sweeps (:func:`plan_tasks`: some grid points of one or more
combinations, all angles, all solvers), computed in this process or spread over every core
(:mod:`qrfield.simulation.parallel`), so a stop request (Ctrl-C, the app's Stop button) loses at
most the tasks in progress and every kept grid point has complete sweeps.
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import angles_from_rotation, rotation_matrix
from qrfield.simulation.combinations import Combination
from qrfield.simulation.study import SolverSpec, StudyConfig
from qrfield.simulation.view import poses_in_view

#: Poses per task at most (a task is whole sweeps of some grid points, of one or more combinations):
#: large enough that each solver call is vectorised over many poses, small enough to bound the
#: work lost on a stop. A parallel run cuts smaller tasks when that gives each worker at least
#: TASKS_PER_WORKER of them (balance).
CHUNK_POSES = 8192
TASKS_PER_WORKER = 3

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

    def coverage(
        self, solver: str, combination: int | None = None, *, converged_only: bool = False
    ) -> float | None:
        """Share of in-view samples that pass, over one combination (or all pooled); None if none ran.

        Two readings (see the module docstring): by default "within criteria" (the pose meets the
        criteria and the solver stopped within n_max: status PASSED); with ``converged_only``,
        "converged and within criteria" (the solver's own converged flag holds as well). The
        denominator is the same: the in-view samples judged.
        """
        s = self.solvers.index(solver)
        index = (s,) if combination is None else (s, combination)
        status = self.status[index]
        ok = status == PASSED
        if converged_only:
            ok &= self.converged[index]
        passed = int(np.count_nonzero(ok))
        judged = int(np.count_nonzero(status == PASSED)) + int(np.count_nonzero(status == FAILED))
        return passed / judged if judged else None

    def mean_coverage(self, solver: str, *, converged_only: bool = False) -> float | None:
        """Mean of the per-combination coverages (the seed's 'average'); None if none ran."""
        values = [
            self.coverage(solver, c, converged_only=converged_only) for c in range(len(self.combinations))
        ]
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
                {
                    "name": combo.name,
                    "coverage": {k: rounded(self.coverage(k, c)) for k in self.solvers},
                    "coverage_converged": {
                        k: rounded(self.coverage(k, c, converged_only=True)) for k in self.solvers
                    },
                }
                for c, combo in enumerate(self.combinations)
            ],
            "mean_coverage": {k: rounded(self.mean_coverage(k)) for k in self.solvers},
            "mean_coverage_converged": {
                k: rounded(self.mean_coverage(k, converged_only=True)) for k in self.solvers
            },
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


def judge_samples(
    result: Any, truth_position: np.ndarray, truth_angles: np.ndarray, config: StudyConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(passed, position error mm, largest angle error deg) of N solved samples against the truth:
    the study's criteria, by :func:`judge_solved`."""
    c = config.criteria
    return judge_solved(result, truth_position, truth_angles, c.acceptance, c.n_max)


def judge_solved(
    result: Any, truth_position: np.ndarray, truth_angles: np.ndarray, acceptance: Any, n_max: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(passed, position error mm, largest angle error deg) of N solved samples (``result``: arrays
    position_mm (N, 3), angles_deg (N, 3), converged (N,), iterations (N,)) against the truth (N, 3)
    mm and degrees: the acceptance criteria (:meth:`AcceptanceCriteria.judge`, the rule's one home)
    and, the study's own condition, a solver that stopped before ``n_max`` (see the module doc)."""
    passed, pos_err, ang_err = acceptance.judge(
        result.position_mm, result.angles_deg, truth_position, truth_angles
    )
    within = np.asarray(result.converged, bool) | (np.asarray(result.iterations) < n_max)
    return passed & within, pos_err, ang_err


def _should_stop(stop: threading.Event | Callable[[], bool] | None) -> bool:
    if stop is None:
        return False
    if isinstance(stop, threading.Event):
        return stop.is_set()
    return bool(stop())


# ---------------------------------------------------------------------- tasks
#: A block is whole sweeps of grid points g0..g1-1 of one combination: (combination, g0, g1).
Block = tuple[int, int, int]


def plan_tasks(combinations: int, grid_points: int, angles: int, chunk_poses: int) -> list[list[Block]]:
    """Work split into tasks of at most ``chunk_poses`` poses (at least one grid point's sweep).

    Each combination's grid points are cut into blocks of ``chunk_poses // angles`` points;
    consecutive blocks (of one or more combinations) are packed into one task while the task
    stays within ``chunk_poses``, so that a small study costs one solver call per solver.
    """
    per_block = max(1, chunk_poses // angles)
    tasks: list[list[Block]] = []
    current: list[Block] = []
    size = 0
    for c in range(combinations):
        for g0 in range(0, grid_points, per_block):
            g1 = min(grid_points, g0 + per_block)
            poses = (g1 - g0) * angles
            if current and size + poses > chunk_poses:
                tasks.append(current)
                current, size = [], 0
            current.append((c, g0, g1))
            size += poses
    if current:
        tasks.append(current)
    return tasks


@dataclass(frozen=True)
class Derived:
    """What every task of one study needs, computed once per process (see :func:`derived`)."""

    camera: CameraModel
    specs: list[SolverSpec]
    combinations: list[Combination]
    sweep_deg: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray  # (C, A, 3, 3)
    truth_angles_deg: np.ndarray  # (C, A, 3)


@functools.lru_cache(maxsize=4)
def derived(config: StudyConfig) -> Derived:
    """The camera, solvers, grid, rotations and true angles of a study (cached per process)."""
    combos = config.combination_list()
    sweep = config.sweep_values()
    rotations = (
        np.stack([rotation_matrix(c.angles_deg(sweep)) for c in combos]) if combos else np.zeros((0, 0, 3, 3))
    )
    return Derived(
        camera=config.camera_model(),
        specs=config.solver_specs(),
        combinations=combos,
        sweep_deg=sweep,
        positions=grid_positions(config.x_values(), config.y_values(), config.z_values()),
        rotations=rotations,
        truth_angles_deg=angles_from_rotation(rotations),
    )


#: The per-solver arrays a task returns, with their fill value where a sample is out of view.
SAMPLE_ARRAYS: dict[str, tuple[Any, Any, tuple[int, ...]]] = {
    "status": (np.int8, OUT_OF_VIEW, ()),
    "position_mm": (float, np.nan, (3,)),
    "angles_deg": (float, np.nan, (3,)),
    "converged": (bool, False, ()),
    "iterations": (np.int32, 0, ()),
    "position_error_mm": (float, np.nan, ()),
    "angle_error_deg": (float, np.nan, ()),
}

#: What one task returns: per block, (block, in_view (g, A), per solver {array name: (g, A, ...)}).
TaskResult = list[tuple[Block, np.ndarray, list[dict[str, np.ndarray]]]]


def compute_task(
    config: StudyConfig,
    task: list[Block],
    solve_fn: SolveFn | None = None,
    stop: threading.Event | Callable[[], bool] | None = None,
) -> TaskResult | None:
    """Project, degrade, solve (each solver once over all blocks) and judge one task's sweeps.

    Returns None when ``stop`` was set midway (between solver calls); safe in a worker process.
    """
    solve = solve_fn or default_solve
    d = derived(config)
    a = d.sweep_deg.size
    views, corners, truth_pos, truth_ang = [], [], [], []
    noise_of: dict[int, np.ndarray | None] = {}
    for ci, g0, g1 in task:
        if ci not in noise_of:
            noise_of[ci] = combination_noise(config, ci, (d.positions.shape[0], a, 4, 2))
        noise = noise_of[ci]
        positions = d.positions[g0:g1]
        in_view, exact = poses_in_view(
            d.camera, config.side_mm, d.rotations[ci], positions, config.max_view_angle_deg
        )
        observed = degrade(exact, config, None if noise is None else noise[g0:g1])
        mask = in_view.ravel()
        views.append(in_view)
        corners.append(observed.reshape(-1, 4, 2)[mask])
        truth_pos.append(np.broadcast_to(positions[:, None, :], (g1 - g0, a, 3)).reshape(-1, 3)[mask])
        truth_ang.append(np.broadcast_to(d.truth_angles_deg[ci][None], (g1 - g0, a, 3)).reshape(-1, 3)[mask])
    flat_corners = np.concatenate(corners)
    flat_pos, flat_ang = np.concatenate(truth_pos), np.concatenate(truth_ang)
    per_solver: list[dict[str, np.ndarray]] = []
    for spec in d.specs:
        if _should_stop(stop):
            return None
        values = {
            name: np.full((flat_corners.shape[0], *shape), fill, dtype)
            for name, (dtype, fill, shape) in SAMPLE_ARRAYS.items()
        }
        if flat_corners.shape[0]:
            res = solve(spec, flat_corners, d.camera, config.side_mm)
            passed, pos_err, ang_err = judge_samples(res, flat_pos, flat_ang, config)
            values["status"][:] = np.where(passed, PASSED, FAILED)
            values["position_mm"][:] = res.position_mm
            values["angles_deg"][:] = res.angles_deg
            values["converged"][:] = res.converged
            values["iterations"][:] = res.iterations
            values["position_error_mm"][:] = pos_err
            values["angle_error_deg"][:] = ang_err
        per_solver.append(values)
    out: TaskResult = []
    start = 0
    for (ci, g0, g1), in_view in zip(task, views, strict=True):
        mask = in_view.ravel()
        count = int(mask.sum())
        arrays = []
        for values in per_solver:
            block = {}
            for name, (dtype, fill, shape) in SAMPLE_ARRAYS.items():
                full = np.full((mask.size, *shape), fill, dtype)
                full[mask] = values[name][start : start + count]
                block[name] = full.reshape(g1 - g0, a, *shape)
            arrays.append(block)
        start += count
        out.append(((ci, g0, g1), in_view, arrays))
    return out


# ---------------------------------------------------------------------- the run
def run_study(
    config: StudyConfig,
    progress: Callable[[Progress], None] | None = None,
    stop: threading.Event | Callable[[], bool] | None = None,
    solve_fn: SolveFn | None = None,
    workers: int | None = None,
    chunk_poses: int | None = None,
) -> StudyResult:
    """Run ``config``; safe to call from a background thread.

    Args:
        config: the study (see :mod:`qrfield.simulation.study`).
        progress: called after every task with a :class:`Progress` (from the calling thread).
        stop: a threading.Event or a callable; when set/true the run stops after the tasks in
            progress, drops what is unfinished and returns with ``partial`` True.
        solve_fn: replaces the project's solvers (tests and the benchmark's old path; see
            :data:`SolveFn`); it runs in this process, so the run is then serial.
        workers: processes to spread the tasks over; None picks them
            (:func:`qrfield.simulation.parallel.auto_workers`: every core for a large study, this
            process alone for a small one); 1 runs everything in this process.
        chunk_poses: poses per task at most (default :data:`CHUNK_POSES`).

    Returns the :class:`StudyResult` (partial or complete).
    """
    from qrfield.simulation import parallel

    t0 = time.perf_counter()
    d = derived(config)
    S, C, G, A = len(d.specs), len(d.combinations), d.positions.shape[0], d.sweep_deg.size
    result = StudyResult(
        config=config,
        camera=d.camera,
        x_mm=config.x_values(),
        y_mm=config.y_values(),
        z_mm=config.z_values(),
        sweep_deg=d.sweep_deg,
        combinations=d.combinations,
        solvers=[s.key for s in d.specs],
        truth_angles_deg=d.truth_angles_deg.copy(),
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
    total = C * G * A
    if solve_fn is not None:
        workers = 1
    elif workers is None:
        workers = parallel.auto_workers(total)
    if chunk_poses is None:
        chunk_poses = CHUNK_POSES
        if workers > 1:
            chunk_poses = max(1, min(chunk_poses, -(-total // (TASKS_PER_WORKER * workers))))
    tasks = plan_tasks(C, G, A, chunk_poses)
    done_poses = 0

    def merge(task_result: TaskResult) -> None:
        nonlocal done_poses
        for (ci, g0, g1), in_view, arrays in task_result:
            result.in_view[ci, g0:g1] = in_view
            for si, block in enumerate(arrays):
                for name, value in block.items():
                    getattr(result, name)[si, ci, g0:g1] = value
            result.done[ci, g0:g1] = True
            done_poses += (g1 - g0) * A
        result.seconds = time.perf_counter() - t0
        if progress is not None:
            last = task_result[-1][0][0]
            progress(Progress(done_poses, total, d.combinations[last].name, result.seconds))

    if workers > 1 and len(tasks) > 1:
        stopped = parallel.run_tasks(config, tasks, workers, merge, lambda: _should_stop(stop))
    else:
        stopped = False
        for task in tasks:
            if _should_stop(stop):
                stopped = True
                break
            task_result = compute_task(config, task, solve_fn, stop)
            if task_result is None:
                stopped = True
                break
            merge(task_result)
    result.partial = stopped
    result.seconds = time.perf_counter() - t0
    return result
