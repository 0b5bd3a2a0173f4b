"""The combination a ground-truth pose belongs to, from the signs of its angles (the simulation's
names: qrfield/data/combinations-default.csv). Expected names worked out by hand from the file."""

from __future__ import annotations

import pytest

from qrfield.sessions.combo_signs import (
    ZERO_ANGLE_DEG,
    angle_signs,
    combination_mismatch,
    sign_table,
    suggest_combination,
)

TABLE = sign_table()


@pytest.mark.parametrize(
    ("angles", "expected"),
    [
        ((0.0, 40.0, 0.0), "beta"),  # the row logged as alpha+beta-gamma+ in the issue
        ((15.0, -20.0, 10.0), "alpha+beta-gamma+"),  # the virtual bench's default pose
        ((30.0, 0.4, -0.8), "alpha"),  # hand-measured zeros within a degree
        ((12.0, 12.5, 0.0), "alpha+beta+"),
        ((25.0, 0.0, -25.0), "alpha+gamma-"),
        ((0.0, 10.0, -10.0), "beta+gamma-"),
        ((5.0, 5.0, -5.0), "alpha+beta+gamma-"),
        ((-30.0, 0.0, 0.0), None),  # the simulation sweeps t >= 0: no combination has alpha < 0
        ((0.2, -0.5, 0.9), None),  # no tilt: every combination at t = 0
    ],
)
def test_the_suggestion_follows_the_signs(angles, expected) -> None:
    assert TABLE is not None and len(TABLE) == 12
    assert suggest_combination(angles, TABLE) == expected


def test_the_zero_band_is_a_degree() -> None:
    assert ZERO_ANGLE_DEG == 1.0
    assert angle_signs((1.0, -1.0, 1.01)) == (0, 0, 1)
    assert angle_signs((-1.01, 0.0, 90.0)) == (-1, 0, 1)
    with pytest.raises(ValueError, match="three finite angles"):
        angle_signs((1.0, float("nan"), 0.0))


def test_a_disagreeing_label_is_named_with_what_fits() -> None:
    message = combination_mismatch("alpha+beta-gamma+", (0.0, 40.0, 0.0), TABLE)
    assert "'alpha+beta-gamma+' means α+ β− γ+" in message and "fit 'beta'" in message
    assert combination_mismatch("beta", (0.0, 40.0, 0.0), TABLE) == ""
    assert combination_mismatch("beta", (0.0, 0.3, 0.0), TABLE) == ""  # t = 0 fits every label
    assert "no combination of the list" in combination_mismatch("alpha", (-30.0, 0.0, 0.0), TABLE)
    assert combination_mismatch("my own label", (0.0, 40.0, 0.0), TABLE) == ""  # not in the list


def test_of_two_with_the_same_signs_the_nearer_direction_wins() -> None:
    table = {"alpha+beta+": (1.0, 1.0, 0.0), "2alpha+beta+": (2.0, 1.0, 0.0)}
    assert suggest_combination((40.0, 20.0, 0.0), table) == "2alpha+beta+"
    assert suggest_combination((20.0, 20.0, 0.0), table) == "alpha+beta+"
