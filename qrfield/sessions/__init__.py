"""Experiment sessions: ground truth entry, averaged rows, crash-safe CSV, analysis.

The app's form, table and analysis tab are thin layers over these functions:
  - :func:`check_ground_truth` / :func:`validate_field`: per-field messages for the form;
  - :class:`FrameCollector` / :func:`measure`: N frames -> means, deviations, errors, pass;
  - :class:`Session`: create / open (resume) / log / undo / retry, rows for the table;
  - :func:`qrfield.sessions.analysis.analyze`: per-combination figures, plots, resemblance.
"""

from qrfield.sessions.averaging import (
    AveragedPose,
    FrameCollector,
    Judgement,
    Measurement,
    average_frames,
    circular_mean_deg,
    judge_row,
    measure,
)
from qrfield.sessions.criteria import AcceptanceCriteria, SessionSettings
from qrfield.sessions.groundtruth import (
    FIELDS,
    GroundTruth,
    GroundTruthError,
    check_ground_truth,
    known_combinations,
    parse_ground_truth,
    truth_fields,
    validate_field,
)
from qrfield.sessions.store import (
    COLUMNS,
    EXTRA_COLUMNS,
    REQUIRED_COLUMNS,
    LoggedRow,
    LogOutcome,
    Session,
    SessionError,
    SessionInfo,
    read_session,
    sanitize_name,
    session_folders,
)

__all__ = [
    "COLUMNS",
    "EXTRA_COLUMNS",
    "FIELDS",
    "REQUIRED_COLUMNS",
    "AcceptanceCriteria",
    "AveragedPose",
    "FrameCollector",
    "GroundTruth",
    "GroundTruthError",
    "Judgement",
    "LogOutcome",
    "LoggedRow",
    "Measurement",
    "Session",
    "SessionError",
    "SessionInfo",
    "SessionSettings",
    "average_frames",
    "check_ground_truth",
    "circular_mean_deg",
    "judge_row",
    "known_combinations",
    "measure",
    "parse_ground_truth",
    "read_session",
    "sanitize_name",
    "session_folders",
    "truth_fields",
    "validate_field",
]
