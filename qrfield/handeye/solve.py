"""The hand-eye solve: the camera's place on the gripper (or in the cell) from robot and code poses.

docs/conventions.md, "Hand-eye"; docs/handeye.md. Each pair i holds the tool pose the robot reports,
T_base_tool_i, and the code's pose the camera measured there, C_i = T_camera_marker_i, with its
covariance. Both set-ups are one model with two unknown rigid transforms X and Y:

    C_i = X^-1 M_i Y

- eye-in-hand: X = T_tool_camera ("camera_to_tool"), M_i = T_base_tool_i^-1, Y = T_base_marker
  (the fixed code in the base frame);
- eye-to-hand: X = T_base_camera ("camera_to_base"), M_i = T_base_tool_i, Y = T_tool_marker (the
  code in the gripper).

1. Closed form (Park & Martin, "Robot sensor calibration: solving AX = XB on the Euclidean group",
   IEEE Trans. Robotics and Automation 10(5), 1994): for every i < j, A_ij = M_j M_i^-1 and
   B_ij = C_j C_i^-1 satisfy A X = X B; the rotation vectors obey alpha_ij = R_X beta_ij, so R_X is
   the orthogonal Procrustes fit of the beta onto the alpha, and t_X the least-squares solution of
   (R_A - I) t_X = R_X t_B - t_A. Y follows as the mean of M_i^-1 X C_i. (OpenCV 4's
   calibrateHandEye(method=CALIB_HAND_EYE_PARK) is this method on the same motions: tests compare.)
2. Refinement: Levenberg-Marquardt over X and Y (12 parameters) of the residuals of every pair's
   predicted code pose against the measured one, (x, y, z) in mm and (alpha, beta, gamma) in
   degrees, whitened by that pose's covariance (PoseResult.pose_cov), plus the robot's own pose
   uncertainty when given (propagated to the same residuals).
3. Uncertainty: the covariance of X from the refinement's Jacobian, (J^T J)^-1 of the whitened
   residuals, scaled up by chi2 / dof when the residuals are larger than the pose covariances
   explain (never down). Without pose covariances every pair weighs the same (1 mm, 1 deg) and the
   covariance is scaled by chi2 / dof, up or down: then the residuals alone say how good the poses are.

Transforms are (4, 4) row-major, mm; a transform's covariance is of (dt mm, dtheta deg) with
``rigid.perturbed``'s convention (R' = exp(dtheta) R, t' = t + dt: in the frame it maps into, the
tool or base frame for X).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from qrfield.geometry import angle_difference, angles_from_rotation
from qrfield.handeye.diversity import MIN_PAIRS, MIN_SPREAD_DEG, MIN_TURN_DEG, Spread, check_diversity
from qrfield.handeye.rigid import (
    check_transform,
    invert,
    make_transform,
    perturbed,
    rotation_angle_deg,
    rotation_log,
    transform_from_pose,
)
from qrfield.handeye.setups import EYE_IN_HAND, TARGET_FRAME, HandEyeError, check_setup

#: The method recorded in handeye.json.
METHOD = "park-martin + weighted least squares"
#: The covariance assumed for a pair without one: 1 mm and 1 deg, independent (unit weights).
UNIT_COV = np.eye(6)
#: Added to every pair's covariance diagonal (mm^2, deg^2): (1e-6 mm)^2, (1e-6 deg)^2.
COV_FLOOR = 1e-12
#: The refinement's limits: iterations, and the relative change of the cost that ends it.
MAX_ITERATIONS = 100
COST_TOLERANCE = 1e-12
_DEG = 180.0 / math.pi
#: Central-difference step of the numerical Jacobian, in mm and rad.
_STEP = 1e-6


@dataclass(frozen=True)
class Pair:
    """One robot pose and the code's pose the camera measured there.

    Attributes:
        tool_in_base: (4, 4) T_base_tool, the tool frame in the robot's base frame, mm.
        code_in_camera: (4, 4) T_camera_marker, the code's pose (docs/conventions.md), mm.
        code_cov: (6, 6) covariance of the code pose's (x, y, z, alpha, beta, gamma) in mm and
            degrees (``PoseResult.pose_cov``), or None when unknown.
        label: where the pair came from (an image, a serial command), for messages.
    """

    tool_in_base: np.ndarray
    code_in_camera: np.ndarray
    code_cov: np.ndarray | None = None
    label: str = ""

    def __post_init__(self) -> None:
        where = f"pair {self.label}" if self.label else "pair"
        object.__setattr__(self, "tool_in_base", check_transform(self.tool_in_base, f"{where} tool pose"))
        object.__setattr__(self, "code_in_camera", check_transform(self.code_in_camera, f"{where} code pose"))
        if self.code_cov is not None:
            cov = np.asarray(self.code_cov, dtype=float)
            if cov.shape != (6, 6):
                raise ValueError(f"{where}: code_cov must have shape (6, 6) (mm, deg), got {cov.shape}")
            if not np.all(np.isfinite(cov)):
                cov = None  # unknown (the solver computed none): the pair counts with unit weights
            object.__setattr__(self, "code_cov", cov)

    @classmethod
    def from_pose(cls, tool_in_base: np.ndarray, pose: Any, label: str = "") -> Pair:
        """A pair from a tool pose and a converged ``PoseResult`` (its position, angles, pose_cov)."""
        if not getattr(pose, "converged", True) or not np.all(np.isfinite(pose.position_mm)):
            where = f"pair {label}" if label else "a pair"
            raise HandEyeError(f"{where}: the code's pose did not converge")
        return cls(
            tool_in_base,
            transform_from_pose(pose.position_mm, pose.angles_deg),
            getattr(pose, "pose_cov", None),
            label,
        )


@dataclass(frozen=True)
class HandEyeResult:
    """A solved hand-eye calibration.

    Attributes:
        setup: "eye-in-hand" or "eye-to-hand".
        transform: (4, 4) X: camera_to_tool (eye-in-hand) or camera_to_base (eye-to-hand), mm.
        other: (4, 4) Y: the code in the base frame (eye-in-hand) or in the tool frame (eye-to-hand).
        covariance: (6, 6) of X's (dt mm, dtheta deg) in the tool/base frame (module docstring).
        other_covariance: (6, 6) the same for Y.
        residuals_mm: (N,) per pair, the distance between the code's measured position and the one
            the solution predicts, in the camera frame, mm.
        residuals_deg: (N,) per pair, the angle between the measured and predicted orientations, deg.
        chi2: sum of the squared whitened residuals; dof: 6 N - 12.
        scale: the factor applied to (J^T J)^-1 (>= 1 with pose covariances; chi2/dof without).
        weighted: every pair had its pose covariance (else unit weights for all).
        closed_form: (4, 4) the Park-Martin estimate of X (before refinement).
        iterations: refinement iterations; spread: the poses' rotation spread; labels: the pairs'.
    """

    setup: str
    transform: np.ndarray
    other: np.ndarray
    covariance: np.ndarray
    other_covariance: np.ndarray
    residuals_mm: np.ndarray
    residuals_deg: np.ndarray
    chi2: float
    dof: int
    scale: float
    weighted: bool
    closed_form: np.ndarray
    iterations: int
    spread: Spread
    labels: tuple[str, ...] = field(default_factory=tuple)
    method: str = METHOD

    @property
    def n_pairs(self) -> int:
        return len(self.residuals_mm)

    @property
    def residual_mm(self) -> float:
        """RMS over the pairs of :attr:`residuals_mm`."""
        return float(np.sqrt(np.mean(self.residuals_mm**2)))

    @property
    def residual_deg(self) -> float:
        """RMS over the pairs of :attr:`residuals_deg`."""
        return float(np.sqrt(np.mean(self.residuals_deg**2)))

    @property
    def translation_std_mm(self) -> np.ndarray:
        """(3,) standard uncertainty of X's translation along the tool/base frame's x, y, z, mm."""
        return np.sqrt(np.diag(self.covariance)[:3])

    @property
    def rotation_std_deg(self) -> np.ndarray:
        """(3,) standard uncertainty of X's rotation about the tool/base frame's x, y, z, deg."""
        return np.sqrt(np.diag(self.covariance)[3:])

    @property
    def target_frame(self) -> str:
        """The frame X maps camera coordinates into: "tool" or "base"."""
        return TARGET_FRAME[self.setup]


def model_terms(pairs_tool: np.ndarray, setup: str) -> np.ndarray:
    """(N, 4, 4) M_i of the model C_i = X^-1 M_i Y: T_base_tool^-1 (eye-in-hand) or T_base_tool."""
    return invert(pairs_tool) if check_setup(setup) == EYE_IN_HAND else np.array(pairs_tool, dtype=float)


def predict(x: np.ndarray, m: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(N, 4, 4) the code poses the model predicts, X^-1 M_i Y."""
    return invert(x) @ m @ y


def park_martin(m: np.ndarray, c: np.ndarray) -> np.ndarray:
    """X (4, 4) of A X = X B in closed form, from M (N, 4, 4) and C (N, 4, 4) (module docstring)."""
    i, j = np.triu_indices(len(m), 1)
    a = m[j] @ invert(m[i])
    b = c[j] @ invert(c[i])
    alpha = rotation_log(a[:, :3, :3])
    beta = rotation_log(b[:, :3, :3])
    # R = argmin sum |R beta - alpha|^2: the orthogonal Procrustes solution (Kabsch).
    u, _, vt = np.linalg.svd(alpha.T @ beta)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    lhs = (a[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (np.einsum("ij,kj->ki", r, b[:, :3, 3]) - a[:, :3, 3]).reshape(-1)
    t = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return make_transform(r, t)


def _mean_transform(transforms: np.ndarray) -> np.ndarray:
    """The chordal mean of rigid transforms (N, 4, 4): the rotation nearest the mean matrix."""
    u, _, vt = np.linalg.svd(transforms[:, :3, :3].mean(axis=0))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    return make_transform(u @ d @ vt, transforms[:, :3, 3].mean(axis=0))


def other_from(x: np.ndarray, m: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Y (4, 4) given X: the mean of M_i^-1 X C_i."""
    return _mean_transform(invert(m) @ x @ c)


def pose_residuals(predicted: np.ndarray, measured: np.ndarray, measured_angles: np.ndarray) -> np.ndarray:
    """(..., N, 6) predicted (..., N, 4, 4) minus measured (N, 4, 4) poses: (x, y, z) in mm and
    (alpha, beta, gamma) in degrees (wrapped); ``measured_angles`` (N, 3) are the measured ones."""
    return np.concatenate(
        [
            predicted[..., :3, 3] - measured[:, :3, 3],
            angle_difference(angles_from_rotation(predicted[..., :3, :3]), measured_angles),
        ],
        axis=-1,
    )


def _tool_cov(
    m_tool: np.ndarray, setup: str, x: np.ndarray, y: np.ndarray, tool_std_mm: float, tool_std_deg: float
) -> np.ndarray:
    """(N, 6, 6) the robot's pose uncertainty (isotropic, in the base frame) carried to the residuals."""
    count = len(m_tool)
    sigma = np.diag([tool_std_mm**2] * 3 + [math.radians(tool_std_deg) ** 2] * 3)
    base = predict(x, model_terms(m_tool, setup), y)
    base_angles = angles_from_rotation(base[:, :3, :3])
    jac = np.empty((count, 6, 6))
    for k in range(6):
        delta = np.zeros(6)
        delta[k] = _STEP
        moved = predict(x, model_terms(perturbed(m_tool, delta), setup), y)
        back = predict(x, model_terms(perturbed(m_tool, -delta), setup), y)
        jac[:, :, k] = (
            pose_residuals(moved, base, base_angles) - pose_residuals(back, base, base_angles)
        ) / (2 * _STEP)
    return np.einsum("nij,jk,nlk->nil", jac, sigma, jac)


def _whiteners(cov: np.ndarray) -> np.ndarray:
    """(N, 6, 6) L_i^-1 with cov_i = L_i L_i^T; HandEyeError for a covariance that is not positive."""
    try:
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise HandEyeError(
            "a pair's pose covariance is not positive definite (a pose without usable uncertainty)",
            "a pose has no usable covariance",
        ) from None
    return np.linalg.inv(chol)


class _Problem:
    """The weighted least-squares problem of the refinement (parameters: dX, dY, 12 values)."""

    def __init__(self, m: np.ndarray, c: np.ndarray, whiteners: np.ndarray) -> None:
        self.m, self.c, self.w = m, c, whiteners
        self.angles = angles_from_rotation(c[:, :3, :3])

    def residuals(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whitened residuals (..., 6 N) of X (..., 4, 4) and Y (..., 4, 4)."""
        predicted = invert(x)[..., None, :, :] @ self.m @ y[..., None, :, :]
        raw = pose_residuals(predicted, self.c, self.angles)
        white = np.einsum("nij,...nj->...ni", self.w, raw)
        return white.reshape(*white.shape[:-2], -1)

    def jacobian(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(6 N, 12) by central differences, all 24 evaluations in one batch."""
        steps = np.concatenate([np.eye(12), -np.eye(12)]) * _STEP
        r = self.residuals(perturbed(x, steps[:, :6]), perturbed(y, steps[:, 6:]))
        return ((r[:12] - r[12:]) / (2 * _STEP)).T


def _refine(problem: _Problem, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Levenberg-Marquardt from (X, Y); returns the refined pair and the iterations made."""
    r = problem.residuals(x, y)
    cost = float(r @ r)
    damping = 1e-3
    iterations = 0
    for iterations in range(1, MAX_ITERATIONS + 1):  # noqa: B007 - the count is returned
        jac = problem.jacobian(x, y)
        jtj, jtr = jac.T @ jac, jac.T @ r
        improved = False
        while damping < 1e12:
            step = np.linalg.solve(jtj + damping * np.diag(np.diag(jtj) + 1e-12), -jtr)
            x_new, y_new = perturbed(x, step[:6]), perturbed(y, step[6:])
            r_new = problem.residuals(x_new, y_new)
            cost_new = float(r_new @ r_new)
            if cost_new <= cost:
                improved = True
                break
            damping *= 10.0
        if not improved:
            break
        change = cost - cost_new
        x, y, r = x_new, y_new, r_new
        cost, damping = cost_new, max(damping / 10.0, 1e-9)
        if change <= COST_TOLERANCE * max(cost, 1.0):
            break
    return x, y, iterations


def solve_handeye(
    pairs: Sequence[Pair],
    setup: str,
    *,
    tool_std_mm: float = 0.0,
    tool_std_deg: float = 0.0,
    min_pairs: int = MIN_PAIRS,
    min_turn_deg: float = MIN_TURN_DEG,
    min_spread_deg: float = MIN_SPREAD_DEG,
) -> HandEyeResult:
    """Solve the hand-eye transform of ``setup`` from ``pairs`` (module docstring).

    Args:
        pairs: at least ``min_pairs`` :class:`Pair`.
        setup: "eye-in-hand" (X = camera_to_tool) or "eye-to-hand" (X = camera_to_base).
        tool_std_mm, tool_std_deg: the robot's own pose uncertainty (1 sigma, isotropic, position
            and rotation of T_base_tool); 0 = exact tool poses.
        min_pairs, min_turn_deg, min_spread_deg: the checks of :mod:`qrfield.handeye.diversity`.

    Raises HandEyeError (a ValueError) for too few pairs or poses that do not turn about two axes
    (the message says what poses to add), or a problem the refinement cannot solve.
    """
    check_setup(setup)
    for name, value in (("tool_std_mm", tool_std_mm), ("tool_std_deg", tool_std_deg)):
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    pairs = list(pairs)
    if not all(isinstance(p, Pair) for p in pairs):
        raise TypeError("pairs must be qrfield.handeye.Pair objects")
    tool = np.array([p.tool_in_base for p in pairs]).reshape(-1, 4, 4)
    spread = check_diversity(
        tool, setup, min_pairs=min_pairs, min_turn_deg=min_turn_deg, min_spread_deg=min_spread_deg
    )
    c = np.array([p.code_in_camera for p in pairs])
    m = model_terms(tool, setup)
    weighted = all(p.code_cov is not None for p in pairs)
    cov = np.array([p.code_cov for p in pairs]) if weighted else np.repeat(UNIT_COV[None], len(pairs), 0)
    # Symmetric, and a floor far below any real pose's uncertainty so that a component the solver
    # reported as exactly 0 does not make the whitening singular.
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2)) + np.eye(6) * COV_FLOOR
    x0 = park_martin(m, c)
    x, y = x0, other_from(x0, m, c)
    iterations = 0
    robot = tool_std_mm > 0 or tool_std_deg > 0
    for _ in range(2 if robot else 1):  # with robot noise: weights at the start, then at the solution
        total = cov + (_tool_cov(tool, setup, x, y, tool_std_mm, tool_std_deg) if robot else 0.0)
        problem = _Problem(m, c, _whiteners(total))
        x, y, done = _refine(problem, x, y)
        iterations += done
    r = problem.residuals(x, y)
    chi2 = float(r @ r)
    dof = 6 * len(pairs) - 12
    jac = problem.jacobian(x, y)
    try:
        inverse = np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        raise HandEyeError(
            "the pairs do not determine the transform (singular normal equations)",
            "the pairs do not fix the transform",
        ) from None
    ratio = chi2 / dof if dof > 0 else math.nan
    if weighted:
        scale = max(1.0, ratio) if math.isfinite(ratio) else 1.0
    else:
        scale = ratio if math.isfinite(ratio) else math.nan
    units = np.diag([1.0, 1.0, 1.0, _DEG, _DEG, _DEG])
    full = scale * inverse
    predicted = predict(x, m, y)
    return HandEyeResult(
        setup=setup,
        transform=x,
        other=y,
        covariance=units @ full[:6, :6] @ units,
        other_covariance=units @ full[6:, 6:] @ units,
        residuals_mm=np.linalg.norm(predicted[:, :3, 3] - c[:, :3, 3], axis=1),
        residuals_deg=rotation_angle_deg(predicted[:, :3, :3] @ np.swapaxes(c[:, :3, :3], 1, 2)),
        chi2=chi2,
        dof=dof,
        scale=float(scale),
        weighted=weighted,
        closed_form=x0,
        iterations=iterations,
        spread=spread,
        labels=tuple(p.label for p in pairs),
    )
