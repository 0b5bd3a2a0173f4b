"""``qrfield session new|log|undo|list|show`` on the virtual bench, without a screen.

Truth: the virtual bench's own pose (docs/conventions.md frames; mm and degrees) and the rows as
read back by csv, not by the session code.
"""

from __future__ import annotations

import csv
import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from qrfield.cli import main

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]
REPO = Path(__file__).resolve().parent.parent
BENCH = {"x": 10.0, "y": -5.0, "z": 300.0, "alpha": 15.0, "beta": -20.0, "gamma": 10.0}  # its defaults


def rows_of(folder: Path) -> list[dict[str, str]]:
    with open(folder / "rows.csv", newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def new_session(tmp_path: Path, capsys, *extra: str) -> Path:
    args = [
        "session",
        "new",
        str(tmp_path / "root"),
        "--name",
        "cli test",
        "--config-dir",
        str(tmp_path / "cfg"),
    ]
    assert main([*args, *extra]) == 0
    out = capsys.readouterr()
    folder = Path(out.out.strip())
    assert folder.parent == tmp_path / "root" and folder.name.endswith("-cli-test")
    return folder


def log_args(folder: Path, tmp_path: Path, *extra: str) -> list[str]:
    return [
        "session",
        "log",
        str(folder),
        "--source",
        "virtual",
        "--config-dir",
        str(tmp_path / "cfg"),
        *extra,
    ]


def test_new_then_log_measures_the_bench_with_the_sessions_setup(tmp_path: Path, capsys) -> None:
    folder = new_session(tmp_path, capsys, "--side-mm", "50", "--method", "ippe", "--frames-per-row", "4",
                         "--max-angle-error-deg", "1.5")  # fmt: skip
    meta = json.loads((folder / "session.json").read_text())
    assert (meta["side_mm"], meta["solver"]["method"], meta["frames_per_row"]) == (50.0, "ippe", 4)
    assert meta["criteria"]["max_angle_error_deg"] == 1.5 and meta["camera"]["width"] == 640
    truth = "--truth=10,-5,300,15,-20,10"
    assert (
        main(log_args(folder, tmp_path, truth, "--combo", "alpha+beta-gamma+", "--note", "first card")) == 0
    )
    out = capsys.readouterr()
    assert out.out.startswith("logged row 1: pass")
    (row,) = rows_of(folder)
    assert (row["row"], row["combo"], row["note"], row["method"]) == (
        "1",
        "alpha+beta-gamma+",
        "first card",
        "ippe",
    )
    assert (row["n_frames"], row["n_converged"], row["pass"]) == ("4", "4", "1")
    for name, value in BENCH.items():
        assert float(row[f"gt_{name}"]) == value
    measured = np.array([float(row[k]) for k in BENCH])
    assert np.linalg.norm(measured[:3] - np.array(list(BENCH.values())[:3])) < 5.0
    assert np.all(np.abs(measured[3:] - np.array(list(BENCH.values())[3:])) <= 1.5)
    # A negative truth (given with '='), the bench's own truth, and --frames.
    assert (
        main(log_args(folder, tmp_path, "--truth=-10,5,300,0,0,0", "--combo", "beta", "--frames", "2")) == 0
    )
    assert capsys.readouterr().out.startswith("logged row 2: fail")  # the bench is not at that pose
    assert (
        main(
            log_args(
                folder, tmp_path, "--truth", "bench", "--combo", "gamma", "--frames", "3", "--force-combo"
            )
        )
        == 0
    )
    assert capsys.readouterr().out.startswith("logged row 3: pass")
    rows = rows_of(folder)
    assert (rows[1]["gt_x"], rows[1]["n_frames"], rows[1]["pass"]) == ("-10.000", "2", "0")
    assert [float(rows[2][f"gt_{k}"]) for k in BENCH] == list(BENCH.values())


def test_a_bad_truth_names_each_field_and_logs_nothing(tmp_path: Path, capsys) -> None:
    folder = new_session(tmp_path, capsys)
    code = main(log_args(folder, tmp_path, "--truth=10,-5,3o0,15,-95,10", "--combo", "nope"))
    err = capsys.readouterr().err
    assert code == 2
    assert "z: '3o0' is not a number" in err and "beta: -95 deg is outside -90..90" in err
    assert "combo: 'nope' is not a known combination" in err
    assert main(log_args(folder, tmp_path, "--truth=1,2,3", "--combo", "alpha")) == 2
    assert "give 6 numbers" in capsys.readouterr().err
    assert rows_of(folder) == []


def test_a_mistyped_virtual_truth_is_named_as_such(tmp_path: Path, capsys) -> None:
    """``--truth virtal`` (a typo of 'virtual') is told apart from a short list of numbers."""
    folder = new_session(tmp_path, capsys)
    assert main(log_args(folder, tmp_path, "--truth", "virtal", "--combo", "alpha")) == 2
    err = capsys.readouterr().err
    assert "'virtal': did you mean 'virtual'?" in err and "or 'virtual' for the virtual bench" in err
    assert main(log_args(folder, tmp_path, "--truth", "1,2,3", "--combo", "alpha")) == 2
    err = capsys.readouterr().err
    assert "did you mean" not in err and "give 6 numbers" in err
    assert rows_of(folder) == []


def test_a_name_without_ascii_letters_is_refused_saying_folder_names_are_ascii(
    tmp_path: Path, capsys
) -> None:
    args = ["session", "new", str(tmp_path / "root"), "--config-dir", str(tmp_path / "cfg")]
    assert main([*args, "--name", "测试"]) == 2
    err = capsys.readouterr().err
    assert "folder names are ASCII-only" in err and "has no letters or digits" not in err
    assert not (tmp_path / "root").exists() or not any((tmp_path / "root").iterdir())


def test_truth_takes_semicolons_and_spaces_as_every_list_does(tmp_path: Path, capsys) -> None:
    """docs/cli.md: lists are separated by commas, semicolons or spaces; --truth too (audit-2).
    Each field is then checked on its own: the out-of-range beta is named, not the list's shape."""
    folder = new_session(tmp_path, capsys)
    for truth in ("10;-5;300;15;-95;10", "10 -5 300 15 -95 10", "10, -5; 300 15,-95,10"):
        assert main(log_args(folder, tmp_path, f"--truth={truth}", "--combo", "alpha")) == 2
        err = capsys.readouterr().err
        assert "beta: -95 deg is outside -90..90" in err and "give 6 numbers" not in err, truth
    assert rows_of(folder) == []


@pytest.mark.slow
def test_a_truth_with_spaces_logs_the_numbers_typed(tmp_path: Path, capsys) -> None:
    folder = new_session(tmp_path, capsys)
    argv = log_args(folder, tmp_path, "--truth", "10 -5 300 0 0 0", "--combo", "alpha", "--frames", "1")
    assert main([*argv, "--force-combo"]) == 0
    (row,) = rows_of(folder)
    assert [float(row[f"gt_{k}"]) for k in BENCH] == [10.0, -5.0, 300.0, 0.0, 0.0, 0.0]


def test_a_row_is_logged_only_once_it_is_on_disk(tmp_path: Path, capsys, monkeypatch) -> None:
    from qrfield.sessions.files import FileOps

    folder = new_session(tmp_path, capsys)

    def full_disk(self, fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(FileOps, "fsync", full_disk)
    code = main(
        log_args(
            folder, tmp_path, "--truth=10,-5,300,15,-20,10", "--combo", "alpha+beta-gamma+", "--frames", "2"
        )
    )
    out = capsys.readouterr()
    assert code == 1 and "logged row" not in out.out
    assert "NOT logged" in out.err and "disk full" in out.err
    # Words for a process that is ending, not the app's "kept in memory ... Retry. Do not close the app".
    assert "Retry" not in out.err and "close the app" not in out.err and "kept in memory" not in out.err
    assert "nothing of the row was left in rows.csv" in out.err
    assert "unwritten line of rows.csv: 1," in out.err  # the row is not lost: the operator has it


def test_an_undo_that_cannot_be_written_says_so_in_a_commands_words(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    """audit-1: a failed `session undo` printed the app's advice ("kept in memory ... Retry. Do not
    close the app") from a process that was exiting, losing the record it said it kept."""
    from qrfield.sessions.files import FileOps

    folder = new_session(tmp_path, capsys)
    truth = ["--truth=10,-5,300,15,-20,10", "--combo", "alpha+beta-gamma+", "--frames", "2"]
    assert main(log_args(folder, tmp_path, *truth)) == 0
    capsys.readouterr()
    before = (folder / "rows.csv").read_bytes()

    def full_disk(self, fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    with monkeypatch.context() as patch:
        patch.setattr(FileOps, "fsync", full_disk)
        assert main(["session", "undo", str(folder)]) == 1
    err = capsys.readouterr().err
    assert "NOT withdrawn" in err and "disk full" in err and "row 1 stays in force" in err
    assert "Retry" not in err and "close the app" not in err and "kept in memory" not in err
    assert (folder / "rows.csv").read_bytes() == before  # nothing torn, the row still in force
    assert main(["session", "undo", str(folder)]) == 0  # once it can be written, undo works
    assert [r["withdraws"] for r in rows_of(folder)] == ["", "1"]


def test_undo_list_and_show(tmp_path: Path, capsys) -> None:
    folder = new_session(tmp_path, capsys)
    # `--truth virtual` names the virtual bench's pose; `bench`, its older spelling, still works.
    for row, (combo, truth) in enumerate((("alpha+beta-gamma+", "virtual"), ("beta", "bench")), start=1):
        force = ["--force-combo"] if combo == "beta" else []
        assert (
            main(log_args(folder, tmp_path, "--truth", truth, "--combo", combo, "--frames", "2", *force)) == 0
        )
        assert capsys.readouterr().out.startswith(f"logged row {row}: pass")
    capsys.readouterr()
    assert main(["session", "undo", str(folder)]) == 0
    assert capsys.readouterr().out.startswith("withdrew row 2")
    rows = rows_of(folder)
    assert len(rows) == 3 and rows[2]["withdraws"] == "2" and rows[2]["row"] == ""
    assert main(["session", "list", str(tmp_path / "root")]) == 0
    assert (
        f"{folder.name}  numerical, 50 mm, picam-v2@640x480: 1 rows, 1 pass, 1 withdrawn"
        in capsys.readouterr().out
    )
    assert main(["session", "show", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "solver numerical, 10 frames per row, criteria 2°/5 mm" in out
    assert "withdrawn" in out.splitlines()[-1] and "   1 alpha+beta-gamma+" in out
    assert main(["session", "undo", str(folder)]) == 0 and main(["session", "undo", str(folder)]) == 2
    assert "nothing to undo" in capsys.readouterr().err


def test_interactive_log_asks_each_field_with_the_forms_checks(tmp_path: Path, capsys) -> None:
    folder = new_session(tmp_path, capsys)
    # Row 1: z, combo and the note (bytes that are not UTF-8: it was refused only after the
    # row was measured) typed wrong once each; then Enter for the next row, Enter x 8 (keep
    # every value) for row 2, and q.
    first = ["10", "-5", "3o0", "300", "15", "-20", "10", "nope", "alpha+beta-gamma+", "bad \udcff note"]
    answers = [*first, "typed by hand", "", *[""] * 8, "q"]
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONIOENCODING="utf-8:surrogateescape")
    done = subprocess.run(
        [sys.executable, "-m", "qrfield", *log_args(folder, tmp_path, "--frames", "2")],
        input=("\n".join(answers) + "\n").encode("utf-8", "surrogateescape"),
        capture_output=True,
        timeout=90,
        env=env,
    )
    done.stdout, done.stderr = (out.decode("utf-8", "replace") for out in (done.stdout, done.stderr))
    assert done.returncode == 0, done.stderr
    assert (
        "z: '3o0' is not a number" in done.stdout
        and "combo: 'nope' is not a known combination" in done.stdout
        and "note: not UTF-8 text (character 5 is U+DCFF, the byte 0xFF" in done.stdout
    )
    assert done.stdout.count("logged row") == 2  # the second row kept every value (Enter), then q
    rows = rows_of(folder)
    assert [r["combo"] for r in rows] == ["alpha+beta-gamma+"] * 2 and rows[0]["note"] == "typed by hand"
    assert [float(rows[1][f"gt_{k}"]) for k in BENCH] == list(BENCH.values())


def test_interactive_log_asks_again_only_the_combination_its_angles_contradict(
    tmp_path: Path, capsys
) -> None:
    """audit-1: a combination the angles contradict was refused only after the note, and then the
    whole row was asked again from x, so the next answer typed (the right combination) went into
    the note and the one after into x."""
    folder = new_session(tmp_path, capsys)
    # (15, -20, 10) deg has the signs of alpha+beta-gamma+, not of 'alpha' (docs/app.md, item 4).
    answers = ["10", "-5", "300", "15", "-20", "10", "alpha", "alpha+beta-gamma+", "second card", "q"]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(
        [sys.executable, "-m", "qrfield", *log_args(folder, tmp_path, "--frames", "2")],
        input="\n".join(answers) + "\n",
        capture_output=True,
        text=True,
        timeout=90,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    assert "they fit 'alpha+beta-gamma+'" in done.stdout and done.stdout.count("logged row") == 1
    (row,) = rows_of(folder)
    assert (row["combo"], row["note"]) == ("alpha+beta-gamma+", "second card")
    assert [float(row[f"gt_{k}"]) for k in BENCH] == list(BENCH.values())


def test_new_and_list_use_the_apps_sessions_folder(tmp_path: Path, capsys, monkeypatch) -> None:
    """Issue 23: both needed a ROOT folder; the app's folder is $QRFIELD_SESSIONS_DIR, else the one
    chosen in the app (app.json), else ~/.local/share/qrfield/sessions."""
    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "shared"))
    config = ["--config-dir", str(tmp_path / "cfg")]
    assert main(["session", "new", "--name", "by default", *config]) == 0
    folder = Path(capsys.readouterr().out.strip())
    assert folder.parent == tmp_path / "shared"
    assert main(["session", "list", *config]) == 0
    out = capsys.readouterr()
    assert folder.name in out.out and str(tmp_path / "shared") in out.err
    # A folder chosen in the app (its Session tab saves it in app.json) is used the same way.
    (tmp_path / "cfg").mkdir(exist_ok=True)
    (tmp_path / "cfg" / "app.json").write_text(
        json.dumps({"session_folder": {"root": str(tmp_path / "chosen")}})
    )
    assert main(["session", "new", "--name", "chosen", *config]) == 0
    assert Path(capsys.readouterr().out.strip()).parent == tmp_path / "chosen"


def test_export_without_out_writes_beside_rows_csv_and_never_overwrites(tmp_path: Path, capsys) -> None:
    folder = new_session(tmp_path, capsys)
    assert (
        main(
            log_args(folder, tmp_path, "--truth", "virtual", "--combo", "alpha+beta-gamma+", "--frames", "1")
        )
        == 0
    )
    capsys.readouterr()
    assert main(["session", "export", str(folder)]) == 0
    assert capsys.readouterr().out.strip() == f"exported 1 rows to {folder / 'rows-clean.csv'}"
    with open(folder / "rows-clean.csv", newline="", encoding="utf-8") as f:
        (row,) = list(csv.DictReader(f))
    assert row["combo"] == "alpha+beta-gamma+" and float(row["gt_z_mm"]) == 300.0
    before = (folder / "rows-clean.csv").read_bytes()
    assert main(["session", "export", str(folder)]) == 2
    assert "exists; choose another name, or add --force" in capsys.readouterr().err
    assert main(["session", "export", str(folder), "--force"]) == 0
    assert (folder / "rows-clean.csv").read_bytes() == before


def test_a_combination_its_angles_contradict_is_refused_unless_forced(tmp_path: Path, capsys) -> None:
    """Issue 23: `--combo alpha` with beta 30 was logged without a word; the app asks first. The
    rule and its words are the core's (qrfield.sessions.combo_signs), which the app shows too."""
    from qrfield.sessions.combo_signs import combination_mismatch, sign_table

    folder = new_session(tmp_path, capsys)
    argv = log_args(folder, tmp_path, "--truth=10,-5,300,0,30,0", "--combo", "alpha", "--frames", "1")
    assert main(argv) == 2
    err = capsys.readouterr().err
    words = combination_mismatch("alpha", (0.0, 30.0, 0.0), sign_table())
    assert (
        words
        == "the angles (0, 30, 0) deg have the signs α0 β+ γ0, but 'alpha' means α+ β0 γ0; they fit 'beta'"
    )
    assert f"not logged: {words}" in err and "--force-combo" in err and err.count("\n") == 1
    assert rows_of(folder) == []
    assert main([*argv, "--force-combo"]) == 0
    assert [r["combo"] for r in rows_of(folder)] == ["alpha"]
    # The bench's own pose (15, -20, 10 deg) is known only once measured: checked before it is logged.
    assert main(log_args(folder, tmp_path, "--truth", "virtual", "--combo", "gamma", "--frames", "1")) == 2
    assert "they fit 'alpha+beta-gamma+'" in capsys.readouterr().err and len(rows_of(folder)) == 1


def test_interactive_log_never_offers_a_withdrawn_rows_values(tmp_path: Path, capsys) -> None:
    folder = new_session(tmp_path, capsys)
    for truth in ("--truth=10,-5,300,15,-20,10", "--truth=20,-5,300,15,-20,10"):
        assert main(log_args(folder, tmp_path, truth, "--combo", "alpha+beta-gamma+", "--frames", "1")) == 0
    assert main(["session", "undo", str(folder)]) == 0  # row 2 (x = 20) was wrong
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(
        [sys.executable, "-m", "qrfield", *log_args(folder, tmp_path, "--frames", "1")],
        input="\n" * 8 + "q\n",
        capture_output=True,
        text=True,
        timeout=90,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    assert "x (mm) [10.000]" in done.stdout and "[20.000]" not in done.stdout
    rows = [r for r in rows_of(folder) if r["row"]]
    assert [r["gt_x"] for r in rows] == ["10.000", "20.000", "10.000"]


def test_a_file_source_that_ends_before_the_row_says_how_far_it_got(tmp_path: Path, capsys) -> None:
    """A folder of 2 images (no code in them) gives 2 frames; a row of 5 frames cannot fill: the
    message says 2 of 5 and how to ask for fewer or repeat them, and nothing is logged."""
    import cv2

    folder = new_session(tmp_path, capsys)
    images = tmp_path / "frames"
    images.mkdir()
    for i in range(2):
        cv2.imwrite(str(images / f"f{i}.png"), np.full((480, 640), 110, np.uint8))
    args = log_args(folder, tmp_path, "--truth", "10,-5,300,15,-20,10", "--combo", "alpha+beta-gamma+")
    args[args.index("virtual")] = str(images)
    assert main([*args, "--frames", "5"]) == 1
    err = capsys.readouterr().err
    assert (
        "nothing logged: the frame loop ended (the source stopped or failed) after 2 of the row's 5 frames"
        in err
    )
    assert "--frames N asks for fewer, --loop repeats it" in err
    assert rows_of(folder) == []


def test_list_of_a_file_says_it_is_not_a_folder(tmp_path: Path, capsys) -> None:
    """``session list FILE`` (e.g. a session's session.json) exists: not "no such folder"."""
    folder = new_session(tmp_path, capsys)
    assert main(["session", "list", str(folder / "session.json")]) == 2
    err = capsys.readouterr().err
    assert "session.json: not a folder (give the folder that holds the sessions)" in err
    assert main(["session", "list", str(tmp_path / "nowhere")]) == 2
    assert "nowhere: no such folder" in capsys.readouterr().err
