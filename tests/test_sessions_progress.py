"""A session's plan and progress on disk: attached once, states from rows.csv (undo makes a target
todo again), skips, a crash between "will log" and the row, and sessions without a plan untouched."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from qrfield.camera import CameraModel
from qrfield.sessions import GroundTruth, Session, SessionError, measure
from qrfield.sessions.plan import generate_plan, read_plan
from qrfield.sessions.progress import DONE, PLAN_FILE, PROGRESS_FILE, SKIPPED, TODO, PlanProgress, attach_plan

CAMERA = CameraModel.from_focal(600.0, 640, 480, name="test")
PLAN = generate_plan("alpha,beta", [10, 20], z_mm=300)  # 4 targets


@pytest.fixture
def session(tmp_path: Path) -> Session:
    s = Session.create(tmp_path, "plan test", camera=CAMERA, side_mm=50.0, solver="numerical")
    yield s
    s.close()


def log_at(session: Session, truth: GroundTruth) -> int:
    """Log a row whose one frame is exactly the truth (a pass)."""
    frame = {"converged": True, "position_mm": truth.position_mm, "angles_deg": truth.angles_deg}
    outcome = session.log(measure([frame], truth))
    assert outcome.ok
    return outcome.row


def test_attach_copies_the_plan_and_the_states_follow_the_rows(session: Session) -> None:
    progress = attach_plan(session.path, PLAN, session.rows, source="mine.csv")
    assert read_plan(session.path / PLAN_FILE) == PLAN
    assert [s.state for s in progress.states(session.rows)] == [TODO] * 4
    assert progress.next_target(session.rows) == PLAN[0]
    for target in PLAN[:2]:
        progress.will_log(target.number, session.next_row)
        log_at(session, target.truth)
    states = progress.states(session.rows)
    assert [s.state for s in states] == [DONE, DONE, TODO, TODO]
    assert [s.rows for s in states[:2]] == [(1,), (2,)]
    assert progress.next_target(session.rows) == PLAN[2]
    progress.skip(3)
    assert progress.next_target(session.rows) == PLAN[3]
    assert progress.counts(session.rows) == {TODO: 1, DONE: 2, SKIPPED: 1}
    # Undo of row 2 makes target 2 todo again; a new row for it makes it done.
    assert session.undo().ok
    assert [s.state for s in progress.states(session.rows)] == [DONE, TODO, SKIPPED, TODO]
    assert progress.next_target(session.rows, after=1) == PLAN[1]
    # What is on disk says the same after a restart.
    session.close()
    reopened = Session.open(session.path)
    again = PlanProgress.load(reopened.path, reopened.rows)
    assert [s.state for s in again.states(reopened.rows)] == [DONE, TODO, SKIPPED, TODO]
    assert again.states(reopened.rows)[1].withdrawn == (2,)
    assert again.target_of_row(1) == PLAN[0] and again.warnings == []
    reopened.close()


def test_a_row_entered_but_never_logged_is_dropped_on_opening(session: Session) -> None:
    progress = attach_plan(session.path, PLAN, session.rows)
    progress.will_log(1, session.next_row)
    log_at(session, PLAN[0].truth)
    progress.will_log(2, session.next_row)  # ... and the process ends before row 2 is logged
    session.close()
    reopened = Session.open(session.path)
    loaded = PlanProgress.load(reopened.path, reopened.rows)
    assert [s.state for s in loaded.states(reopened.rows)] == [DONE, TODO, TODO, TODO]
    assert "target 2: row 2" in loaded.warnings[0]
    saved = json.loads((reopened.path / PROGRESS_FILE).read_text(encoding="utf-8"))
    assert saved["targets"]["2"]["rows"] == []  # rewritten: row 2 will be another target's
    loaded.will_log(3, reopened.next_row)
    log_at(reopened, PLAN[2].truth)
    assert loaded.target_of_row(2) == PLAN[2]
    reopened.close()


def test_the_same_plan_continues_and_another_is_refused_once_rows_were_logged(session: Session) -> None:
    attach_plan(session.path, PLAN, session.rows).will_log(1, session.next_row)
    log_at(session, PLAN[0].truth)
    same = attach_plan(session.path, read_plan(session.path / PLAN_FILE), session.rows)
    assert same.states(session.rows)[0].state == DONE
    other = generate_plan("gamma", [10], z_mm=300)
    with pytest.raises(SessionError, match="follows another plan"):
        attach_plan(session.path, other, session.rows)
    assert read_plan(session.path / PLAN_FILE) == PLAN


def test_another_plan_replaces_one_nothing_was_logged_for(session: Session) -> None:
    attach_plan(session.path, PLAN, session.rows)
    other = generate_plan("gamma", [10], z_mm=300)
    progress = attach_plan(session.path, other, session.rows)
    assert progress.targets == other and read_plan(session.path / PLAN_FILE) == other


def test_a_session_without_a_plan_has_no_progress_and_no_new_files(session: Session) -> None:
    log_at(session, PLAN[0].truth)
    assert PlanProgress.load(session.path, session.rows) is None
    assert sorted(p.name for p in session.path.iterdir()) == ["rows.csv", "session.json"]


@pytest.mark.parametrize(
    ("content", "words"),
    [
        ('{"targets": {"9": {"rows": [1]}}}', "target 9 is not in the plan"),
        ('{"targets": {"1": {"rows": ["1"]}}}', "list of row numbers"),
        ('{"targets": {"1": {"skipped": "yes"}}}', "true or false"),
        ('{"targets": []}', "'targets' must be a JSON object"),
        ("{not json", "plan progress"),
    ],
)
def test_a_damaged_progress_file_is_named(session: Session, content: str, words: str) -> None:
    attach_plan(session.path, PLAN, session.rows)
    (session.path / PROGRESS_FILE).write_text(content, encoding="utf-8")
    with pytest.raises(SessionError, match=words):
        PlanProgress.load(session.path, session.rows)


def test_a_plan_edited_in_the_session_folder_is_warned_about(session: Session) -> None:
    attach_plan(session.path, PLAN, session.rows)
    path = session.path / PLAN_FILE
    path.write_text(path.read_text(encoding="utf-8").replace("300,10,0,0", "310,10,0,0"), encoding="utf-8")
    loaded = PlanProgress.load(session.path, session.rows)
    assert loaded.targets[0].truth.z == 310 and "changed since it was attached" in loaded.warnings[0]
