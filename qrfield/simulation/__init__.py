"""The thesis' simulation study: where each solver finds the pose, for rotation combinations over a grid.

Entry points: :func:`load_study` (a TOML study plus overrides) -> :class:`StudyConfig`;
:func:`run_study` (vectorised sweep, progress callback, stop event) -> :class:`StudyResult`;
:func:`write_outputs` (samples, heatmaps, summary). See ``qrfield simulate --help``.
"""

from qrfield.simulation.combinations import Combination, CombinationError, load_combinations
from qrfield.simulation.outputs import write_outputs
from qrfield.simulation.runner import Progress, StudyResult, run_study
from qrfield.simulation.study import (
    Criteria,
    StudyConfig,
    StudyError,
    config_from_dict,
    load_study,
    with_overrides,
)

__all__ = [
    "Combination",
    "CombinationError",
    "Criteria",
    "Progress",
    "StudyConfig",
    "StudyError",
    "StudyResult",
    "config_from_dict",
    "load_combinations",
    "load_study",
    "run_study",
    "with_overrides",
    "write_outputs",
]
