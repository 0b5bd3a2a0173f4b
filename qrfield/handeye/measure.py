"""The code's pose in one image, for a hand-eye pair: detected, solved, and judged fit for a pair.

A pair needs a pose the camera is sure of: a code found with refined corners, a converged solve,
and no flip risk (``PoseResult.ambiguous``: the mirror pose of the planar ambiguity fits the corners
as well, and a pair built on the wrong one would pull the solve by twice the tilt). Anything else is
left out with the reason (docs/handeye.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from qrfield.camera import CameraModel
from qrfield.methods import NUMERICAL

#: The kinds of :func:`pair_problem_kind` ("" when the pose makes a pair).
NO_POSE, NOT_CONVERGED, AMBIGUOUS = "no pose", "not converged", "ambiguous"


def pair_problem_kind(result: Any) -> str:
    """Why a PoseResult cannot make a pair, in one word: NO_POSE (no code, or no result),
    NOT_CONVERGED, AMBIGUOUS, or "" when it can."""
    if result is None:
        return NO_POSE
    if not result.converged or not np.all(np.isfinite(result.position_mm)):
        return NOT_CONVERGED
    if result.ambiguous:
        return AMBIGUOUS
    return ""


def pair_problem(result: Any) -> str:
    """Why a PoseResult cannot make a pair, for a person ("" when it can)."""
    kind = pair_problem_kind(result)
    if kind == NOT_CONVERGED:
        return f"not converged: {result.reason or 'no pose'}"
    if kind == AMBIGUOUS:
        return (
            "ambiguous: the mirror pose fits the corners as well (a view with more tilt, or a closer "
            "or larger code, makes the pose unique)"
        )
    return kind


def pose_for_pair(
    image: np.ndarray,
    camera: CameraModel,
    side_mm: float,
    detector: Any,
    *,
    method: str = NUMERICAL,
    settings: Any = None,
    select_text: str = "",
) -> tuple[Any, str]:
    """(PoseResult, "") for the code in ``image`` (grey or BGR, at ``camera``'s size), or (None or
    the unusable PoseResult, why it makes no pair). ``detector``: a :class:`qrfield.detect.Detector`
    (its lens is set to ``camera`` here); ``select_text``: only a code with this payload counts."""
    from qrfield.detect import select_code
    from qrfield.solvers import solve

    height, width = image.shape[:2]
    if (width, height) != camera.size:
        raise ValueError(f"image is {width}x{height}, camera {camera.name} is {camera.width}x{camera.height}")
    detector.set_camera(camera)
    detection = select_code(detector.detect(image), select_text)
    if detection is None:
        return None, f"no QR code with the text {select_text!r} found" if select_text else "no QR code found"
    if detection.untrusted:
        return None, f"corners not trusted: {detection.untrusted}"
    result = solve(detection.corners_px, camera, side_mm, method, settings, detection.pose_cov)
    problem = pair_problem(result)
    return result, problem
