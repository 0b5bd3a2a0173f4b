"""A session's plan and its progress on disk: ``plan.csv`` and ``plan-progress.json`` in the session folder.

A plan is optional: a session folder without ``plan.csv`` is a session as before, and nothing here
is read for it. Attaching a plan (:func:`attach_plan`) copies it into the session folder
(``plan.csv``, written atomically; the session is self-contained and a restarted app or terminal
continues with it) and starts ``plan-progress.json``::

    {"format": "qrfield-plan-progress/1", "plan": "plan.csv", "plan_sha256": "...",
     "source": "/where/it/came/from.csv", "combinations": "default",
     "targets": {"3": {"rows": [5, 9], "skipped": false}, ...}}

``rows`` are the session's row numbers measured for that target. A row is entered *before* it is
logged (:meth:`PlanProgress.will_log`), so a crash between the two leaves an entry for a row that
rows.csv does not have; opening drops such entries (row numbers only grow, so a dropped number is
never another target's row). The state of a target follows from rows.csv itself
(:meth:`PlanProgress.states`): **done** while one of its rows is not withdrawn, **skipped** when
the operator skipped it and it is not done, else **todo**; withdrawing a target's row (undo)
makes it todo again. The next target is the first todo one in plan order.

Every write is atomic (temp file, fsync, rename). A failed write of the progress raises OSError to
the caller, which says so; the rows themselves are in rows.csv regardless.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from qrfield.files import Fields, FileFormatError, atomic_write, atomic_write_json, read_bytes, read_json
from qrfield.sessions.plan import PlanError, PlanTarget, parse_plan, plan_text
from qrfield.sessions.store import LoggedRow, SessionError

PLAN_FILE = "plan.csv"
PROGRESS_FILE = "plan-progress.json"
FORMAT = "qrfield-plan-progress/1"
TODO, DONE, SKIPPED = "todo", "done", "skipped"


@dataclass(frozen=True)
class TargetState:
    """A target and where it stands: TODO, DONE or SKIPPED; its rows in force and its withdrawn ones."""

    target: PlanTarget
    state: str
    rows: tuple[int, ...]
    withdrawn: tuple[int, ...] = ()


def has_plan(session_dir: str | os.PathLike[str]) -> bool:
    return (Path(session_dir) / PLAN_FILE).is_file()


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class PlanProgress:
    """The plan of one session folder and the rows measured for each target (see the module doc)."""

    def __init__(
        self,
        folder: Path,
        targets: list[PlanTarget],
        rows_of: dict[int, list[int]],
        skipped: set[int],
        *,
        sha: str,
        source: str = "",
        combinations: str = "default",
        warnings: Sequence[str] = (),
    ) -> None:
        self.folder = folder
        self.targets = targets
        self._rows_of = rows_of
        self._skipped = skipped
        self.sha = sha
        self.source = source
        self.combinations = combinations
        self.warnings = list(warnings)

    # ------------------------------------------------------------------ reading
    @classmethod
    def load(cls, session_dir: str | os.PathLike[str], rows: Sequence[LoggedRow]) -> PlanProgress | None:
        """The plan of ``session_dir`` with its progress, checked against the session's ``rows``
        (entries for rows rows.csv does not have are dropped and the file rewritten); None when the
        session has no plan. PlanError for a plan.csv that no longer reads; SessionError for a
        damaged progress file (its message says which)."""
        folder = Path(session_dir)
        plan_path = folder / PLAN_FILE
        if not plan_path.is_file():
            return None
        progress_path = folder / PROGRESS_FILE
        data: dict[str, Any] = {}
        if progress_path.exists():
            try:
                data = read_json(progress_path, "plan progress")
                fields = Fields(data, str(progress_path))
                combinations = fields.text("combinations", "default")
                source = fields.text("source", "")
                sha = fields.text("plan_sha256", "")
                entries = fields.mapping("targets", {})
            except FileFormatError as exc:
                raise SessionError(str(exc)) from None
        else:
            combinations, source, sha, entries = "default", "", "", {}
        try:
            raw = read_bytes(plan_path, "plan")
        except FileFormatError as exc:
            raise PlanError([str(exc)]) from None
        from qrfield.files import decode_text

        try:
            targets = parse_plan(decode_text(raw, str(plan_path)), str(plan_path), combinations)
        except FileFormatError as exc:
            raise PlanError([str(exc)]) from None
        warnings = []
        if sha and sha != _sha(raw):
            warnings.append(
                f"{plan_path} changed since it was attached: its target numbers may not match the rows "
                "logged for them"
            )
        rows_of, skipped = cls._entries(entries, len(targets), str(progress_path))
        progress = cls(
            folder,
            targets,
            rows_of,
            skipped,
            sha=sha or _sha(raw),
            source=source,
            combinations=combinations,
            warnings=warnings,
        )
        existing = {r.number for r in rows}
        dropped = {n: [r for r in numbers if r not in existing] for n, numbers in rows_of.items()}
        dropped = {n: numbers for n, numbers in dropped.items() if numbers}
        if dropped:
            for n in dropped:
                progress._rows_of[n] = [r for r in progress._rows_of[n] if r in existing]
            described = ", ".join(f"target {n}: row {', '.join(map(str, v))}" for n, v in dropped.items())
            progress.warnings.append(
                f"{progress_path}: row(s) never written to rows.csv (the app or terminal ended before "
                f"they were logged) are no longer counted ({described})"
            )
            try:
                progress.save()
            except OSError as exc:
                progress.warnings.append(f"{progress_path}: cannot be rewritten ({exc})")
        return progress

    @staticmethod
    def _entries(entries: dict[str, Any], count: int, where: str) -> tuple[dict[int, list[int]], set[int]]:
        rows_of: dict[int, list[int]] = {}
        skipped: set[int] = set()
        for key, value in entries.items():
            try:
                number = int(key)
            except ValueError:
                raise SessionError(f"{where}: target {key!r} is not a number") from None
            if not 1 <= number <= count:
                raise SessionError(f"{where}: target {number} is not in the plan (1..{count})")
            try:
                entry = Fields(value, f"{where} target {number}")
                numbers = entry.data.get("rows", [])
                if not isinstance(numbers, list) or not all(
                    isinstance(r, int) and not isinstance(r, bool) and r > 0 for r in numbers
                ):
                    raise FileFormatError(f"{where} target {number}: 'rows' must be a list of row numbers")
                flag = entry.data.get("skipped", False)
                if not isinstance(flag, bool):
                    raise FileFormatError(f"{where} target {number}: 'skipped' must be true or false")
            except FileFormatError as exc:
                raise SessionError(str(exc)) from None
            rows_of[number] = list(numbers)
            if flag:
                skipped.add(number)
        return rows_of, skipped

    # ------------------------------------------------------------------ states
    def states(self, rows: Sequence[LoggedRow]) -> list[TargetState]:
        """Every target's state from the session's rows (withdrawn rows do not count)."""
        withdrawn = {r.number for r in rows if r.withdrawn}
        existing = {r.number for r in rows}
        out = []
        for target in self.targets:
            numbers = [r for r in self._rows_of.get(target.number, []) if r in existing]
            active = tuple(r for r in numbers if r not in withdrawn)
            gone = tuple(r for r in numbers if r in withdrawn)
            if active:
                state = DONE
            elif target.number in self._skipped:
                state = SKIPPED
            else:
                state = TODO
            out.append(TargetState(target, state, active, gone))
        return out

    def next_target(self, rows: Sequence[LoggedRow], after: int = 0) -> PlanTarget | None:
        """The first todo target after target number ``after`` (wrapping round), None when none is todo."""
        todo = [s.target for s in self.states(rows) if s.state == TODO]
        later = [t for t in todo if t.number > after]
        return (later or todo or [None])[0]

    def target(self, number: int) -> PlanTarget:
        if not 1 <= number <= len(self.targets):
            raise SessionError(f"no target {number} in the plan (1..{len(self.targets)})")
        return self.targets[number - 1]

    def target_of_row(self, row: int) -> PlanTarget | None:
        for number, rows in self._rows_of.items():
            if row in rows:
                return self.target(number)
        return None

    def counts(self, rows: Sequence[LoggedRow]) -> dict[str, int]:
        """How many targets are todo, done and skipped."""
        states = [s.state for s in self.states(rows)]
        return {name: states.count(name) for name in (TODO, DONE, SKIPPED)}

    # ------------------------------------------------------------------ changes (each saved at once)
    def will_log(self, target: int, row: int) -> None:
        """Before ``row`` is logged for ``target``: entered and saved (see the module doc)."""
        self.target(target)
        rows = self._rows_of.setdefault(target, [])
        if row not in rows:
            rows.append(row)
        self._skipped.discard(target)
        self.save()

    def skip(self, target: int, skipped: bool = True) -> None:
        """Skip a target (it is not offered until chosen again), or take the skip back."""
        self.target(target)
        if skipped:
            self._skipped.add(target)
        else:
            self._skipped.discard(target)
        self.save()

    def save(self) -> None:
        data = {
            "format": FORMAT,
            "plan": PLAN_FILE,
            "plan_sha256": self.sha,
            "source": self.source,
            "combinations": self.combinations,
            "targets": {
                str(n): {"rows": list(self._rows_of.get(n, [])), "skipped": n in self._skipped}
                for n in sorted(set(self._rows_of) | self._skipped)
            },
        }
        atomic_write_json(self.folder / PROGRESS_FILE, data)


def attach_plan(
    session_dir: str | os.PathLike[str],
    targets: Sequence[PlanTarget],
    rows: Sequence[LoggedRow],
    *,
    source: str = "",
    combinations: str = "default",
) -> PlanProgress:
    """Make ``targets`` the session's plan (copied to its folder) and return its progress.

    The same plan again (same targets) continues where it was. Another plan replaces the session's
    only while no row has been logged for the old one; else SessionError (start a new session for
    another plan: the rows of one session follow one plan).
    """
    folder = Path(session_dir)
    if not targets:
        raise PlanError(["the plan has no targets"])
    text = plan_text(targets)
    current = PlanProgress.load(folder, rows)
    if current is not None:
        if [(t.truth, t.note) for t in current.targets] == [(t.truth, t.note) for t in targets]:
            return current
        measured = sum(len(s.rows) + len(s.withdrawn) for s in current.states(rows))
        if measured:
            raise SessionError(
                f"{folder.name} follows another plan ({len(current.targets)} targets, {measured} row(s) "
                "logged for them); start a new session for this plan"
            )
    data = text.encode("utf-8")
    atomic_write(folder / PLAN_FILE, data)
    progress = PlanProgress(
        folder, list(targets), {}, set(), sha=_sha(data), source=source, combinations=combinations
    )
    progress.save()
    return progress
