"""Session store: folders, session.json, the CSV's columns and values, resume, undo, faults."""

from __future__ import annotations

import contextlib
import csv
import datetime as dt
import errno
import json
import os
import re
import stat
import tempfile
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qrfield
from qrfield.sessions import (
    COLUMNS,
    REQUIRED_COLUMNS,
    AcceptanceCriteria,
    GroundTruth,
    Session,
    SessionError,
    measure,
    read_session,
)
from qrfield.sessions.files import FileOps

_DESIGN_TEXT = (  # the column list exactly as docs/conventions.md writes it
    "row,time,combo,gt_x,gt_y,gt_z,gt_alpha,gt_beta,gt_gamma,x,y,z,alpha,beta,gamma,n_frames,"
    "n_converged,err_pos,err_alpha,err_beta,err_gamma,pass,note"
)
DESIGN_COLUMNS = _DESIGN_TEXT.split(",")
NOW = dt.datetime(2026, 11, 22, 10, 30, 5)


def make(root, camera, name="bench run", **kwargs):
    return Session.create(
        root,
        name,
        camera=camera,
        side_mm=60.0,
        solver="numerical",
        solver_settings={"tf": 1.0, "n_max": 30},
        operator="A. Tester",
        notes="first try\nsecond line",
        now=kwargs.pop("now", NOW),
        **kwargs,
    )


def a_row(z=301.0, alpha=(179.0, -179.0), combo="alpha", note=""):
    frames = [
        {"position_mm": [1.0, 2.0, z - 1.0], "angles_deg": [alpha[0], 0.5, 0.0], "converged": True},
        {"position_mm": [1.0, 2.0, z + 1.0], "angles_deg": [alpha[1], 1.5, 0.0], "converged": True},
        {"position_mm": [0.0, 0.0, 0.0], "angles_deg": [0.0, 0.0, 0.0], "converged": False},
    ]
    return measure(
        frames, GroundTruth(0.0, 2.0, 300.0, 179.0, 0.0, 0.0, combo), method="numerical", note=note
    )


def csv_rows(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.reader(fh))


def test_create_writes_session_json_and_the_header(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga, name="bench run #1 (tilt)")
    assert session.path.name == "20261122-103005-bench-run-1-tilt"
    assert session.path.parent == tmp_path
    meta = json.loads((session.path / "session.json").read_text(encoding="utf-8"))
    assert meta["camera"] == camera_vga.to_dict()
    assert meta["side_mm"] == 60.0
    assert meta["solver"]["method"] == "numerical"
    # The settings given, completed with the solver's defaults when qrfield.solvers is installed.
    assert {"tf": 1.0, "n_max": 30}.items() <= meta["solver"]["settings"].items()
    assert meta["app_version"] == qrfield.__version__
    assert meta["operator"] == "A. Tester"
    assert meta["notes"] == "first try\nsecond line"
    assert meta["name"] == "bench run #1 (tilt)"
    assert meta["created"].startswith("2026-11-22T10:30:05")
    assert meta["criteria"] == {"max_angle_error_deg": 2.0, "max_position_error_mm": 5.0}
    header = csv_rows(session.rows_path)[0]
    assert header[: len(DESIGN_COLUMNS)] == DESIGN_COLUMNS
    assert list(REQUIRED_COLUMNS) == DESIGN_COLUMNS
    assert header == list(COLUMNS)
    assert not any(p.name.startswith(".") for p in session.path.iterdir())  # no temp files left
    session.close()


def test_an_existing_session_is_never_overwritten(tmp_path, camera_vga):
    first = make(tmp_path, camera_vga)
    first.log(a_row())
    first.close()
    before = {p.name: p.read_bytes() for p in first.path.iterdir()}
    second = make(tmp_path, camera_vga)  # same name, same second
    assert second.path != first.path
    assert second.path.name == "20261122-103006-bench-run"  # the next free second
    assert {p.name: p.read_bytes() for p in first.path.iterdir()} == before
    second.close()


def test_bad_arguments_are_named(tmp_path, camera_vga):
    with pytest.raises(SessionError, match="no letters or digits"):
        make(tmp_path, camera_vga, name=" /// ")
    # Letters, but none ASCII: the message says that folder names are ASCII-only (audit-2).
    with pytest.raises(SessionError, match="no ASCII letters or digits: folder names are ASCII-only"):
        make(tmp_path, camera_vga, name="测试")
    with pytest.raises(SessionError, match="positive length"):
        Session.create(tmp_path, "x", camera=camera_vga, side_mm=0, solver="numerical")
    with pytest.raises(SessionError, match="solver 'pnp'"):
        Session.create(tmp_path, "x", camera=camera_vga, side_mm=60, solver="pnp")
    with pytest.raises(SessionError, match="not a session"):
        Session.open(tmp_path)


def test_a_logged_row_has_the_hand_computed_values(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    outcome = session.log(a_row(note="card\nre-taped\u2028again"), time_text="2026-11-22T10:31:00+00:00")
    assert outcome.ok and outcome.status == "logged" and outcome.row == 1
    assert outcome.message == "logged row 1"
    assert session.rows_path.read_bytes().count(b"\n") == 2
    header, line = csv_rows(session.rows_path)
    row = dict(zip(header, line, strict=True))
    # Frames: positions (1,2,300) and (1,2,302) -> mean (1,2,301); alpha 179 and -179 -> 180;
    # beta 0.5 and 1.5 -> 1; truth (0,2,300, 179,0,0): err_pos = |(1,0,1)| = sqrt(2) = 1.414 mm,
    # err_alpha = +1, err_beta = +1, err_gamma = 0 -> pass. Sample deviations: z sqrt(2), alpha sqrt(2).
    expected = {
        "row": "1",
        "time": "2026-11-22T10:31:00+00:00",
        "combo": "alpha",
        "gt_x": "0.000",
        "gt_y": "2.000",
        "gt_z": "300.000",
        "gt_alpha": "179.000",
        "gt_beta": "0.000",
        "gt_gamma": "0.000",
        "x": "1.000",
        "y": "2.000",
        "z": "301.000",
        "alpha": "180.000",
        "beta": "1.000",
        "gamma": "0.000",
        "n_frames": "3",
        "n_converged": "2",
        "err_pos": "1.414",
        "err_alpha": "1.000",
        "err_beta": "1.000",
        "err_gamma": "0.000",
        "pass": "1",
        "note": "card re-taped again",  # kept to one line: every record is one physical line
        "std_z": "1.414",
        "std_alpha": "1.414",
        "std_beta": "0.707",
        "method": "numerical",
        "withdraws": "",
        "sigma_x": "",  # these frames report no uncertainty of their own
        "sigma_gamma": "",
    }
    assert {k: row[k] for k in expected} == expected
    session.close()


def test_sigma_columns_follow_the_required_and_std_columns_and_hold_the_mean_frame_uncertainty(
    tmp_path, camera_vga
):
    # docs/conventions.md's required columns first, unchanged; std_* (frame-to-frame) keep their
    # names; the per-frame uncertainty is sigma_*, a name that cannot be taken for a spread.
    assert COLUMNS[: len(REQUIRED_COLUMNS)] == REQUIRED_COLUMNS and REQUIRED_COLUMNS[-1] == "note"
    axes = ("x", "y", "z", "alpha", "beta", "gamma")
    assert all(f"std_{a}" in COLUMNS and f"sigma_{a}" in COLUMNS for a in axes)
    assert COLUMNS.index("sigma_x") > COLUMNS.index("std_gamma")
    session = make(tmp_path, camera_vga)
    frames = [
        {
            "position_mm": [1.0, 2.0, 300.0],
            "angles_deg": [0.0, 0.5, 0.0],
            "converged": True,
            "position_std_mm": [0.05, 0.07, 1.2],
            "angles_std_deg": [0.4, 0.3, 0.02],
        },
        {
            "position_mm": [1.0, 2.0, 302.0],
            "angles_deg": [0.0, 1.5, 0.0],
            "converged": True,
            "position_std_mm": [0.07, 0.09, 1.4],
            "angles_std_deg": [0.6, 0.5, 0.04],
        },
    ]
    assert session.log(measure(frames, GroundTruth(1.0, 2.0, 301.0, 0.0, 1.0, 0.0, "beta"))).ok
    header, line = csv_rows(session.rows_path)
    row = dict(zip(header, line, strict=True))
    assert [row[f"sigma_{a}"] for a in axes] == ["0.060", "0.080", "1.300", "0.500", "0.400", "0.030"]
    assert (row["std_z"], row["std_beta"]) == ("1.414", "0.707")  # sqrt(2), sqrt(0.5): the frames' spread
    session.close()


def test_resume_continues_numbering_after_withdrawn_rows(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    for _ in range(3):
        assert session.log(a_row()).ok
    assert session.undo().ok  # withdraws row 3
    session.close()
    again = Session.open(session.path)
    assert again.next_row == 4
    assert [(r.number, r.withdrawn) for r in again.rows] == [(1, False), (2, False), (3, True)]
    assert again.log(a_row()).row == 4
    again.close()
    numbers = [line[0] for line in csv_rows(session.rows_path)[1:]]
    assert numbers == ["1", "2", "3", "", "4"]


def test_undo_appends_a_withdrawal_and_keeps_the_line(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    session.log(a_row(z=301.0))
    session.log(a_row(z=310.0))
    before = session.rows_path.read_bytes()
    outcome = session.undo()
    assert outcome.ok and outcome.row == 2 and outcome.logged == ("w2",)
    after = session.rows_path.read_bytes()
    assert after.startswith(before)  # nothing rewritten
    header, *lines = csv_rows(session.rows_path)
    record = dict(zip(header, lines[-1], strict=True))
    assert record["row"] == "" and record["withdraws"] == "2" and "withdraws row 2" in record["note"]
    assert session.undo().row == 1  # the next undo withdraws the row before
    with pytest.raises(SessionError, match="nothing to undo"):
        session.undo()
    session.close()
    _, content = read_session(session.path)
    assert [r.withdrawn for r in content.rows] == [True, True]


def test_an_unfinished_last_line_is_moved_aside_not_dropped(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    session.log(a_row())
    session.close()
    good = session.rows_path.read_bytes()
    torn = b"2,2026-11-22T10:40:00+00:00,alpha,0.000,2.0"
    with open(session.rows_path, "ab") as fh:
        fh.write(torn)
    _, content = read_session(session.path)  # reading alone changes nothing
    assert content.partial == torn and session.rows_path.read_bytes() == good + torn
    again = Session.open(session.path)
    assert any("unfinished line" in w for w in again.warnings)
    aside = list(session.path.glob("rows.csv.partial-*"))
    assert len(aside) == 1 and aside[0].read_bytes() == torn
    assert session.rows_path.read_bytes() == good
    assert again.log(a_row()).row == 2
    again.close()
    assert [line[0] for line in csv_rows(session.rows_path)[1:]] == ["1", "2"]


def test_a_second_process_cannot_log_to_an_open_session(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    with pytest.raises(SessionError, match="another process"):
        Session.open(session.path)
    session.close()
    Session.open(session.path).close()


class FaultyOps(FileOps):
    """Fails the chosen call with an errno while ``fault`` is set; ``short`` writes half a line."""

    def __init__(self):
        self.fault: dict[str, int] = {}
        self.short = False

    def _maybe(self, call):
        if call in self.fault:
            raise OSError(self.fault[call], os.strerror(self.fault[call]))

    def open(self, path, flags, mode=0o644):
        self._maybe("open")
        return super().open(path, flags, mode)

    def write(self, fd, data):
        self._maybe("write")
        if self.short:
            return super().write(fd, data[: len(data) // 2])
        return super().write(fd, data)

    def fsync(self, fd):
        self._maybe("fsync")
        super().fsync(fd)


def test_a_full_disk_keeps_rows_pending_and_retries_them_in_order(tmp_path, camera_vga):
    ops = FaultyOps()
    session = make(tmp_path, camera_vga, file_ops=ops)
    assert session.log(a_row(z=301.0)).ok
    ops.fault = {"write": errno.ENOSPC}
    first = session.log(a_row(z=302.0))
    assert first.status == "pending" and not first.ok
    assert "NOT logged" in first.message and "disk full" in first.message
    assert first.pending == ("2",)
    second = session.log(a_row(z=303.0))
    assert second.pending == ("2", "3")
    assert [r.confirmed for r in session.rows] == [True, False, False]
    assert len(csv_rows(session.rows_path)) == 2  # header + row 1 only
    still = session.retry()
    assert still.status == "pending" and still.pending == ("2", "3")
    ops.fault = {}
    done = session.retry()
    assert done.ok and done.logged == ("2", "3") and done.pending == ()
    assert [line[11] for line in csv_rows(session.rows_path)[1:]] == ["301.000", "302.000", "303.000"]
    session.close()


def test_pending_rows_are_written_before_the_next_row(tmp_path, camera_vga):
    ops = FaultyOps()
    session = make(tmp_path, camera_vga, file_ops=ops)
    ops.fault = {"fsync": errno.EIO}  # written but not confirmed: must not be written twice
    assert session.log(a_row(z=301.0)).status == "pending"
    ops.fault = {}
    outcome = session.log(a_row(z=302.0))
    assert outcome.ok and outcome.logged == ("1", "2")
    lines = csv_rows(session.rows_path)[1:]
    assert [(line[0], line[11]) for line in lines] == [("1", "301.000"), ("2", "302.000")]
    assert not list(session.path.glob("rows.csv.partial-*"))  # the whole line was kept, not moved aside
    session.close()


def test_a_short_write_is_cut_back_at_once_and_the_row_written_whole(tmp_path, camera_vga):
    """Issue 23: a failed append leaves no torn line, not even until the next open (it stayed at
    the end of rows.csv, where another reader saw it)."""
    ops = FaultyOps()
    session = make(tmp_path, camera_vga, file_ops=ops)
    header = session.rows_path.read_bytes()
    ops.short = True
    assert session.log(a_row(z=301.0)).status == "pending"
    assert session.rows_path.read_bytes() == header  # half a line was written, and cut off
    ops.short = False
    assert session.retry().ok
    assert [line[0] for line in csv_rows(session.rows_path)[1:]] == ["1"]
    assert not list(session.path.glob("rows.csv.partial-*"))  # nothing torn to move aside
    session.close()
    assert not Session.open(session.path).warnings


def test_a_write_failing_midway_leaves_no_torn_line(tmp_path, camera_vga):
    """A full disk after part of the line (write returns what fit, then ENOSPC)."""

    class HalfThenFull(FileOps):
        fail = False

        def write(self, fd, data):
            if self.fail:
                super().write(fd, data[:7])
                raise OSError(errno.ENOSPC, "No space left on device")
            return super().write(fd, data)

    ops = HalfThenFull()
    session = make(tmp_path, camera_vga, file_ops=ops)
    assert session.log(a_row(z=301.0)).ok
    good = session.rows_path.read_bytes()
    ops.fail = True
    outcome = session.log(a_row(z=302.0))
    assert outcome.status == "pending" and "disk full" in outcome.reason
    assert session.rows_path.read_bytes() == good and good.endswith(b"\n")
    session.close()


def test_a_symlink_planted_at_rows_csv_is_refused(tmp_path, camera_vga):
    """Issue 23: session log followed it and appended outside the session folder."""
    session = make(tmp_path, camera_vga)
    session.close()
    outside = tmp_path / "outside.csv"
    outside.write_bytes(session.rows_path.read_bytes())
    session.rows_path.unlink()
    session.rows_path.symlink_to(outside)
    with pytest.raises(SessionError, match=r"rows\.csv is a symbolic link"):
        Session.open(session.path)
    assert outside.read_bytes().count(b"\n") == 1  # the header only: nothing appended


def test_lost_permission_when_opening_keeps_rows_pending(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    session.close()
    ops = FaultyOps()
    ops.fault = {"open": errno.EACCES}
    again = Session.open(session.path, file_ops=ops)
    assert not again.writable and "permission denied" in again.warnings[-1]
    outcome = again.log(a_row())
    assert outcome.status == "pending" and "permission denied" in outcome.message
    ops.fault = {}
    assert again.retry().ok
    again.close()
    assert [line[0] for line in csv_rows(session.rows_path)[1:]] == ["1"]


@contextlib.contextmanager
def as_nobody():
    """Drop the effective uid when running as root (root ignores file permissions)."""
    if os.geteuid() != 0:
        yield
        return
    os.seteuid(65534)
    try:
        yield
    finally:
        os.seteuid(0)


@pytest.mark.skipif(not hasattr(os, "geteuid"), reason="POSIX permissions needed")
def test_a_read_only_folder_keeps_rows_pending_until_writable(camera_vga):
    root = Path(tempfile.mkdtemp(prefix="qrfield-ro-"))  # outside pytest's 0700 tree: nobody can reach it
    try:
        root.chmod(0o755)
        session = make(root, camera_vga)
        session.close()
        read_only = stat.S_IRUSR | stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP | stat.S_IROTH | stat.S_IXOTH
        session.path.chmod(read_only)
        session.rows_path.chmod(0o444)
        with as_nobody():
            again = Session.open(session.path)
            outcome = again.log(a_row())
        assert outcome.status == "pending"
        assert re.search(r"permission denied|read-only", outcome.message)
        session.path.chmod(0o755)
        session.rows_path.chmod(0o644)
        assert again.retry().ok
        again.close()
        assert [line[0] for line in csv_rows(session.rows_path)[1:]] == ["1"]
    finally:
        for p in sorted(root.rglob("*"), reverse=True):
            with contextlib.suppress(OSError):
                p.chmod(0o755)
        import shutil

        shutil.rmtree(root, ignore_errors=True)


def test_criteria_and_frames_are_saved(tmp_path, camera_vga):
    session = make(
        tmp_path,
        camera_vga,
        criteria=AcceptanceCriteria(max_angle_error_deg=1.0, max_position_error_mm=3.0),
        frames_per_row=25,
    )
    session.close()
    info, _ = read_session(session.path)
    assert info.criteria.max_angle_error_deg == 1.0 and info.criteria.max_position_error_mm == 3.0
    assert info.frames_per_row == 25
    assert info.camera == camera_vga


def test_pending_rows_can_be_saved_elsewhere_before_closing(tmp_path, camera_vga):
    ops = FaultyOps()
    session = make(tmp_path / "full-disk", camera_vga, file_ops=ops)
    ops.fault = {"write": errno.ENOSPC}
    session.log(a_row(z=301.0))
    session.log(a_row(z=302.0))
    rescue = tmp_path / "usb-stick" / "pending.csv"
    rescue.parent.mkdir()
    assert session.export_pending(rescue) == 2
    saved = csv_rows(rescue)
    assert saved[0] == list(COLUMNS)
    assert [(r[0], r[11]) for r in saved[1:]] == [("1", "301.000"), ("2", "302.000")]
    session.close()


def test_notes_can_be_updated(tmp_path, camera_vga):
    session = make(tmp_path, camera_vga)
    session.update_notes("lamp moved at row 12", operator="B. Other")
    meta = json.loads((session.path / "session.json").read_text(encoding="utf-8"))
    assert (meta["notes"], meta["operator"]) == ("lamp moved at row 12", "B. Other")
    assert meta["camera"] == camera_vga.to_dict()
    session.close()


def test_solver_settings_are_checked(tmp_path, camera_vga):
    from qrfield import solvers
    from qrfield.settings import to_dict

    session = Session.create(tmp_path, "x", camera=camera_vga, side_mm=60, solver="ippe")
    saved = json.loads((session.path / "session.json").read_text(encoding="utf-8"))["solver"]["settings"]
    assert saved == to_dict(solvers.IppeSettings())  # the defaults, recorded in full
    session.close()
    with pytest.raises(SessionError, match="n_max"):
        Session.create(
            tmp_path, "x", camera=camera_vga, side_mm=60, solver="numerical", solver_settings={"n_max": 0}
        )


# ------------------------------------------------------------------------------ streamed reading
@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(
    st.lists(st.text(st.characters(exclude_characters='"\r\n\x00', exclude_categories=("Cs",))), min_size=1)
)
def test_the_fast_split_of_a_line_is_what_the_csv_module_reads(fields):
    from qrfield.sessions.store import _fields

    line = ",".join(fields)
    if line:
        assert _fields(line) == next(csv.reader([line]))


def _log_lines(session, count):
    """``count`` rows appended as qrfield writes them (the line of a real logged row, renumbered)."""
    assert session.log(a_row(note="a note, with a comma")).ok  # quoted: the csv module's path
    assert session.log(a_row()).ok
    lines = session.rows_path.read_bytes().splitlines(keepends=True)
    template = lines[-1].decode()
    with open(session.rows_path, "ab") as handle:
        for number in range(3, count + 1):
            handle.write(template.replace("2,", f"{number},", 1).encode())


def test_rows_read_one_by_one_are_what_csv_reads_from_the_file(tmp_path, camera_vga):
    """Truth: csv.DictReader over the whole file. The scan keeps where each row is; a row read by
    index, by number, in order or in reverse must be that line's values."""
    session = make(tmp_path, camera_vga)
    _log_lines(session, 40)
    session.close()
    with open(session.rows_path, "ab") as handle:
        handle.write(b"not,a,row\n")  # a damaged line between rows: skipped, with a warning
    reopened = Session.open(session.path)
    assert reopened.withdraw(7).ok and reopened.log(a_row(z=400.0)).ok
    with open(session.rows_path, newline="", encoding="utf-8") as f:
        truth = [r for r in csv.DictReader(f) if r["row"].strip().isdigit()]
    rows = reopened.rows
    assert len(rows) == len(truth) == 41 and reopened.next_row == 42
    assert any("row 'not' is not a number; ignored" in w for w in reopened.warnings)
    for row, expected in zip(rows, truth, strict=True):
        assert row.values == {k: v for k, v in expected.items() if k in row.values}
        assert row.withdrawn == (row.number == 7)
    assert [r.number for r in reversed(rows)] == [int(t["row"]) for t in reversed(truth)]
    assert rows[6] == rows.by_number(7) and rows[6].withdrawn and rows[-1].values["z"] == "400.000"
    assert rows[2:4] == [rows[2], rows[3]] and rows.by_number(99) is None
    assert reopened.undo().row == 41  # the last row in force: the one logged now
    reopened.close()
    _, content = read_session(session.path)
    assert sum(r.withdrawn for r in content.rows) == 2 and content.rows == list(content.rows)


@pytest.mark.slow
def test_reading_a_large_session_holds_a_few_bytes_a_row_not_the_file(tmp_path, camera_vga):
    """Issue 23: a 50 MB rows.csv made every session command peak at 858 MB (17 times the file):
    each row was a dict of 39 texts. Now a row is a line's offset and its number."""
    import tracemalloc

    session = make(tmp_path, camera_vga)
    _log_lines(session, 40_000)  # 8 MB of rows.csv
    session.close()
    size = session.rows_path.stat().st_size
    tracemalloc.start()
    try:
        _, content = read_session(session.path)
        active = sum(1 for row in content.rows if not row.withdrawn)
        with Session.open(session.path) as again:
            last = again.rows[-1].number
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert active == 40_000 and last == 40_000
    # Measured: 2.7 MB (1 MiB read chunks and 8 bytes a row); a dict a row was some 140 MB.
    assert peak < 4e6, f"peak {peak / 1e6:.1f} MB for a {size / 1e6:.1f} MB file"


class _NoSync(FileOps):
    """Appends without fsync: many rows fast (what is measured is memory, not the disk)."""

    def fsync(self, fd):
        pass


def test_rows_logged_in_a_long_session_are_read_from_the_file_not_kept(tmp_path, camera_vga):
    """A session open all day: each row logged was kept whole in memory (its dict of texts, some
    5 KB) for as long as the session was open. Once on disk it is read from there, as the rows of a
    resumed session are: memory stays a few bytes a row. Truth: csv.DictReader over the file."""
    import gc
    import tracemalloc

    session = make(tmp_path, camera_vga, file_ops=_NoSync())
    row = a_row(note="a note, with a comma")  # quoted in the file: the csv module's path
    assert session.log(row).ok
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for _ in range(50):
            assert session.log(row).ok
        gc.collect()
        kept = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert kept < 10_000, f"{kept / 50:.0f} bytes kept a row"  # whole rows: 240 KB
    with open(session.rows_path, newline="", encoding="utf-8") as f:
        truth = [r for r in csv.DictReader(f) if r["row"].strip().isdigit()]
    rows = session.rows
    assert len(rows) == len(truth) == 51 and session.next_row == 52
    for got, expected in zip(rows, truth, strict=True):
        assert got.confirmed and got.values == {k: v for k, v in expected.items() if k in got.values}
    assert rows[-1].values["note"] == "a note, with a comma" and rows.by_number(7).number == 7
    assert session.undo().row == 51 and rows[-1].withdrawn and rows.max_number() == 51
    assert session.log(row).ok and rows[-1].number == 52 and rows[-2].withdrawn
    session.close()
