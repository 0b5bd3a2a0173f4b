"""Kill a logging process with SIGKILL at random moments: every confirmed row survives, whole.

The child opens (resumes) the session and logs rows as fast as it can, printing ``logged N``
after each confirmed append. The parent kills it at a seeded random delay after its first
confirmation, then checks that every confirmed row is in rows.csv with its exact values, that
no partial line remains after reopening, and that numbering resumes after the last row.
"""

from __future__ import annotations

import csv
import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from qrfield.sessions import Session

REPO = Path(__file__).resolve().parent.parent
KILLS = 30

CHILD = r"""
import sys
from qrfield.sessions import GroundTruth, Session, measure

session = Session.open(sys.argv[1])
print("start", session.next_row, flush=True)
while True:
    n = session.next_row
    # Values derived from the row number so the parent can check every field; a long note
    # makes each line several kilobytes.
    truth = GroundTruth(float(n), 0.0, 300.0, 0.0, 0.0, 0.0, "alpha")
    frames = [{"position_mm": [float(n), 1.0, 300.0], "angles_deg": [0.5, 0.0, 0.0], "converged": True}]
    outcome = session.log(measure(frames, truth, note=f"row {n} " + "x" * 3000))
    if not outcome.ok:
        print("failed", outcome.message, flush=True)
        sys.exit(3)
    sys.stdout.write(f"logged {n}\n")  # one write: the parent counts only whole lines
    sys.stdout.flush()
"""


def run_and_kill(session_dir: Path, delay_s: float) -> tuple[int, list[int]]:
    """Start a logging child, kill it ``delay_s`` after its first confirmed row; (start, confirmed)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(session_dir)], stdout=subprocess.PIPE, text=True, env=env
    )
    lines: list[str] = []
    first = threading.Event()

    def reader() -> None:
        assert child.stdout is not None
        for line in child.stdout:
            if not line.endswith("\n"):
                break  # cut short by the kill: not a confirmation
            lines.append(line.strip())
            if line.startswith(("logged", "failed")):
                first.set()
        first.set()

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    assert first.wait(30), "the child never logged a row"
    time.sleep(delay_s)
    child.send_signal(signal.SIGKILL)
    child.wait(30)
    thread.join(30)
    assert child.returncode == -signal.SIGKILL, lines[-3:]
    assert lines and lines[0].startswith("start"), lines[:3]
    assert not any(line.startswith("failed") for line in lines), lines
    confirmed = [int(line.split()[1]) for line in lines if line.startswith("logged")]
    return int(lines[0].split()[1]), confirmed


@pytest.mark.slow
def test_sigkill_at_random_moments_loses_no_confirmed_row(tmp_path, camera_vga):
    session = Session.create(tmp_path, "crash", camera=camera_vga, side_mm=60.0, solver="numerical")
    session.close()
    rng = random.Random(20261122)
    confirmed: set[int] = set()
    for kill in range(KILLS):
        start, logged = run_and_kill(session.path, rng.uniform(0.0, 0.04))
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
