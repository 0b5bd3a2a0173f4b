"""Study files, overrides and the default rotation combinations."""

from __future__ import annotations

import numpy as np
import pytest

from qrfield.simulation import StudyError, config_from_dict, load_study, with_overrides
from qrfield.simulation.combinations import CombinationError, load_combinations, parse_combinations
from qrfield.simulation.study import field_specs


def test_default_combinations_are_the_twelve_of_design_md():
    combos = load_combinations("default")
    got = {c.multipliers for c in combos}
    # docs/conventions.md: single axes; pairs with equal and opposite signs; triples (+,+,+), (+,+,-),
    # (+,-,+).
    expected = {
        (1, 0, 0), (0, 1, 0), (0, 0, 1),
        (1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1), (0, 1, -1),
        (1, 1, 1), (1, 1, -1), (1, -1, 1),
    }  # fmt: skip
    assert len(combos) == 12
    assert got == {tuple(float(v) for v in m) for m in expected}
    assert len({c.name for c in combos}) == 12
    pair = next(c for c in combos if c.multipliers == (1.0, -1.0, 0.0))
    np.testing.assert_array_equal(pair.angles_deg(np.array([0.0, 30.0])), [[0, 0, 0], [30, -30, 0]])


def test_default_study_is_valid_and_its_size_is_stated():
    config = load_study()
    assert config.size() == {"grid_points": 105, "combinations": 12, "angles": 46, "poses": 57960}
    assert config.solvers == ("numerical", "numerical-parallelogram", "ippe")
    assert (config.criteria.angle_deg, config.criteria.position_mm, config.criteria.n_max) == (2.0, 5.0, 30)
    specs = {s.key: s for s in config.solver_specs()}
    assert specs["numerical"].settings.initial_guess == "seed"
    assert specs["numerical-parallelogram"].settings.initial_guess == "parallelogram"
    assert specs["numerical"].settings.n_max == 30
    np.testing.assert_allclose(config.sweep_values()[[0, 1, -1]], [0, 2, 90])
    np.testing.assert_allclose(config.x_values(), [-90, -60, -30, 0, 30, 60, 90])


def test_overrides_on_the_command_line():
    config = load_study(
        overrides=[
            "z_range=200,600,100",
            "degradation=noise",
            "noise_px=0.5",
            "criteria.angle_deg=1",
            "criteria.n_max=20",
            "solver.numerical.tf=0.8",
            "solvers=numerical,ippe",
            "camera=picam-v2@1280x960",
        ]
    )
    np.testing.assert_allclose(config.z_values(), [200, 300, 400, 500, 600])
    assert config.degradation == "noise" and config.noise_px == 0.5
    assert config.criteria.angle_deg == 1.0
    specs = {s.key: s for s in config.solver_specs()}
    assert set(specs) == {"numerical", "ippe"}
    assert specs["numerical"].settings.tf == 0.8 and specs["numerical"].settings.n_max == 20
    assert config.camera_model().width == 1280
    # a single number is a single grid value
    assert load_study(overrides=["z_range=300"]).z_values().tolist() == [300.0]


def test_resolved_study_round_trips_through_toml(tmp_path):
    config = load_study(overrides=["degradation=round", "solver.ippe.refine=none", "x_range=-10,10,10"])
    path = tmp_path / "study.toml"
    path.write_text(config.to_toml(), encoding="utf-8")
    assert load_study(path) == config
    assert with_overrides(config, ["side_mm=30"]).side_mm == 30.0


def test_user_file_needs_only_what_it_changes_and_paths_are_relative_to_it(tmp_path):
    (tmp_path / "mine.csv").write_text("name,alpha,beta,gamma\ntilt,1,0,0\n", encoding="utf-8")
    (tmp_path / "study.toml").write_text('combinations = "mine.csv"\nside_mm = 30\n', encoding="utf-8")
    config = load_study(tmp_path / "study.toml")
    assert [c.name for c in config.combination_list()] == ["tilt"]
    assert config.side_mm == 30.0 and config.camera == "picam-v2@640x480"


def test_written_study_reruns_from_another_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.csv").write_text("name,alpha,beta,gamma\nroll,0,0,1\n", encoding="utf-8")
    config = load_study(overrides=["combinations=mine.csv"])
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "study.toml").write_text(config.to_toml(), encoding="utf-8")
    again = load_study(tmp_path / "out" / "study.toml")
    assert [c.name for c in again.combination_list()] == ["roll"]


def test_field_specs_carry_units_limits_and_the_shipped_defaults():
    specs = {s.name: s for s in field_specs()}
    assert specs["side_mm"].unit == "mm" and specs["side_mm"].default == 50.0
    assert specs["degradation"].choices == ("none", "round", "noise")
    assert specs["criteria.n_max"].default == 30 and specs["criteria.angle_deg"].unit == "deg"
    assert specs["max_view_angle_deg"].maximum == 90.0
    assert "x_range" not in specs  # ranges are [start, stop, step], not scalar settings


def test_study_from_a_dict_as_the_app_builds_it():
    config = config_from_dict({"side_mm": 30, "criteria": {"n_max": 10}, "solvers": ["ippe"]})
    assert config.side_mm == 30.0 and config.criteria.n_max == 10 and config.solvers == ("ippe",)
    with pytest.raises(StudyError, match="sid_mm"):
        config_from_dict({"sid_mm": 30})


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("z_rnage = [200.0, 400.0, 100.0]\n", ["z_rnage", "z_range"]),  # typo: named, with a suggestion
        ("[criteria]\nangle_dg = 1\n", ["criteria.angle_dg", "angle_deg"]),
        ("x_range = [0.0, 100.0, 0.0]\n", ["x_range", "step"]),
        ("x_range = [100.0, 0.0, 10.0]\n", ["x_range", "below start"]),
        ("x_range = [0.0, 100.0]\n", ["x_range", "[start, stop, step]"]),
        ("z_range = [-100.0, 100.0, 100.0]\n", ["z_range", "front of the camera"]),
        ('degradation = "blur"\n', ["degradation", "none, round, noise"]),
        ("noise_px = 0.5\n", ["noise_px", "degradation"]),
        ("sweep_limit_deg = 200.0\n", ["sweep_limit_deg", "above the maximum 180"]),
        ("noise_seed = 1.5\n", ["noise_seed", "whole number"]),
        ('camera = ""\n', ["camera", "empty"]),
        ('solvers = ["numerical", "epnp"]\n', ["solvers", "epnp"]),
        ('solvers = ["numerical-fancy"]\n', ["numerical-fancy", "initial guess"]),
        ("[solver.numerical]\ntff = 0.5\n", ["solver.numerical.tff", "tf"]),
        ("[solver.numerical]\ntf = 7.0\n", ["solver.numerical", "tf"]),
        ("[solver.numerical]\nn_max = 10\n", ["solver.numerical.n_max", "criteria.n_max"]),
        ('camera = "no-such-camera"\n', ["camera", "no-such-camera"]),
        ('combinations = "missing.csv"\n', ["combinations", "missing.csv"]),
        ("side_mm = -5\n", ["side_mm", "below the minimum"]),
        ("side_mm = \n", ["not valid TOML"]),
    ],
)
def test_bad_study_file_names_the_field(tmp_path, text, words):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(StudyError) as info:
        load_study(path)
    message = str(info.value)
    for word in words:
        assert word in message, message


@pytest.mark.parametrize(
    ("override", "words"),
    [
        ("z_rang=1,2,1", ["z_rang", "z_range"]),
        ("side_mm", ["FIELD=VALUE"]),
        ("criteria=1", ["criteria.FIELD=VALUE"]),
        ("solver.numerical=1", ["solver.KEY.FIELD"]),
        ("sweep_step_deg=0", ["sweep_step_deg", "below the minimum"]),
    ],
)
def test_bad_override_names_the_field(override, words):
    with pytest.raises(StudyError) as info:
        load_study(overrides=[override])
    for word in words:
        assert word in str(info.value), str(info.value)


def test_bad_combinations_file_names_line_and_field():
    with pytest.raises(CombinationError, match="line 3: field 'beta' must be a number"):
        parse_combinations("name,alpha,beta,gamma\na,1,0,0\nb,1,x,0\n")
    with pytest.raises(CombinationError, match="rotates about no axis"):
        parse_combinations("name,alpha,beta,gamma\nnothing,0,0,0\n")
    with pytest.raises(CombinationError, match="header"):
        parse_combinations("name,a,b,c\nx,1,0,0\n")
    with pytest.raises(CombinationError, match="used twice"):
        parse_combinations("# comment\nname,alpha,beta,gamma\na,1,0,0\na,0,1,0\n")
