"""The simulation study's machinery run for a list of poses: the prediction for an experiment's targets.

Where the study sweeps a grid, this takes N given poses (a session's ground truths, mm and
degrees, camera frame, R = Rx(alpha) Ry(beta) Rz(gamma)) and does to each what the study does to
each sample (:mod:`qrfield.simulation.runner`): the visibility rule (:func:`qrfield.visibility.view_of`
with the study's ``max_view_angle_deg``), the four vertices V1..V4 projected through the camera
model (distortion included), the study's corner degradation (:class:`NoiseModel`: exact, rounded
to whole pixels, or Gaussian noise of ``noise_px`` per coordinate from ``noise_seed``), the
solver's batch path (:func:`qrfield.solvers.solve_batch`) and the study's verdict
(:func:`qrfield.simulation.runner.judge_solved`: the criteria, and a solver that stopped before
n_max). With noise, each pose is drawn ``draws`` times and the prediction is the share that pass.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import rotation_matrix
from qrfield.sessions.criteria import AcceptanceCriteria, pose_errors
from qrfield.simulation.runner import degrade, judge_solved
from qrfield.simulation.study import StudyConfig
from qrfield.visibility import view_of

#: Draws per pose with Gaussian noise (one draw for exact or rounded corners, which are fixed).
DEFAULT_DRAWS = 200


@dataclass(frozen=True)
class NoiseModel:
    """The study's corner degradation: ``degradation`` none | round | noise, ``noise_px`` (sigma per
    coordinate, px), ``noise_seed``, and its visibility limit ``max_view_angle_deg``."""

    degradation: str = "none"
    noise_px: float = 0.0
    noise_seed: int = 0
    max_view_angle_deg: float = 85.0

    @classmethod
    def of_study(cls, config: StudyConfig) -> NoiseModel:
        return cls(config.degradation, config.noise_px, config.noise_seed, config.max_view_angle_deg)

    def describe(self) -> str:
        """E.g. "Gaussian noise of 0.5 px per corner coordinate (seed 0)"."""
        if self.degradation == "round":
            return "corners rounded to whole pixels"
        if self.degradation == "noise":
            return f"Gaussian noise of {self.noise_px:g} px per corner coordinate (seed {self.noise_seed})"
        return "exact corners (no noise)"


@dataclass(frozen=True)
class Prediction:
    """The simulation of N poses, D draws each (D = 1 without noise).

    in_view: (N,) bool; passed, passed_converged: (N, D) bool (False out of view); position_error_mm:
    (N, D) Euclidean; angle_error_deg: (N, D, 3) signed, wrapped (measured minus truth); NaN where
    no pose (out of view or unsolved). Units mm and degrees.
    """

    noise: NoiseModel
    method: str
    draws: int
    in_view: np.ndarray
    passed: np.ndarray
    passed_converged: np.ndarray
    position_error_mm: np.ndarray
    angle_error_deg: np.ndarray

    @property
    def pass_share(self) -> np.ndarray:
        """(N,) share of the draws that pass (NaN out of view)."""
        share = self.passed.mean(axis=1)
        return np.where(self.in_view, share, np.nan)

    def mean_abs_errors(self) -> tuple[np.ndarray, np.ndarray]:
        """((N,) mean position error mm, (N, 3) mean |angle error| deg) over the draws with a pose."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a pose with no solved draw: NaN
            return np.nanmean(self.position_error_mm, axis=1), np.nanmean(
                np.abs(self.angle_error_deg), axis=1
            )


def predict_poses(
    position_mm: Any,
    angles_deg: Any,
    camera: CameraModel,
    side_mm: float,
    method: str,
    settings: Any,
    criteria: AcceptanceCriteria,
    noise: NoiseModel,
    *,
    draws: int | None = None,
    n_max: int | None = None,
) -> Prediction:
    """Simulate poses (N, 3) mm and (N, 3) deg as the study would (see the module doc).

    ``settings``: the solver's settings (NumericalSettings or IppeSettings); ``n_max``: the study's
    iteration cap for the verdict (default: the settings' n_max, else 30). ``draws``: noise draws per
    pose (default :data:`DEFAULT_DRAWS`; always 1 without noise).
    """
    from qrfield.solvers import solve_batch

    position = np.asarray(position_mm, dtype=float).reshape(-1, 3)
    angles = np.asarray(angles_deg, dtype=float).reshape(-1, 3)
    if position.shape != angles.shape:
        raise ValueError(
            f"positions (N, 3) mm and angles (N, 3) deg must match, got {position.shape}, {angles.shape}"
        )
    n = position.shape[0]
    d = max(1, int(draws or DEFAULT_DRAWS)) if noise.degradation == "noise" else 1
    view = view_of(camera, side_mm, rotation_matrix(angles), position, noise.max_view_angle_deg)
    corners = np.broadcast_to(view.corners_px[:, None], (n, d, 4, 2))
    extra = None
    if noise.degradation == "noise":
        extra = np.random.default_rng(noise.noise_seed).normal(0.0, noise.noise_px, size=(n, d, 4, 2))
    observed = degrade(corners, noise, extra)
    passed = np.zeros((n, d), bool)
    passed_converged = np.zeros((n, d), bool)
    pos_err = np.full((n, d), np.nan)
    ang_err = np.full((n, d, 3), np.nan)
    mask = np.broadcast_to(view.in_view[:, None], (n, d))
    if np.any(mask):
        truth_pos = np.broadcast_to(position[:, None], (n, d, 3))[mask]
        truth_ang = np.broadcast_to(angles[:, None], (n, d, 3))[mask]
        result = solve_batch(observed[mask], camera, side_mm, method, settings)
        cap = n_max if n_max is not None else int(getattr(settings, "n_max", 30))
        ok, _, _ = judge_solved(result, truth_pos, truth_ang, criteria, cap)
        passed[mask] = ok
        passed_converged[mask] = ok & np.asarray(result.converged, bool)
        errors_pos, errors_ang = pose_errors(result.position_mm, result.angles_deg, truth_pos, truth_ang)
        pos_err[mask] = errors_pos
        ang_err[mask] = errors_ang
    return Prediction(noise, method, d, view.in_view.copy(), passed, passed_converged, pos_err, ang_err)
