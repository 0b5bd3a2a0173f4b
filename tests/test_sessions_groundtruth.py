"""Ground-truth fields: numbers, units, ranges; a message per bad field and never a half row."""

from __future__ import annotations

import pytest

from qrfield.sessions import (
    GroundTruthError,
    check_ground_truth,
    parse_ground_truth,
    truth_fields,
    validate_field,
)

GOOD = {"x": "-12.5", "y": "40", "z": "350", "alpha": "10", "beta": "-20", "gamma": "179.5", "combo": "alpha"}


def test_good_fields_give_the_numbers_in_mm_and_degrees():
    truth = parse_ground_truth(GOOD)
    assert (truth.x, truth.y, truth.z) == (-12.5, 40.0, 350.0)
    assert (truth.alpha, truth.beta, truth.gamma) == (10.0, -20.0, 179.5)
    assert truth.combo == "alpha"


@pytest.mark.parametrize(
    ("field", "text", "value"),
    [
        ("z", "300 mm", 300.0),
        ("z", "300mm", 300.0),
        ("x", "12,5", 12.5),  # a decimal comma is accepted...
        ("x", "-0,25", -0.25),
        ("alpha", "12.5 deg", 12.5),
        ("alpha", "12.5°", 12.5),
        ("gamma", "-180", 180.0),  # the same angle; the convention's range is (-180, 180]
        ("beta", "-90", -90.0),
        ("y", "1e2", 100.0),
    ],
)
def test_accepted_spellings(field, text, value):
    assert validate_field(field, text) == (value, "")


@pytest.mark.parametrize(
    ("field", "text", "words"),
    [
        ("z", "3OO", ["'3OO'", "not a number"]),  # letter O typed for zero
        ("x", "", ["empty"]),
        ("x", "1,000", ["ambiguous"]),  # ...but not where it may be a thousands separator
        ("z", "30 cm", ["unit 'cm'", "mm"]),
        ("alpha", "0.3 rad", ["unit 'rad'", "deg"]),
        ("alpha", "12 mm", ["unit 'mm'", "deg"]),
        ("z", "0", ["> 0"]),
        ("z", "-300", ["> 0"]),
        ("beta", "95", ["-90..90"]),
        ("alpha", "181", ["outside (-180, 180]"]),  # the convention's range (docs/conventions.md)
        ("gamma", "-200", ["outside (-180, 180]"]),
        ("x", "9000", ["outside"]),
        ("y", "nan", ["not a number"]),
        ("y", "1.2.3", ["not a number"]),
        ("combo", "  ", ["empty"]),
        ("combo", "a\nb", ["one line"]),
    ],
)
def test_bad_field_messages(field, text, words):
    value, message = validate_field(field, text)
    assert value is None
    for word in words:
        assert word in message


def test_every_bad_field_is_reported_and_no_row_is_made():
    fields = {**GOOD, "z": "3OO", "beta": "95", "combo": ""}
    truth, errors = check_ground_truth(fields)
    assert truth is None
    assert set(errors) == {"z", "beta", "combo"}
    with pytest.raises(GroundTruthError) as info:
        parse_ground_truth(fields)
    assert set(info.value.errors) == {"z", "beta", "combo"}
    assert "z: '3OO' is not a number" in str(info.value)


def test_missing_and_unknown_fields_are_named():
    fields = {k: v for k, v in GOOD.items() if k != "gamma"} | {"delta": "1"}
    truth, errors = check_ground_truth(fields)
    assert truth is None
    assert errors["gamma"] == "missing"
    assert "unknown field" in errors["delta"]


def test_combo_must_be_one_of_the_simulation_combinations_when_given():
    names = ["alpha", "beta", "gamma", "alpha+beta"]
    assert parse_ground_truth({**GOOD, "combo": "alpha+beta"}, names).combo == "alpha+beta"
    truth, errors = check_ground_truth({**GOOD, "combo": "alpha-beta"}, names)
    assert truth is None
    assert "not a known combination" in errors["combo"]
    # Without a list any one-line text names the combination.
    assert parse_ground_truth({**GOOD, "combo": " my tilt rig "}).combo == "my tilt rig"


def test_the_form_keeps_the_last_values():
    truth = parse_ground_truth(GOOD)
    assert parse_ground_truth(truth.as_fields()) == truth


def test_the_virtual_bench_pose_pre_fills_the_form():
    fields = truth_fields([12.34567, -0.0001, 300.0], [10.0, -0.5, 179.9999], "alpha")
    assert fields == {
        "x": "12.346",
        "y": "0",
        "z": "300",
        "alpha": "10",
        "beta": "-0.5",
        "gamma": "180",
        "combo": "alpha",
    }
    assert parse_ground_truth(fields).gamma == 180.0


def test_combinations_come_from_the_simulation():
    from qrfield.sessions import known_combinations

    names = known_combinations()
    assert names and {"alpha", "beta", "gamma"} <= set(names)
    assert parse_ground_truth({**GOOD, "combo": names[-1]}, names).combo == names[-1]
