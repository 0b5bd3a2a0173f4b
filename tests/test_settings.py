"""Settings declared once: validation, JSON round trip, CLI options from one declaration."""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import pytest

from qrfield import settings as st


@dataclass(frozen=True)
class Demo:
    tf: float = st.setting(0.9, label="tuning factor", minimum=0.05, maximum=2.0)
    n_max: int = st.setting(30, label="n_max", unit="iterations", minimum=1, maximum=1000)
    z_min_mm: float = st.setting(50.0, label="Z_w,min", unit="mm", minimum=1.0)
    guess: str = st.setting("seed", label="initial guess", choices=("seed", "homography"))
    refine: bool = st.setting(True, label="refine")


def test_specs_carry_unit_and_limits():
    specs = {s.name: s for s in st.specs(Demo)}
    assert specs["z_min_mm"].unit == "mm" and specs["z_min_mm"].minimum == 1.0
    assert specs["n_max"].type is int and specs["guess"].choices == ("seed", "homography")


def test_round_trip_and_validation():
    demo = st.from_dict(Demo, {"tf": "0.5", "n_max": 12.0, "refine": "false"})
    assert (demo.tf, demo.n_max, demo.refine) == (0.5, 12, False)
    assert st.from_dict(Demo, st.to_dict(demo)) == demo
    with pytest.raises(st.SettingError, match=r"tf.*above the maximum 2\.0"):
        st.from_dict(Demo, {"tf": 3})
    with pytest.raises(st.SettingError, match=r"n_max.*whole number"):
        st.from_dict(Demo, {"n_max": 2.5})
    with pytest.raises(st.SettingError, match="not one of"):
        st.from_dict(Demo, {"guess": "magic"})
    with pytest.raises(st.SettingError, match="unknown setting"):
        st.from_dict(Demo, {"tff": 1})
    assert st.from_dict(Demo, {"tff": 1}, strict=False) == Demo()
    with pytest.raises(st.SettingError, match=r"z_min_mm: 0\.0 mm is below"):
        st.validated(Demo(z_min_mm=0.0))


def test_cli_options_from_the_declaration():
    parser = argparse.ArgumentParser()
    st.add_arguments(parser, Demo)
    args = parser.parse_args(["--tf", "1.5", "--guess", "homography", "--refine", "no"])
    demo = st.from_arguments(Demo, args)
    assert (demo.tf, demo.guess, demo.refine, demo.n_max) == (1.5, "homography", False, 30)
