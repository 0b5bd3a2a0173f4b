"""Texts (qrfield.texts) and numbers (qrfield.limits.as_number): the one path each goes through.

Truth: Python's own UTF-8 codec says which texts are representable; Python's float() says which
numbers are finite floats. A text that is not UTF-8 (a lone surrogate, which is how Python keeps a
byte of the command line that is not UTF-8) crashed OpenCV's binding with a segmentation fault
(``marker --text``, ``render --text``, ``run --virtual-text``); each must now be one line, exit 2.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from qrfield.cli import main
from qrfield.files import FileFormatError, loads_json, loads_toml
from qrfield.limits import LimitError, as_number
from qrfield.settings import SettingError, from_dict
from qrfield.sources.virtual import VirtualBenchSettings
from qrfield.texts import TextError, check_text

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FEW = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
# Every code point, surrogates included (hypothesis leaves them out of text() by default).
any_text = st.text(st.characters(min_codepoint=0, max_codepoint=0x10FFFF, exclude_categories=()), max_size=12)
surrogate = st.integers(0xD800, 0xDFFF).map(chr)


def _utf8(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


# ------------------------------------------------------------------------------------ texts
@FEW
@given(any_text)
@example("\ud800")
@example("abc\udcff")
def test_a_text_is_taken_exactly_when_utf8_can_encode_it(text):
    if _utf8(text):
        assert check_text(text, "--text") == text
    else:
        with pytest.raises(TextError, match=r"^--text: not UTF-8 text \(character \d+ is U\+D[89A-F]") as err:
            check_text(text, "--text")
        assert "\n" not in str(err.value)


def test_the_message_names_the_byte_the_command_line_gave():
    with pytest.raises(TextError, match=r"character 2 is U\+DCFF, the byte 0xFF, which is not UTF-8"):
        check_text("a\udcff", "--name")
    with pytest.raises(TextError, match="expected text, got int"):
        check_text(3, "x")


@FEW
@given(st.tuples(any_text, surrogate, any_text).map("".join))
def test_a_text_setting_that_is_not_utf8_is_refused_by_name(text):
    with pytest.raises(SettingError, match=r"setting VirtualBenchSettings\.text: not UTF-8 text"):
        from_dict(VirtualBenchSettings, {"text": text})


def _cli(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, err.getvalue()


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv",
    [
        [b"marker", b"--side-mm", b"30", b"--out", b"m.svg", b"--text", b"\xed\xa0\x80"],
        [
            b"render",
            b"--side-mm",
            b"30",
            b"--pose",
            b"0,0,300,0,0,0",
            b"--out",
            b"r.png",
            b"--text",
            b"a\xff",
        ],
        [b"run", b"--source", b"virtual", b"--frames", b"1", b"--virtual-text", b"\xff"],
    ],
    ids=["marker", "render", "run"],
)
def test_a_command_line_text_that_is_not_utf8_is_one_line_not_a_crash(argv, tmp_path):
    """In a subprocess: before the fix each of these ended in a segmentation fault (exit -11)."""
    env = {**os.environ, "PYTHONPATH": REPO, "QRFIELD_CONFIG_DIR": str(tmp_path / "config")}
    done = subprocess.run(
        [sys.executable.encode(), b"-m", b"qrfield", *argv],
        cwd=tmp_path,
        capture_output=True,
        env=env,
        timeout=120,
    )
    err = done.stderr.decode("utf-8", "replace").strip()
    assert done.returncode == 2, err
    assert len(err.splitlines()) == 1 and "not UTF-8 text" in err
    assert not list(tmp_path.glob("[mr].*"))  # nothing written


def test_a_settings_file_text_that_is_not_utf8_costs_only_its_key_and_a_strict_run_names_it(
    tmp_path, monkeypatch, capsys
):
    # Only the bad value is left out (the rest of the file is kept, nothing set aside); `qrfield
    # run`, strict about the values it uses, stops naming it, as for any other bad value.
    config = tmp_path / "config"
    config.mkdir()
    (config / "app.json").write_text('{"virtual": {"text": "\\ud800"}, "run": {"method": "ippe"}}')
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(config))
    assert main(["run", "--source", "virtual", "--frames", "1"]) != 0
    err = capsys.readouterr().err
    assert "value virtual.text: not UTF-8 text" in err and err.count("\n") == 1
    assert not list(config.glob("app.json.bad-*"))
    assert main(["run", "--source", "virtual", "--frames", "1", "--virtual-text", "ok"]) == 0


@pytest.mark.slow
@FEW
@given(command=st.sampled_from(["marker", "render"]), text=st.tuples(any_text, surrogate).map("".join))
def test_any_qr_text_that_is_not_utf8_is_refused_in_one_line(command, text, tmp_path):
    extra = ["--pose", "0,0,300,0,0,0", "--out", str(tmp_path / "r.png")] if command == "render" else []
    extra = extra or ["--out", str(tmp_path / "m.svg")]
    code, err = _cli([command, "--side-mm", "30", "--text", text, *extra])
    assert code == 2 and err.count("\n") == 1 and "not UTF-8 text" in err


# ------------------------------------------------------------------------------------ numbers
def _float_or_none(value):
    try:
        number = float(value)
    except (OverflowError, ValueError, TypeError):
        return None
    return number if math.isfinite(number) else None


@FEW
@given(
    st.one_of(
        st.integers(-(10**600), 10**600),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(alphabet="0123456789+-.eEinfa ", max_size=80),
        st.booleans(),
    )
)
@example(10**400)
@example(2**1024 - 1)
@example("1e400")
@example("9" * 65)
def test_a_number_is_taken_exactly_when_it_is_a_finite_float(value):
    expected = None if isinstance(value, bool) else _float_or_none(value)
    if isinstance(value, str) and len(value.strip()) > 64:
        expected = None
    if expected is None:
        with pytest.raises(LimitError, match=r"^k: fx ") as err:
            as_number(value, "k", "fx")
        assert "\n" not in str(err.value)
    else:
        assert as_number(value, "k", "fx") == expected


@FEW
@given(digits=st.integers(1, 20000), sign=st.sampled_from(["", "-"]), key=st.sampled_from(["fx", "width"]))
@example(digits=400, sign="", key="fx")
@example(digits=5000, sign="-", key="fx")  # beyond int()'s 4300 digits: Python's advice was shown
def test_any_integer_in_a_json_file_is_read_or_refused_naming_the_file_and_key(digits, sign, key):
    text = json.dumps({key: 0}).replace("0", sign + "9" * digits)
    if digits <= 308:
        assert loads_json(text, "camera file c.json")[key] == int(sign + "9" * digits)
    else:
        with pytest.raises(FileFormatError, match=rf"^camera file c\.json: value {key}: .* {digits} digits"):
            loads_json(text, "camera file c.json")


@FEW
@given(digits=st.integers(1, 20000), sign=st.sampled_from(["", "-", "+"]))
@example(digits=5000, sign="")  # beyond int()'s 4300 digits: a bare ValueError came out of loads_toml
def test_any_integer_in_a_toml_file_is_read_or_refused_naming_the_file(digits, sign):
    text = f"[grid]\nz = {sign}{'9' * digits}\n"
    if digits <= 308:
        assert loads_toml(text, "study s.toml")["grid"]["z"] == int(sign + "9" * digits)
    else:
        with pytest.raises(
            FileFormatError, match=rf"^study s\.toml: value (grid\.)?z: .* {digits} digits"
        ) as err:
            loads_toml(text, "study s.toml")
        assert "\n" not in str(err.value)


def test_overflowing_numbers_in_json_and_toml_are_named():
    with pytest.raises(FileFormatError, match=r"study s\.toml: value grid\.z: the number must be a finite"):
        loads_toml("[grid]\nz = 1e400\n", "study s.toml")
    with pytest.raises(FileFormatError, match=r"f\.json: value a\[1\]: the number must be a finite"):
        loads_json('{"a": [1, 1e999]}', "f.json")
    with pytest.raises(FileFormatError, match=r"a key in b: not UTF-8"):
        loads_json('{"b": {"\\udcff": 1}}', "f.json")


def test_a_400_digit_integer_in_a_camera_profile_is_one_line(tmp_path, capsys):
    """It was an OverflowError traceback (qrfield/files.py, Fields.number)."""
    profile = {"name": "big", "width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240}
    path = tmp_path / "big.json"
    path.write_text(json.dumps(profile).replace('"fx": 500', '"fx": ' + "9" * 400))
    code = main(
        [
            "render",
            "--camera",
            str(path),
            "--side-mm",
            "30",
            "--pose",
            "0,0,300,0,0,0",
            "--out",
            str(tmp_path / "r.png"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert f"camera file {path}: value fx: the number is an integer of 400 digits" in err


def test_numbers_of_csv_files_and_typed_values_go_through_the_same_reader():
    from qrfield.sessions.groundtruth import parse_number
    from qrfield.simulation.combinations import CombinationError, parse_combinations

    with pytest.raises(
        CombinationError, match=r"c\.csv, line 2: field 'alpha': the multiplier must be a finite"
    ):
        parse_combinations("name,alpha,beta,gamma\na,1e400,0,0\n", "c.csv")
    with pytest.raises(ValueError, match="must be a finite number in mm"):
        parse_number(10**400, "mm")  # was OverflowError from float()
