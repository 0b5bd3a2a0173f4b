"""``qrfield session run-plan SESSION``: log a session's plan target by target, without the app.

The frame loop runs with the session's camera, side and solver (as ``session log``) and feeds a
:class:`qrfield.sessions.guide.Guide` with every frame (a sink of the loop). For each target still
to do, in plan order:

- on the **virtual bench** the bench is set to the target's pose and the row is asked for "once
  still" (the hold time counts from the first frame after the request, so no frame of the pose
  before counts): no hand is needed (a demo, and the test of the whole path);
- from a **camera** the target is printed and the terminal asks: Enter when the jig is set (the
  row is measured once the card has been still for the hold time), ``s`` to skip the target,
  ``q`` to stop; while it waits, the difference to the target is shown on one line.

Each row carries the target as its ground truth and the target's note, is entered in the plan's
progress before it is logged (:mod:`qrfield.sessions.progress`) and is appended and fsynced before
"logged row K" is printed, so a stopped run continues where it was with the same command.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import threading
import time
from typing import Any


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.commands.session import add_frames_argument
    from qrfield.runconfig import add_run_arguments
    from qrfield.sessions.guide import GuideSettings
    from qrfield.sessions.stillness import StillnessSettings
    from qrfield.settings import add_arguments as add_setting_arguments

    parser.add_argument("folder", metavar="SESSION", help="the session folder")
    parser.add_argument(
        "--plan",
        metavar="PLAN.csv",
        help="the plan to follow (copied into the session; default: the plan the session already has)",
    )
    parser.add_argument(
        "--combinations",
        default="default",
        metavar="FILE",
        help="the combinations file the plan's names come from (default: the study's)",
    )
    add_frames_argument(parser)
    parser.add_argument("--retry-skipped", action="store_true", help="offer the targets skipped before again")
    group = parser.add_argument_group("stillness (section 'stillness' of app.json)")
    add_setting_arguments(group, StillnessSettings)
    add_setting_arguments(group, GuideSettings, skip=("auto_gate",))
    add_run_arguments(
        parser, only=("run", "detector", "virtual", "picamera"), run_skip=("camera", "side_mm", "method")
    )


def say(text: str) -> None:
    print(f"qrfield session run-plan: {text}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    from qrfield.commands.session import loop_thread
    from qrfield.engine import FrameLoop, SayEvents
    from qrfield.handeye.setups import CAMERA
    from qrfield.runconfig import effective_settings
    from qrfield.sessions import Session
    from qrfield.sessions.guide import Guide, GuideSettings
    from qrfield.sessions.plan import read_plan
    from qrfield.sessions.progress import PlanProgress, attach_plan
    from qrfield.sessions.recorder import session_run_config
    from qrfield.sessions.stillness import StillnessSettings
    from qrfield.settings import from_arguments

    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames must be at least 1, got {args.frames}")
    plan = read_plan(args.plan, args.combinations) if args.plan else None  # PlanError before any change
    session = Session.open(args.folder)
    try:
        for warning in session.warnings:
            say(f"warning: {warning}")
        if session.info.pose_frame != CAMERA:  # plan targets are poses of the code in the camera frame
            raise ValueError(
                f"{session.path.name} reports poses in the {session.info.pose_frame} frame; a plan's targets "
                "are in the camera frame: run the plan in a session made without --frame"
            )
        if plan is not None:
            progress = attach_plan(
                session.path, plan, session.rows, source=str(args.plan), combinations=args.combinations
            )
        else:
            progress = PlanProgress.load(session.path, session.rows)
            if progress is None:
                raise ValueError(f"{session.path.name} has no plan yet: give --plan PLAN.csv")
        for warning in progress.warnings:
            say(f"warning: {warning}")
        if args.retry_skipped:
            for state in progress.states(session.rows):
                if state.state == "skipped":
                    progress.skip(state.target.number, False)
        effective = effective_settings(args, resolve_camera=False)
        for problem in effective.store.problems:
            say(f"settings: {problem}")
        store = effective.store
        stillness = from_arguments(StillnessSettings, args, base=store.group("stillness", StillnessSettings))
        guide_settings = from_arguments(GuideSettings, args, base=store.group("guide", GuideSettings))
        config = session_run_config(effective.run_config(camera=session.info.camera), session.info)
        info = session.info
        guide = Guide(
            info.solver, info.criteria, args.frames or info.frames_per_row, stillness, guide_settings
        )
        loop = FrameLoop(config, events=SayEvents(say), sinks=(guide,))
        try:
            with loop_thread(loop) as thread:
                return _Runner(
                    session, progress, guide, loop, config, thread, guide_settings.still_timeout_s
                ).run()
        except KeyboardInterrupt:
            say("stopped: the rows logged so far are kept; run the same command to continue")
            return 130
    finally:
        session.close()


@dataclasses.dataclass
class _Runner:
    session: Any
    progress: Any
    guide: Any
    loop: Any
    config: Any
    thread: threading.Thread
    still_timeout_s: float
    failed: int = 0

    def run(self) -> int:
        from qrfield.sessions.progress import TODO

        if not self._first_frame():
            say("no frames came from the source: nothing logged")
            return 1
        virtual = _is_virtual_bench(self.loop.source)
        counts = self.progress.counts(self.session.rows)
        total = len(self.progress.targets)
        say(
            f"plan of {total} targets: {counts['done']} done, {counts['skipped']} skipped, "
            f"{counts['todo']} to do; "
            + (
                "the virtual bench is set to each target"
                if virtual
                else "Enter when the jig is set, s to skip, q to stop"
            )
        )
        tried: set[int] = set()
        last, outcome = 0, ""
        while self.thread.is_alive():
            target = self.progress.next_target(self.session.rows, after=last)
            if target is None or target.number in tried:
                break
            tried.add(target.number)
            last = target.number
            print(f"{target.describe()} ({target.number} of {total})", flush=True)
            outcome = self._bench_target(target) if virtual else self._operator_target(target)
            if outcome in ("quit", "eof"):
                break
        counts = self.progress.counts(self.session.rows)
        states = self.progress.states(self.session.rows)
        passed = sum(1 for s in states for row in s.rows if self._row(row).passed)
        rows = sum(len(s.rows) for s in states)
        print(
            f"plan: {counts['done']} of {total} targets done ({passed} of {rows} rows pass), "
            f"{counts['skipped']} skipped, {counts['todo']} to do",
            flush=True,
        )
        if counts[TODO] and not self.thread.is_alive():
            say("the source stopped before the plan was done")
            return 1
        if counts[TODO] and outcome == "eof":
            say(
                "end of input: no one answered the prompt (run it in a terminal, or use --source "
                "virtual); the rows logged so far are kept, run the same command to continue"
            )
            return 1
        return 1 if self.failed else 0

    def _row(self, number: int) -> Any:
        return next(r for r in self.session.rows if r.number == number)

    def _first_frame(self, timeout_s: float = 30.0) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end and self.thread.is_alive():
            if self.guide.view().frames_seen > 0:
                return True
            time.sleep(0.05)
        return False

    # ---------------------------------------------------------------- the virtual bench
    def _bench_target(self, target: Any) -> str:
        from qrfield.settings import SettingError, validated
        from qrfield.sources.virtual import VirtualBenchSettings

        bench = self.config.virtual or VirtualBenchSettings()
        t = target.truth
        try:
            bench = validated(
                dataclasses.replace(
                    bench, x_mm=t.x, y_mm=t.y, z_mm=t.z, alpha_deg=t.alpha, beta_deg=t.beta, gamma_deg=t.gamma
                )
            )
        except SettingError as exc:
            say(f"target {target.number}: the virtual bench cannot take this pose ({exc}); skipped")
            self.progress.skip(target.number)
            return "skipped"
        self.config = dataclasses.replace(self.config, virtual=bench)
        self.loop.configure(self.config)
        self.guide.set_target(target)
        self.guide.arm(when_still=True)
        return self._collect(target)

    # ---------------------------------------------------------------- a camera and an operator
    def _operator_target(self, target: Any) -> str:
        self.guide.set_target(target)
        while True:
            answer = _ask("Enter when the jig is set, s to skip, q to stop: ")
            if answer is None:  # stdin ended (a script, < /dev/null): nobody answers
                return "eof"
            if answer.strip().lower() == "q":
                return "quit"
            if answer.strip().lower() == "s":
                self.progress.skip(target.number)
                print(f"skipped target {target.number}", flush=True)
                return "skipped"
            self.guide.arm(when_still=True)
            outcome = self._collect(target, live=True)
            if outcome != "again":
                return outcome

    def _collect(self, target: Any, live: bool = False) -> str:
        from qrfield.sessions.guide import difference_text

        end = time.monotonic() + self.still_timeout_s
        shown = 0.0
        while not self.guide.wait(0.1):
            if not self.thread.is_alive():
                self.guide.cancel()
                return "quit"
            view = self.guide.view()
            if view.problem:
                say(view.problem)
                return "again" if live else "failed"
            now = time.monotonic()
            if live and now - shown >= 0.5 and sys.stderr.isatty():
                print(f"\r{difference_text(view)[:150]:<150}", end="", file=sys.stderr, flush=True)
                shown = now
            if now > end:
                self.guide.cancel()
                say(
                    f"target {target.number}: not still within {self.still_timeout_s:g} s "
                    f"({view.stillness.reason or 'moving'})"
                    + ("; Enter to try again, s to skip" if live else "; left to do")
                )
                return "again" if live else "failed"
        if live and sys.stderr.isatty():
            print(file=sys.stderr)
        for row in self.guide.take():
            self._log(row)
        return "logged"

    def _log(self, row: Any) -> None:
        from qrfield.commands.session import _log

        number = self.session.next_row
        try:
            self.progress.will_log(row.target.number, number)
        except OSError as exc:
            say(f"warning: the plan's progress cannot be saved ({exc}); the row is logged all the same")
        if _log(self.session, row.measurement) != 0:
            self.failed += 1


def _is_virtual_bench(source: Any) -> bool:
    from qrfield.sources.virtual import VirtualBenchSource

    return isinstance(source, VirtualBenchSource)


def _ask(prompt: str) -> str | None:
    try:
        return input(prompt)
    except EOFError:
        return None
