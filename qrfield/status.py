"""Statuses: what the pipeline made of a frame, what other programs are told, and the one rule between.

docs/conventions.md ("Serial protocol 2"). Three vocabularies, each a ``StrEnum`` (members are str,
so they compare equal to, format and serialise as their words):

- :class:`ResultStatus`, a frame's result (``qrfield.pipeline.FrameResult.status``): OK (the first
  chosen method converged), NOQR, NOCONV, ERROR.
- :class:`Reported`, what a frame is reported as to people and programs (the app, ``qrfield run``'s
  JSON lines, sessions): OK only for an unambiguous pose from a live camera, AMBIG for an ambiguous
  one from a live camera, SIM for a pose from any other source; NOQR, NOCONV, ERROR as they are.
- :class:`WireStatus`, the serial line's words (``$QRF``, ``$QRM``): the reported ones with ERROR
  sent as NOCONV (a controller treats both as "no pose"), plus the link's own STALE and NOSRC and the
  measurement's TIMEOUT.

:func:`reported_status` is the only place that decides OK against AMBIG against SIM, so a program
that acts only on OK is never handed a made-up, recorded or ambiguous pose. :func:`usable_pose`
says when a solver's result holds a pose that may be used at all (averaged, shown, sent).
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Any


class ResultStatus(StrEnum):
    """What the pipeline made of one frame (``FrameResult.status``)."""

    OK = "OK"  # the first chosen method converged: a pose is given
    NOQR = "NOQR"  # no code found (or none with the selected text)
    NOCONV = "NOCONV"  # a code, but no converged pose (or corners not fit for one)
    ERROR = "ERROR"  # anything else (the camera model does not fit, a solver raised)


class Reported(StrEnum):
    """A frame's status as reported to people and programs (the app, JSON lines, sessions)."""

    OK = "OK"  # a measured, unambiguous pose from a live camera: the only one to act on
    AMBIG = "AMBIG"  # a live camera's pose whose flip (mirror) ambiguity is unresolved
    SIM = "SIM"  # a pose from a virtual, recorded or simulated source
    NOQR = "NOQR"
    NOCONV = "NOCONV"
    ERROR = "ERROR"


class WireStatus(StrEnum):
    """The status words of the serial protocol (``$QRF`` lines and ``$QRM`` answers)."""

    OK = "OK"
    AMBIG = "AMBIG"
    SIM = "SIM"
    NOQR = "NOQR"
    NOCONV = "NOCONV"
    STALE = "STALE"  # the source is up, but no frame newer than stale_after_s was processed
    NOSRC = "NOSRC"  # no camera frames (also after a video or folder ended)
    TIMEOUT = "TIMEOUT"  # $QRM only: not enough converged frames in time


#: Reported statuses that carry a pose (the fields are filled).
POSE_REPORTED = frozenset({Reported.OK, Reported.AMBIG, Reported.SIM})
#: Wire statuses of a ``$QRF`` line, and those whose pose fields are filled / always empty.
QRF_STATUSES = (
    WireStatus.OK,
    WireStatus.AMBIG,
    WireStatus.SIM,
    WireStatus.NOQR,
    WireStatus.NOCONV,
    WireStatus.STALE,
    WireStatus.NOSRC,
)
QRF_POSE_STATUSES = frozenset({WireStatus.OK, WireStatus.AMBIG, WireStatus.SIM})
#: Wire statuses of a ``$QRM`` answer: a mean pose, or why there is none.
QRM_STATUSES = (
    WireStatus.OK,
    WireStatus.AMBIG,
    WireStatus.SIM,
    WireStatus.NOQR,
    WireStatus.NOCONV,
    WireStatus.NOSRC,
    WireStatus.TIMEOUT,
)
# ERROR is "no pose" to a controller, the same as a pose that did not converge.
_REPORTED_TO_WIRE = {
    Reported.OK: WireStatus.OK,
    Reported.AMBIG: WireStatus.AMBIG,
    Reported.SIM: WireStatus.SIM,
    Reported.NOQR: WireStatus.NOQR,
    Reported.NOCONV: WireStatus.NOCONV,
    Reported.ERROR: WireStatus.NOCONV,
}


def pose_reported(*, live: bool, ambiguous: bool = False) -> Reported:
    """How a usable pose is reported: OK only from a live camera and unambiguous; AMBIG from a live
    camera when the flip is unresolved; SIM from any other source (ambiguous or not: a made-up pose is
    never acted on, and its ``ambiguous`` flag travels beside it)."""
    if not live:
        return Reported.SIM
    return Reported.AMBIG if ambiguous else Reported.OK


def reported_status(status: str, *, live: bool, ambiguous: bool = False) -> Reported:
    """The one rule from a result status to what is reported (see the module doc).

    Args:
        status: a :class:`ResultStatus` word (ValueError for any other).
        live: the frame came from a live camera (``qrfield.sources.is_live_camera``).
        ambiguous: the pose's flip is unresolved (``FrameResult.ambiguous``).
    """
    result = ResultStatus(status)
    if result is ResultStatus.OK:
        return pose_reported(live=live, ambiguous=ambiguous)
    return Reported(result.value)


def wire_status(reported: str) -> WireStatus:
    """The serial word for a reported status (ERROR goes out as NOCONV); ValueError otherwise."""
    return _REPORTED_TO_WIRE[Reported(reported)]


def usable_pose(pose: Any) -> bool:
    """True when a solver's result (``qrfield.solvers.PoseResult`` or anything with ``converged``
    and ``position_mm``) holds a pose to use: converged with a finite position. None is not usable."""
    if pose is None or not bool(getattr(pose, "converged", False)):
        return False
    position = getattr(pose, "position_mm", None)
    if position is None:
        return False
    try:
        return all(math.isfinite(float(v)) for v in position)
    except (TypeError, ValueError):
        return False
