"""The status vocabularies and the one rule between them (docs/conventions.md, "Serial protocol 2").

The truth table is written out here by hand from the conventions, not derived from the module."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import pytest

from qrfield.status import (
    QRF_STATUSES,
    QRM_STATUSES,
    Reported,
    ResultStatus,
    WireStatus,
    reported_status,
    usable_pose,
    wire_status,
)

# (result status, live camera, ambiguous) -> (reported, on the wire)
TABLE = {
    ("OK", True, False): ("OK", "OK"),
    ("OK", True, True): ("AMBIG", "AMBIG"),
    ("OK", False, False): ("SIM", "SIM"),
    ("OK", False, True): ("SIM", "SIM"),
    ("NOQR", True, False): ("NOQR", "NOQR"),
    ("NOQR", False, True): ("NOQR", "NOQR"),
    ("NOCONV", True, True): ("NOCONV", "NOCONV"),
    ("NOCONV", False, False): ("NOCONV", "NOCONV"),
    ("ERROR", True, False): ("ERROR", "NOCONV"),
    ("ERROR", False, True): ("ERROR", "NOCONV"),
}


@pytest.mark.parametrize(("key", "expected"), list(TABLE.items()))
def test_a_result_is_reported_and_sent_by_the_conventions_rule(key, expected) -> None:
    status, live, ambiguous = key
    reported = reported_status(status, live=live, ambiguous=ambiguous)
    assert (reported, wire_status(reported)) == expected


def test_only_an_unambiguous_pose_from_a_live_camera_is_ok() -> None:
    oks = [key for key, (reported, _) in TABLE.items() if reported == "OK"]
    assert oks == [("OK", True, False)]


def test_the_vocabularies_hold_the_words_of_the_conventions() -> None:
    assert [s.value for s in ResultStatus] == ["OK", "NOQR", "NOCONV", "ERROR"]
    assert {s.value for s in Reported} == {"OK", "AMBIG", "SIM", "NOQR", "NOCONV", "ERROR"}
    assert [s.value for s in QRF_STATUSES] == ["OK", "AMBIG", "SIM", "NOQR", "NOCONV", "STALE", "NOSRC"]
    assert [s.value for s in QRM_STATUSES] == ["OK", "AMBIG", "SIM", "NOQR", "NOCONV", "NOSRC", "TIMEOUT"]
    assert "ERROR" not in {s.value for s in WireStatus}


def test_statuses_are_plain_words_in_text_and_json() -> None:
    assert f"{Reported.AMBIG}" == "AMBIG" and str(WireStatus.NOSRC) == "NOSRC"
    assert json.dumps({"status": Reported.SIM}) == '{"status": "SIM"}'
    assert ResultStatus.OK == "OK"


def test_an_unknown_status_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match="BOGUS"):
        reported_status("BOGUS", live=True)
    with pytest.raises(ValueError, match="STALE"):
        wire_status("STALE")  # a wire word, not a reported one


@pytest.mark.parametrize(
    ("pose", "usable"),
    [
        (None, False),
        (SimpleNamespace(converged=True, position_mm=(1.0, 2.0, 300.0)), True),
        (SimpleNamespace(converged=False, position_mm=(1.0, 2.0, 300.0)), False),
        (SimpleNamespace(converged=True, position_mm=(1.0, math.nan, 300.0)), False),
        (SimpleNamespace(converged=True, position_mm=(1.0, 2.0, math.inf)), False),
        (SimpleNamespace(converged=True, position_mm=None), False),
        (SimpleNamespace(converged=True), False),
    ],
)
def test_a_usable_pose_is_converged_with_a_finite_position(pose, usable) -> None:
    assert usable_pose(pose) is usable
