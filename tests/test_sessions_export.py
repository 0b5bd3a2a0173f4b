"""The clean export of a session: only the rows in force, units in the column names, values as
rows.csv holds them; checked against a rows.csv and an expected file written here by hand."""

from __future__ import annotations

import csv
import io

import pytest

from qrfield.sessions import Session, SessionError
from qrfield.sessions.export import column_with_unit, export_path, export_session

# A rows.csv as the store writes it (docs/conventions.md's columns, then the extra ones): row 1
# passes, row 2 is withdrawn by the record on the last line, row 3 had no converged frame and a
# note with a comma and quotes, row 4 passes. Typed by hand, not written by the code under test.
HEADER = (
    "row,time,combo,gt_x,gt_y,gt_z,gt_alpha,gt_beta,gt_gamma,x,y,z,alpha,beta,gamma,n_frames,"
    "n_converged,err_pos,err_alpha,err_beta,err_gamma,pass,note,std_x,std_y,std_z,std_alpha,"
    "std_beta,std_gamma,mean_iterations,reprojection_px,method,withdraws"
)
ROWS_CSV = (
    HEADER
    + "\n"
    + "1,2026-11-22T10:31:00+01:00,beta,0.000,0.000,300.000,0.000,40.000,0.000,0.100,-0.200,300.500,"
    "0.100,40.300,-0.100,10,10,0.548,0.100,0.300,-0.100,1,,0.010,0.020,0.030,0.040,0.050,0.060,"
    "3.00,0.120,numerical,\n"
    + "2,2026-11-22T10:32:00+01:00,beta,0.000,0.000,300.000,0.000,50.000,0.000,0.000,0.000,309.000,"
    "0.000,50.000,0.000,10,10,9.000,0.000,0.000,0.000,0,z typo,0.010,0.010,0.010,0.010,0.010,0.010,"
    "3.00,0.110,numerical,\n"
    + "3,2026-11-22T10:33:00+01:00,beta,0.000,0.000,300.000,0.000,80.000,0.000,,,,,,,10,0,,,,,0,"
    '"glare, ""bad"" light",,,,,,,,,numerical,\n'
    + "4,2026-11-22T10:34:00+01:00,alpha+beta-,10.000,-5.000,320.000,20.000,-20.000,0.000,10.200,"
    "-5.100,321.000,20.500,-19.800,0.100,10,9,1.025,0.500,0.200,0.100,1,,0.100,0.100,0.200,0.300,"
    "0.100,0.100,4.50,0.200,numerical,\n"
    + ",2026-11-22T10:35:00+01:00,,,,,,,,,,,,,,,,,,,,,withdraws row 2 (undo),,,,,,,,,,2\n"
)
EXPECTED = (
    "row,time,combo,gt_x_mm,gt_y_mm,gt_z_mm,gt_alpha_deg,gt_beta_deg,gt_gamma_deg,x_mm,y_mm,z_mm,"
    "alpha_deg,beta_deg,gamma_deg,n_frames,n_converged,err_pos_mm,err_alpha_deg,err_beta_deg,"
    "err_gamma_deg,pass,note,std_x_mm,std_y_mm,std_z_mm,std_alpha_deg,std_beta_deg,std_gamma_deg,"
    "mean_iterations,reprojection_px,method\n"
    "1,2026-11-22T10:31:00+01:00,beta,0.000,0.000,300.000,0.000,40.000,0.000,0.100,-0.200,300.500,"
    "0.100,40.300,-0.100,10,10,0.548,0.100,0.300,-0.100,1,,0.010,0.020,0.030,0.040,0.050,0.060,"
    "3.00,0.120,numerical\n"
    "3,2026-11-22T10:33:00+01:00,beta,0.000,0.000,300.000,0.000,80.000,0.000,,,,,,,10,0,,,,,0,"
    '"glare, ""bad"" light",,,,,,,,,numerical\n'
    "4,2026-11-22T10:34:00+01:00,alpha+beta-,10.000,-5.000,320.000,20.000,-20.000,0.000,10.200,"
    "-5.100,321.000,20.500,-19.800,0.100,10,9,1.025,0.500,0.200,0.100,1,,0.100,0.100,0.200,0.300,"
    "0.100,0.100,4.50,0.200,numerical\n"
)


@pytest.fixture
def session_dir(tmp_path, camera_vga):
    """A session folder whose rows.csv is the hand-written one above."""
    with Session.create(tmp_path, "export", camera=camera_vga, side_mm=50.0, solver="numerical") as session:
        folder = session.path
    (folder / "rows.csv").write_text(ROWS_CSV, encoding="utf-8")
    return folder


def test_the_export_holds_the_rows_in_force_with_units_in_the_names(session_dir, tmp_path) -> None:
    before = (session_dir / "rows.csv").read_bytes()
    out = tmp_path / "out" / "rows-clean.csv"  # its folder does not exist yet
    assert export_session(session_dir, out) == 3
    assert out.read_bytes() == EXPECTED.encode("utf-8")  # UTF-8, no byte-order mark
    assert (session_dir / "rows.csv").read_bytes() == before  # rows.csv keeps its format


def test_the_export_reads_back_with_csv(session_dir, tmp_path) -> None:
    out = tmp_path / "clean.csv"
    export_session(session_dir, out)
    with open(out, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["row"] for r in rows] == ["1", "3", "4"]
    assert rows[1]["note"] == 'glare, "bad" light' and rows[1]["x_mm"] == ""
    assert float(rows[2]["err_pos_mm"]) == 1.025 and float(rows[0]["gt_beta_deg"]) == 40.0
    assert "withdraws" not in rows[0] and all(r["row"] for r in rows)


def test_the_export_reads_back_with_pandas(session_dir, tmp_path) -> None:
    pandas = pytest.importorskip("pandas", reason="pandas is not a dependency of qrfield")
    out = tmp_path / "clean.csv"
    export_session(session_dir, out)
    frame = pandas.read_csv(out)
    assert list(frame["row"]) == [1, 3, 4] and frame["z_mm"].isna().tolist() == [False, True, False]
    assert frame["gt_z_mm"].dtype.kind == "f" and frame.loc[2, "err_alpha_deg"] == 0.5


def test_a_folder_as_target_gets_rows_clean_csv(session_dir, tmp_path) -> None:
    target = tmp_path / "exports"
    target.mkdir()
    assert export_path(session_dir, target) == target / "rows-clean.csv"
    assert export_session(session_dir, target) == 3
    first_line = io.StringIO((target / "rows-clean.csv").read_text()).readline()
    assert first_line.startswith("row,time,combo,gt_x_mm")


def test_the_session_own_files_are_never_overwritten(session_dir) -> None:
    before = (session_dir / "rows.csv").read_bytes()
    for name in ("rows.csv", "session.json"):
        with pytest.raises(SessionError, match="own"):
            export_session(session_dir, session_dir / name)
    assert (session_dir / "rows.csv").read_bytes() == before


def test_a_folder_that_is_no_session_is_named(tmp_path) -> None:
    with pytest.raises(SessionError, match=r"session\.json"):
        export_session(tmp_path, tmp_path / "out.csv")
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize(
    ("column", "named"),
    [
        ("gt_x", "gt_x_mm"),
        ("x", "x_mm"),
        ("err_pos", "err_pos_mm"),
        ("std_gamma", "std_gamma_deg"),
        ("alpha", "alpha_deg"),
        ("reprojection_px", "reprojection_px"),
        ("n_frames", "n_frames"),
        ("pass", "pass"),
        ("mean_iterations", "mean_iterations"),
    ],
)
def test_column_names_carry_their_unit(column, named) -> None:
    assert column_with_unit(column) == named


def test_the_session_export_command_writes_the_same_file(session_dir, tmp_path, capsys) -> None:
    from qrfield.cli import main

    out = tmp_path / "clean.csv"
    assert main(["session", "export", str(session_dir), "--out", str(out)]) == 0
    assert out.read_bytes() == EXPECTED.encode("utf-8")
    assert f"exported 3 rows to {out}" in capsys.readouterr().out
    # A folder that does not hold a session is one clear error, and nothing is written.
    assert main(["session", "export", str(tmp_path / "nothing"), "--out", str(tmp_path / "x.csv")]) == 2
    assert not (tmp_path / "x.csv").exists()
    # Folders above the one named are never created (the shared folder rule).
    deep = tmp_path / "a" / "b" / "c.csv"
    assert main(["session", "export", str(session_dir), "--out", str(deep)]) != 0
    assert not (tmp_path / "a").exists()
