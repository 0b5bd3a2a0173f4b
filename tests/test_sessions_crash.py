"""Kill a logging process with SIGKILL at random moments: every confirmed row survives, whole.

The child (a forked process) opens (resumes) the session and logs rows as fast as it can,
printing ``logged N`` after each confirmed append. The parent kills it at a seeded random delay
after its first confirmation, then checks that every confirmed row is in rows.csv with its exact values, that
no partial line remains after reopening, and that numbering resumes after the last row.
"""

from __future__ import annotations

import csv
import os
import random
import select
import signal
import time
from pathlib import Path

import pytest

from qrfield.sessions import GroundTruth, Session, measure

KILLS = 60


def log_forever(session_dir: Path) -> None:
    """The child's work: resume the session and log rows until killed, reporting each confirmation."""
    session = Session.open(session_dir)
    os.write(1, f"start {session.next_row}\n".encode())
    while True:
        n = session.next_row
        # Values derived from the row number so the parent can check every field; a long note
        # makes each line several kilobytes.
        truth = GroundTruth(float(n), 0.0, 300.0, 0.0, 0.0, 0.0, "alpha")
        frames = [{"position_mm": [float(n), 1.0, 300.0], "angles_deg": [0.5, 0.0, 0.0], "converged": True}]
        outcome = session.log(measure(frames, truth, note=f"row {n} " + "x" * 3000))
        if not outcome.ok:
            os.write(1, f"failed {outcome.message}\n".encode())
            return
        os.write(1, f"logged {n}\n".encode())  # one write of a short line: whole or not at all


def run_and_kill(session_dir: Path, delay_s: float) -> tuple[int, list[int]]:
    """Fork a logging child, SIGKILL it ``delay_s`` after its first confirmed row; (start, confirmed).

    The child is a forked copy of this process (already importing qrfield), so that many kills
    fit in a few seconds; it logs through the real file system like the app does.
    """
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: stdout is the pipe; never returns into pytest
        try:
            os.close(read_end)
            os.dup2(write_end, 1)
            log_forever(session_dir)
        finally:
            os._exit(3)
    os.close(write_end)
    buffer = b""
    deadline = time.monotonic() + 30
    while b"logged" not in buffer and b"failed" not in buffer and time.monotonic() < deadline:
        ready, _, _ = select.select([read_end], [], [], 1.0)
        if ready:
            chunk = os.read(read_end, 65536)
            if not chunk:
                break
            buffer += chunk
    time.sleep(delay_s)
    os.kill(pid, signal.SIGKILL)
    _, status = os.waitpid(pid, 0)
    while chunk := os.read(read_end, 65536):
        buffer += chunk
    os.close(read_end)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, buffer[-200:]
    # Only whole lines count: a line cut short by the kill is no confirmation.
    lines = buffer.decode().split("\n")[:-1]
    assert lines and lines[0].startswith("start"), lines[:3]
    assert not any(line.startswith("failed") for line in lines), lines
    assert any(line.startswith("logged") for line in lines), "the child never logged a row"
    confirmed = [int(line.split()[1]) for line in lines if line.startswith("logged")]
    return int(lines[0].split()[1]), confirmed


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork and SIGKILL (POSIX)")
def test_sigkill_at_random_moments_loses_no_confirmed_row(tmp_path, camera_vga):
    session = Session.create(tmp_path, "crash", camera=camera_vga, side_mm=60.0, solver="numerical")
    session.close()
    rng = random.Random(20261122)
    confirmed: set[int] = set()
    for kill in range(KILLS):
        start, logged = run_and_kill(session.path, rng.uniform(0.0, 0.02))
        data = session.rows_path.read_bytes()
        # The previous child's rows are all there: this child resumed right after the last one.
        assert start == max(confirmed, default=0) + 1 or start > max(confirmed, default=0), (kill, start)
        assert logged and logged[0] == start and logged == list(range(start, start + len(logged)))
        confirmed.update(logged)
        reopened = Session.open(session.path)  # moves aside an unfinished last line, if any
        try:
            numbers = [r.number for r in reopened.rows]
            assert numbers == list(range(1, len(numbers) + 1)), f"kill {kill}: gaps or repeats {numbers}"
            assert confirmed <= set(numbers), f"kill {kill}: lost {sorted(confirmed - set(numbers))}"
            assert reopened.next_row == numbers[-1] + 1
            tail_ok = reopened.rows_path.read_bytes()
            assert tail_ok.endswith(b"\n")
            if data.endswith(b"\n"):
                assert tail_ok == data  # nothing changed when the kill left no unfinished line
            for row in reopened.rows:
                v = row.values
                assert v["gt_x"] == f"{row.number:.3f}" and v["x"] == f"{row.number:.3f}"
                assert v["alpha"] == "0.500" and v["err_alpha"] == "0.500" and v["pass"] == "1"
                assert v["note"] == f"row {row.number} " + "x" * 3000
        finally:
            reopened.close()
    with open(session.rows_path, newline="", encoding="utf-8") as fh:
        records = list(csv.reader(fh))
    assert all(len(r) == len(records[0]) for r in records)
    assert len(confirmed) >= KILLS
    print(
        f"{KILLS} kills, {len(confirmed)} confirmed rows, {len(records) - 1} records on disk, "
        f"{len(list(session.path.glob('rows.csv.partial-*')))} unfinished lines moved aside"
    )
