"""Experiment plans: generated from the study's combinations (checked against the list in
docs/conventions.md, typed here), written and read back, and hand-written plans whose every
problem is named by line, target and column."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qrfield.sessions.plan import PLAN_COLUMNS, PlanError, generate_plan, parse_plan, read_plan, write_plan

# docs/conventions.md, "Simulation study": the single axes, the pairs with equal and with opposite
# signs, and the triples (+,+,+), (+,+,-), (+,-,+) (typed from the document, not read from the code).
DESIGN_COMBINATIONS = {
    "alpha": (1, 0, 0),
    "beta": (0, 1, 0),
    "gamma": (0, 0, 1),
    "alpha+beta+": (1, 1, 0),
    "alpha+beta-": (1, -1, 0),
    "alpha+gamma+": (1, 0, 1),
    "alpha+gamma-": (1, 0, -1),
    "beta+gamma+": (0, 1, 1),
    "beta+gamma-": (0, 1, -1),
    "alpha+beta+gamma+": (1, 1, 1),
    "alpha+beta+gamma-": (1, 1, -1),
    "alpha+beta-gamma+": (1, -1, 1),
}


def test_all_combinations_at_two_angles_are_the_studys_12_times_2() -> None:
    targets = generate_plan("all", [10, 20], z_mm=300, x_mm=5, y_mm=-4)
    assert len(targets) == 24
    assert [t.number for t in targets] == list(range(1, 25))
    seen = {}
    for target in targets:
        t = target.truth
        assert (t.x, t.y, t.z) == (5, -4, 300)
        seen.setdefault(t.combo, []).append(t.angles_deg)
    assert set(seen) == set(DESIGN_COMBINATIONS)
    for name, angles in seen.items():
        m = DESIGN_COMBINATIONS[name]
        assert angles == [tuple(10.0 * k for k in m), tuple(20.0 * k for k in m)], name


def test_a_list_of_combinations_keeps_the_files_order_of_angles_as_given() -> None:
    targets = generate_plan("beta+gamma-, alpha", [30, 5], z_mm=250)
    assert [(t.combo, t.truth.angles_deg) for t in targets] == [
        ("beta+gamma-", (0.0, 30.0, -30.0)),
        ("beta+gamma-", (0.0, 5.0, -5.0)),
        ("alpha", (30.0, 0.0, 0.0)),
        ("alpha", (5.0, 0.0, 0.0)),
    ]


@pytest.mark.parametrize(
    ("combos", "angles", "z", "words"),
    [
        ("alpha,delta", [10], 300, "unknown combination(s) delta"),
        ("alpha", [10, 10], 300, "given twice"),
        ("alpha", [-10], 300, ">= 0"),
        ("beta", [95], 300, "beta = 95"),
        ("alpha", [10], -5, "--z-mm"),
        ("alpha", [], 300, "--angles"),
    ],
)
def test_generation_refuses_what_no_target_can_be(combos, angles, z, words) -> None:
    with pytest.raises(ValueError, match=None) as info:
        generate_plan(combos, angles, z_mm=z)
    assert words in str(info.value)


@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(
    combos=st.lists(st.sampled_from(sorted(DESIGN_COMBINATIONS)), min_size=1, max_size=12, unique=True),
    angles=st.lists(
        st.floats(min_value=0, max_value=90, allow_nan=False).map(lambda v: round(v, 3)),
        min_size=1,
        max_size=5,
        unique=True,
    ),
    z=st.floats(min_value=50, max_value=2000).map(lambda v: round(v, 3)),
    x=st.floats(min_value=-500, max_value=500).map(lambda v: round(v, 3)),
)
def test_a_written_plan_reads_back_as_the_same_targets(tmp_path_factory, combos, angles, z, x) -> None:
    targets = generate_plan(combos, angles, z_mm=z, x_mm=x)
    path = tmp_path_factory.mktemp("plan") / "plan.csv"
    write_plan(path, targets)
    back = read_plan(path)
    assert back == targets
    for target in back:
        m = DESIGN_COMBINATIONS[target.combo]
        t = max(abs(a) for a in target.truth.angles_deg)
        assert target.truth.angles_deg == pytest.approx([t * k for k in m], abs=1e-9)


def test_a_hand_written_plan_with_units_commas_comments_and_columns_in_another_order() -> None:
    text = (
        "\ufeff# my jig, z from the rail\n"
        "combo,note,gamma,beta,alpha,z,y,x\n"
        'alpha,first,0,0,"12,5",300 mm,0,0\n'
        "\n"
        "alpha+beta-,jig B,0 deg,-10°,10,310,2,-3\n"
    )
    targets = parse_plan(text, "hand.csv")
    assert [t.number for t in targets] == [1, 2]
    assert targets[0].truth.angles_deg == (12.5, 0.0, 0.0) and targets[0].note == "first"
    assert targets[1].truth.position_mm == (-3.0, 2.0, 310.0)
    assert targets[1].truth.angles_deg == (10.0, -10.0, 0.0) and targets[1].combo == "alpha+beta-"


def test_every_problem_of_a_hand_written_plan_names_its_line_target_and_column() -> None:
    text = (
        "x,y,z,alpha,beta,gamma,combo,note\n"
        "0,0,300,10,0,0,alpha,ok\n"  # line 2: target 1, good
        "0,0,30 cm,10,95,0,beta,\n"  # line 3: target 2, z in cm and beta beyond 90
        "0,0,300,-10,0,0,alpha,\n"  # line 4: target 3, the angles do not have alpha's sign
        "0,0,300,1,000,0,0,alpha,\n"  # line 5: target 4, one value too many
        "0,0,300,10,0,0,omega,\n"  # line 6: target 5, no such combination
    )
    with pytest.raises(PlanError) as info:
        parse_plan(text, "plan.csv")
    problems = info.value.problems
    assert len(problems) == 5, problems
    assert problems[0].startswith("plan.csv line 3 (target 2), column 'z':") and "cm" in problems[0]
    assert problems[1].startswith("plan.csv line 3 (target 2), column 'beta':") and "-90..90" in problems[1]
    assert problems[2].startswith("plan.csv line 4 (target 3), column 'combo':") and "'alpha'" in problems[2]
    assert problems[3].startswith("plan.csv line 5 (target 4):") and "9 values" in problems[3]
    assert problems[4].startswith("plan.csv line 6 (target 5), column 'combo':") and "omega" in problems[4]
    assert str(info.value).count("plan.csv line") == 5  # one message names them all


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("", "empty"),
        ("x,y,z,alpha,beta,gamma\n0,0,300,0,0,0\n", "no column 'combo'"),
        ("x,y,z,alpha,beta,gamma,combo,weight\n", "unknown column 'weight'"),
        ("x,y,z,alpha,beta,gamma,combo,x\n", "named twice"),
        ("x,y,z,alpha,beta,gamma,combo\n", "no targets"),
    ],
)
def test_a_plan_without_a_usable_header_or_targets_is_refused(text, words) -> None:
    with pytest.raises(PlanError, match=words):
        parse_plan(text, "p.csv")


@pytest.mark.slow
def test_the_command_writes_checks_and_refuses_to_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "plan.csv"

    def qrfield(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "qrfield", *args], capture_output=True, text=True, timeout=120
        )

    done = qrfield("plan", "--combos", "all", "--angles", "10,20", "--z-mm", "300", "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert "24 targets" in done.stdout
    lines = out.read_text(encoding="utf-8").splitlines()
    assert lines[0] == ",".join(PLAN_COLUMNS) and len(lines) == 25
    assert lines[-1] == "0,0,300,20,-20,20,alpha+beta-gamma+,"
    again = qrfield("plan", "--angles", "10", "--z-mm", "300", "--out", str(out))
    assert again.returncode == 2 and "--force" in again.stderr
    assert len(out.read_text(encoding="utf-8").splitlines()) == 25  # untouched
    check = qrfield("plan", "--check", str(out))
    assert check.returncode == 0 and "24 targets, 12 combinations" in check.stdout
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z,alpha,beta,gamma,combo\n0,0,300,10,0,x,alpha\n", encoding="utf-8")
    refused = qrfield("plan", "--check", str(bad))
    assert refused.returncode == 2
    assert f"{bad} line 2 (target 1), column 'gamma'" in refused.stderr
