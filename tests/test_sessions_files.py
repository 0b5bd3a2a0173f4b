"""Session files read as a spreadsheet or an editor leaves them: a BOM, pass words, long fields,
values of the wrong type, deep nesting; a field too long for CSV is refused when logged."""

from __future__ import annotations

import datetime as dt
import json

import pytest

from qrfield.cli import main
from qrfield.files import MAX_FIELD_CHARS
from qrfield.sessions import GroundTruth, Session, SessionError, measure, read_session


def make(root, camera):
    return Session.create(
        root, "bench", camera=camera, side_mm=50.0, solver="ippe", now=dt.datetime(2026, 1, 2, 3, 4, 5)
    )


def a_row(note=""):
    frames = [{"position_mm": [0.0, 0.0, 300.0], "angles_deg": [10.0, 0.0, 0.0], "converged": True}]
    return measure(frames, GroundTruth(0.0, 0.0, 300.0, 10.0, 0.0, 0.0, "alpha"), method="ippe", note=note)


def test_a_note_longer_than_the_csv_limit_is_refused_when_logged_not_after(tmp_path, camera_vga):
    # Once "logged", after which the session could not be opened or analysed (_csv.Error).
    session = make(tmp_path, camera_vga)
    before = session.rows_path.read_bytes()
    with pytest.raises(SessionError, match=rf"row 1: field 'note' is {MAX_FIELD_CHARS + 1} characters long"):
        session.log(a_row(note="x" * (MAX_FIELD_CHARS + 1)))
    assert session.rows_path.read_bytes() == before and session.rows == [] and not session.pending
    outcome = session.log(a_row(note="fine"))
    assert outcome.ok and outcome.row == 1  # numbering did not skip
    session.close()
    _, content = read_session(session.path)
    assert [r.number for r in content.rows] == [1]


def test_a_rows_file_saved_by_a_spreadsheet_with_a_bom_is_read(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    assert session.log(a_row()).ok
    session.close()
    data = session.rows_path.read_bytes()
    session.rows_path.write_bytes(b"\xef\xbb\xbf" + data)  # "CSV UTF-8" of a spreadsheet
    _, content = read_session(session.path)
    assert [r.number for r in content.rows] == [1] and content.warnings == []
    reopened = Session.open(session.path)  # and logging goes on after it
    assert reopened.log(a_row()).ok and reopened.next_row == 3
    reopened.close()


def _with_pass(session, text):
    session.close()
    lines = session.rows_path.read_text().splitlines(keepends=True)
    header = lines[0].strip().split(",")
    fields = lines[1].rstrip("\n").split(",")
    fields[header.index("pass")] = text
    session.rows_path.write_text(lines[0] + ",".join(fields) + "\n")


PASS_WORDS = [
    ("yes", True, "read as passed"),
    ("FAIL", False, "read as failed"),
    ("maybe", False, "counted as failed"),
]


@pytest.mark.parametrize(("text", "passed", "word"), PASS_WORDS)
def test_pass_words_are_read_with_a_word_never_silently(tmp_path, camera_vga, text, passed, word):
    # Once `pass=yes` counted as a fail without a word.
    session = make(tmp_path, camera_vga)
    assert session.log(a_row()).ok
    _with_pass(session, text)
    _, content = read_session(session.path)
    assert content.rows[0].passed is passed
    assert any(f"row 1 has pass {text!r}" in w and word in w for w in content.warnings), content.warnings


def test_a_line_with_a_field_beyond_the_csv_limit_is_a_warning_not_a_crash(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    assert session.log(a_row()).ok
    session.close()
    with session.rows_path.open("a") as handle:  # written by another program
        handle.write("2,t,alpha," + '"' + "y" * (MAX_FIELD_CHARS + 10) + '"\n')
    _, content = read_session(session.path)
    assert [r.number for r in content.rows] == [1]
    assert any("line 3: not a CSV record" in w for w in content.warnings)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"side_mm": "50"}, "field 'side_mm' must be a number, got text '50'"),
        ({"side_mm": 1e-300}, "QR side 1e-300 mm is below"),
        ({"name": ["a"]}, "field 'name' must be text, got a list of 1"),
        ({"solver": "ippe"}, "field 'solver' must be a JSON object, got text 'ippe'"),
        ({"frames_per_row": 2.5}, "field 'frames_per_row' must be a whole number"),
        ({"camera": {"width": 640}}, "camera: missing field 'height'"),
    ],
)
def test_session_file_values_of_the_wrong_type_are_named(tmp_path, camera_vga, change, message, capsys):
    session = make(tmp_path, camera_vga)
    session.close()
    info_path = session.path / "session.json"
    info_path.write_text(json.dumps({**json.loads(info_path.read_text()), **change}))
    with pytest.raises(SessionError, match=r"session\.json") as exc:
        read_session(session.path)
    assert message in str(exc.value)
    assert main(["analyze", str(session.path), "--no-simulation"]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_a_deeply_nested_session_file_is_a_clear_error(tmp_path, camera_vga, capsys):
    session = make(tmp_path, camera_vga)
    session.close()
    (session.path / "session.json").write_text("[" * 50_000 + "]" * 50_000)
    assert main(["analyze", str(session.path)]) == 2
    err = capsys.readouterr().err
    assert "nested 50000 levels deep" in err and "Recursion" not in err


def test_analyze_out_creates_the_named_folder_only(tmp_path, camera_vga, capsys):
    session = make(tmp_path, camera_vga)
    assert session.log(a_row()).ok
    session.close()
    deep = tmp_path / "no" / "such" / "plots"
    assert main(["analyze", str(session.path), "--no-simulation", "--out", str(deep)]) == 2
    assert "does not exist" in capsys.readouterr().err and not (tmp_path / "no").exists()
    assert main(["analyze", str(session.path), "--no-simulation", "--out", str(tmp_path / "plots")]) == 0
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == [
        "errors_vs_tilt.png",
        "measured_vs_truth.png",
    ]
