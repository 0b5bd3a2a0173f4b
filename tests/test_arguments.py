"""Command-line values: comma lists starting with '-', one-line errors, quiet broken pipes."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from qrfield.arguments import ArgumentParser, parse_numbers
from qrfield.cli import build_parser, main

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_render_takes_a_pose_starting_negative_both_ways(tmp_path, capsys):
    # Once "expected one argument": argparse took -10,5,... for an option.
    for i, pose in enumerate((["--pose", "-10,5,300,0,0,0"], ["--pose=-10,5,300,0,0,0"])):
        out = tmp_path / f"v{i}.png"
        argv = ["render", "--focal-px", "500", "--size", "640x480", "--side-mm", "60", *pose]
        assert main([*argv, "--out", str(out), "--json"]) == 0
        data = json.loads(capsys.readouterr().out)
        assert data["pose"]["position_mm"] == [-10.0, 5.0, 300.0]
        # By hand: x = -10 mm at z = 300 mm with f = 500 px is 16.67 px left of the centre 319.5.
        u_centre = sum(u for u, _ in data["corners"]) / 4
        assert u_centre == pytest.approx(319.5 - 500 * 10 / 300, abs=1e-3)


def test_corners_starting_negative_and_as_eight_numbers(capsys):
    # V1 at u = -5 lies inside the margin of the image: accepted, and both spellings agree.
    spaced = "-5,190 95,190 95,290 -5,290"
    flat = "-5,190,95,190,95,290,-5,290"
    base = ["solve", "--camera", "picam-v2@640x480", "--side-mm", "50", "--method", "ippe", "--json"]
    assert main([*base, "--corners", spaced]) == 0
    a = json.loads(capsys.readouterr().out)
    assert main([*base, f"--corners={flat}"]) == 0
    b = json.loads(capsys.readouterr().out)
    assert a == b and a[0]["position_mm"][0] < 0


def test_an_option_added_later_gets_negative_values_for_free():
    # What issue 14's `session log --truth X,Y,Z,A,B,G` relies on: every subparser is ours.
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    new = sub.add_parser("example-later")
    new.add_argument("--truth")
    assert type(new) is ArgumentParser
    args = parser.parse_args(["example-later", "--truth", "-12.5,0,300,-3,4,5"])
    assert args.truth == "-12.5,0,300,-3,4,5"


def test_real_options_still_parse_as_options():
    parser = ArgumentParser(prog="t")
    parser.add_argument("--pose")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(["--pose", "-1", "--json"])
    assert args.pose == "-1" and args.json
    with pytest.raises(SystemExit):
        parser.parse_args(["--pose", "--json"])  # a real option is not swallowed as a value


def test_help_says_negative_values_work(capsys):
    assert main(["render", "--help"]) == 0
    assert "--pose=-10,5,300,0,0,0" in capsys.readouterr().out.replace("\n", " ").replace("  ", " ")


def test_parse_numbers_names_the_bad_value():
    assert parse_numbers(" -1, 2;3 4 ", "--x") == [-1.0, 2.0, 3.0, 4.0]
    with pytest.raises(ValueError, match=r"--pose: expected 6 comma-separated numbers X,Y,Z,A,B,G, got 2"):
        parse_numbers("1,2", "--pose", names=("X", "Y", "Z", "A", "B", "G"))
    with pytest.raises(ValueError, match=r"--pose: Y 'abc' is not a number"):
        parse_numbers("1,abc", "--pose", names=("X", "Y"))
    with pytest.raises(ValueError, match="finite"):
        parse_numbers("1,inf", "--pose", count=2)


def test_usage_errors_are_one_line_and_returned(capsys):
    assert main(["render", "--side-mm", "50"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "required" in err and "see qrfield render --help" in err


@pytest.mark.slow
def test_solve_piped_into_head_is_quiet(tmp_path):
    # Once "BrokenPipeError" and exit code 2 (or "Exception ignored ... Broken pipe" at exit).
    env = {**os.environ, "PYTHONPATH": REPO}
    view = tmp_path / "view.png"
    subprocess.run(
        [sys.executable, "-m", "qrfield", "render", "--focal-px", "500", "--size", "320x240",
         "--side-mm", "40", "--pose", "0,0,250,10,0,0", "--out", str(view)],
        check=True, env=env, capture_output=True, timeout=120,
    )  # fmt: skip
    images = [str(view)] * 40
    script = (
        f"{sys.executable} -m qrfield solve {' '.join(images)} --focal-px 500 --side-mm 40 | head -c 10;"
        " echo; echo rc=${PIPESTATUS[0]}"
    )
    done = subprocess.run(["bash", "-c", script], env=env, capture_output=True, text=True, timeout=300)
    assert done.stdout.strip().endswith("rc=0"), done.stdout
    assert "Broken pipe" not in done.stderr and "Traceback" not in done.stderr, done.stderr


@pytest.mark.parametrize(
    "argv", [["analyze", "0.0", "\r"], ["solve", "--corners", "1,2\n3,4", "--side-mm", "x\ny"]]
)
def test_control_characters_in_what_was_typed_keep_the_error_on_one_line(argv, capsys):
    # Found by tests/test_fuzz.py: "unrecognized arguments: \r" split the message in two.
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.endswith("\n") and "\r" not in err


def _swap(option: str) -> str:
    """A typo: the two letters after the dashes swapped (``--side-mm`` -> ``--isde-mm``)."""
    return option[:2] + option[3] + option[2] + option[4:]


def _commands(parser):
    """(name, parser) of every leaf command, subcommands of subcommands included."""
    for action in parser._actions:
        if action.__class__.__name__ == "_SubParsersAction":
            for name, sub in action.choices.items():
                if any(a.__class__.__name__ == "_SubParsersAction" for a in sub._actions):
                    yield from ((f"{name} {n}", p) for n, p in _commands(sub))
                else:
                    yield name, sub


@pytest.mark.slow
def test_every_command_suggests_the_option_it_was_mistyped_for(capsys):
    """One implementation for all subcommands: a swapped pair of letters in a long option of each
    command gets "did you mean" with that option, in one line, exit 2 (before this, "unrecognized
    arguments" with no suggestion, or "the following arguments are required" first)."""
    checked = 0
    for name, sub in _commands(build_parser()):
        options = [o for a in sub._actions for o in a.option_strings if o.startswith("--") and len(o) > 6]
        option = next((o for o in options if o != "--help" and _swap(o) not in options), None)
        if option is None:
            continue
        assert main([*name.split(), _swap(option), "1"]) == 2, name
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"unrecognized option {_swap(option)}; did you mean" in err, (
            name,
            err,
        )
        checked += 1
    assert checked >= 15


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["rendr"], "invalid choice: 'rendr' (choose from"),
        (["session", "lst"], "did you mean list?"),
        (["solve", "--method", "ipe", "x.png"], "did you mean ippe?"),
        (["render", "--sied-mm", "30", "--out", "x.png"], "did you mean --side-mm?"),
    ],
)
def test_a_mistyped_command_choice_or_option_gets_the_nearest(argv, words, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1
    if argv[0] == "rendr":
        assert "did you mean render?" in err


@pytest.mark.parametrize("value", ["-inf", "-Infinity", "-nan"])
def test_a_negative_infinity_is_a_value_refused_as_not_finite(value, capsys):
    """Was "argument --side-mm: expected one argument": argparse took -inf for an option."""
    assert main(["render", "--side-mm", value, "--pose", "0,0,300,0,0,0", "--out", "x.png"]) == 2
    err = capsys.readouterr().err
    assert "argument --side-mm: QR side must be a finite number" in err and err.count("\n") == 1
