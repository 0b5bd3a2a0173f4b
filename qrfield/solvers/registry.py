"""The pose methods' registry: what each method is, how it solves, what its settings are.

The names and their order live in :mod:`qrfield.methods` (light: argparse choices are built from it
before numpy or OpenCV load); this module binds each name to its parts. Adding a method is one module
(its settings dataclass, single and batch solvers) plus one entry in :data:`POSE_METHODS` (and its
name in ``qrfield.methods.METHODS``; a test checks the two agree).

Conventions of every solver (docs/conventions.md): corners (4, 2) pixels V1..V4, the side L in mm, the
pose of the QR centre in the camera frame in mm, angles in degrees, R = Rx Ry Rz (marker to camera).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from qrfield.methods import IPPE, METHODS, NUMERICAL
from qrfield.solvers.ippe import IppeSettings, solve_ippe
from qrfield.solvers.ippe import checked_settings as checked_ippe
from qrfield.solvers.ippe_batch import solve_ippe_vectorised
from qrfield.solvers.numerical import NumericalSettings, solve_numerical
from qrfield.solvers.numerical import checked_settings as checked_numerical
from qrfield.solvers.numerical_batch import solve_numerical_batch
from qrfield.solvers.result import SolverError


class SolveSingle(Protocol):
    """One corner set: (corners (4, 2) px, their 8 floats, camera, side mm, settings or None,
    normalised (x, y) lists or None) -> PoseResult (without its uncertainty fields)."""

    def __call__(self, corners: Any, flat: Any, camera: Any, side: float, settings: Any, xy: Any) -> Any: ...


class SolveBatch(Protocol):
    """N corner sets: (corners (N, 4, 2) px, valid (N,) bool, camera, side mm, settings or None,
    corners' covariance (N, 4, 2, 2) px^2 or None) -> BatchResult."""

    def __call__(
        self, corners: Any, valid: Any, camera: Any, side: float, settings: Any, cov: Any
    ) -> Any: ...


@dataclass(frozen=True)
class PoseMethod:
    """One pose method.

    Attributes:
        name: its name on the command line, in files and in results ("numerical", "ippe").
        title: one line for people (reports, notes).
        settings_class: its frozen settings dataclass (qrfield.settings declarations).
        checked_settings: settings or None -> valid settings (SettingError/SolverError otherwise).
        solve_single, solve_batch: the solvers (see :class:`SolveSingle`, :class:`SolveBatch`).
        depth_model: True when the pose comes from the four vertex depths (the thesis' model: its
            uncertainty propagates through the depths, docs/uncertainty.md); False for a rigid
            pose fitted directly (IPPE: through the reprojection of the rigid square).
    """

    name: str
    title: str
    settings_class: type
    checked_settings: Callable[[Any], Any]
    solve_single: SolveSingle
    solve_batch: SolveBatch
    depth_model: bool


#: Every pose method, in qrfield.methods.METHODS order (the first gives a frame's status).
POSE_METHODS: dict[str, PoseMethod] = {
    NUMERICAL: PoseMethod(
        NUMERICAL,
        "the thesis' numerical positioning model (our reconstruction)",
        NumericalSettings,
        checked_numerical,
        solve_numerical,
        solve_numerical_batch,
        depth_model=True,
    ),
    IPPE: PoseMethod(
        IPPE,
        "OpenCV IPPE_SQUARE (closed form, both candidates ranked by reprojection error)",
        IppeSettings,
        checked_ippe,
        solve_ippe,
        solve_ippe_vectorised,
        depth_model=False,
    ),
}
if tuple(POSE_METHODS) != METHODS:  # the light list and the registry must name the same methods
    raise ImportError(f"qrfield.methods.METHODS {METHODS} and the registry {tuple(POSE_METHODS)} differ")


def pose_method(name: str) -> PoseMethod:
    """The registered method ``name``; SolverError naming the known ones otherwise."""
    try:
        return POSE_METHODS[name]
    except (KeyError, TypeError):
        raise SolverError(f"unknown solver method {name!r}; choose one of {', '.join(METHODS)}") from None


def settings_class(method: str) -> type:
    """The settings dataclass of a method (NumericalSettings or IppeSettings); SolverError otherwise."""
    return pose_method(method).settings_class


def settings_classes() -> dict[str, type]:
    """Every method's settings dataclass, in METHODS order."""
    return {name: spec.settings_class for name, spec in POSE_METHODS.items()}


def uses_depth_model(method: str) -> bool:
    """True when the method's pose comes from vertex depths (see :attr:`PoseMethod.depth_model`)."""
    return pose_method(method).depth_model
