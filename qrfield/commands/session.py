"""``qrfield session``: experiment sessions without a screen (new, log, undo, list, show, export).

The same files as the app's Session tab (docs/conventions.md, "Experiment sessions on disk"), made by
the same core (:mod:`qrfield.sessions`): a row is the average of N frames of the session's solver,
judged against the session's acceptance criteria, appended and fsynced before "logged row K" is
printed. ``session log`` measures with the session's own camera model, QR side and solver settings
(what its rows claim) from the configured source (``qrfield config``) or ``--source``.

Each subcommand is one :class:`Subcommand` in :data:`SUBCOMMANDS` (help, add_arguments, run):
adding one is one entry.
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from qrfield.commands._signals import interrupt
from qrfield.geometry import POSE_NAMES

HELP = "make experiment sessions and log rows without the app (new, log, run-plan, undo, list, show, export)"
DESCRIPTION = (
    "Experiment sessions on disk, as the app's Session tab makes them: 'new' creates one, 'log' "
    "measures a row (averaged frames against a ground truth measured by hand), 'run-plan' logs a plan's "
    "targets one by one (the virtual bench is set to each; from a camera the terminal asks), 'undo' "
    "withdraws the "
    "last row, 'list' and 'show' read them, 'export' writes the rows in force for a spreadsheet."
)


@dataclass(frozen=True)
class Subcommand:
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def say(text: str) -> None:
    print(f"qrfield session: {text}", file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------ new
def _add_new(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import add_side_argument, text
    from qrfield.camera import add_camera_arguments
    from qrfield.methods import METHODS
    from qrfield.runconfig import add_run_arguments
    from qrfield.sessions import AcceptanceCriteria, SessionSettings
    from qrfield.settings import add_arguments

    parser.add_argument(
        "root",
        nargs="?",
        metavar="ROOT",
        help="the folder that holds sessions (made if missing; default: the app's sessions folder, "
        "$QRFIELD_SESSIONS_DIR, else ~/.local/share/qrfield/sessions)",
    )
    parser.add_argument(
        "--name",
        type=text("--name"),
        required=True,
        metavar="N",
        help="the session's name (part of its folder's)",
    )
    add_camera_arguments(parser, default=None)
    add_side_argument(parser, configured="the run configuration's")
    parser.add_argument(
        "--method",
        choices=METHODS,
        default=None,
        help="the solver whose results the rows average (default: the configured one; numerical for both)",
    )
    parser.add_argument("--operator", type=text("--operator"), default="", help="who measures")
    parser.add_argument("--notes", type=text("--notes"), default="", help="notes saved in session.json")
    group = parser.add_argument_group(
        "rows and acceptance criteria (sections 'session', 'criteria' of app.json)"
    )
    add_arguments(group, SessionSettings)
    add_arguments(group, AcceptanceCriteria)
    add_run_arguments(parser, only=(*METHODS, "handeye"))


def _run_new(args: argparse.Namespace) -> int:
    from qrfield.camera import camera_origin
    from qrfield.handeye import PoseFrame
    from qrfield.methods import METHODS, methods_from_choice
    from qrfield.runconfig import effective_settings
    from qrfield.sessions import AcceptanceCriteria, Session, SessionSettings
    from qrfield.sessions.folders import configured_root
    from qrfield.settings import from_arguments

    effective = effective_settings(args)
    for problem in effective.store.problems:
        say(f"settings: {problem}")
    run = effective.groups["run"]
    side = args.side_mm if args.side_mm is not None else run.side_mm
    method = args.method or methods_from_choice(run.method)[0]
    assert method in METHODS
    for note in effective.assumed():
        if "QR side" in note and args.side_mm is not None:
            continue
        say(note)
    if effective.camera.path:  # which profile file the session records (docs/cli.md)
        say(f"camera {effective.camera.name} from {camera_origin(effective.camera)}")
    store = effective.store
    rows = from_arguments(SessionSettings, args, base=store.group("session", SessionSettings))
    criteria = from_arguments(AcceptanceCriteria, args, base=store.group("criteria", AcceptanceCriteria))
    root = Path(args.root) if args.root else configured_root(store)
    pose_frame = PoseFrame.from_settings(effective.groups["handeye"], args.config_dir)
    if not pose_frame.identity:
        say(f"rows and their ground truth in the {pose_frame.frame} frame: {pose_frame.describe()}")
    session = Session.create(
        root,
        args.name,
        camera=effective.camera,
        side_mm=side,
        solver=method,
        solver_settings=effective.groups[method],
        criteria=criteria,
        frames_per_row=rows.frames_per_row,
        operator=args.operator,
        notes=args.notes,
        pose_frame=pose_frame.frame,
        handeye=pose_frame.calibration.to_dict() if pose_frame.calibration is not None else None,
    )
    session.close()
    info = session.info
    say(
        f"created session {info.name}: camera {info.camera.name} {info.camera.width}x{info.camera.height}, "
        f"QR side {info.side_mm:g} mm, solver {info.solver}, {info.frames_per_row} frames per row, "
        f"criteria {criteria.label()}"
    )
    print(session.path)
    return 0


# ------------------------------------------------------------------------------------ log
def add_frames_argument(parser: argparse.ArgumentParser) -> None:
    """``--frames N``: the frames averaged per row, 1..MAX_FRAMES_PER_ROW (default: the session's);
    ``session log`` and ``session run-plan`` share it."""
    from qrfield.arguments import count
    from qrfield.sessions.criteria import MAX_FRAMES_PER_ROW

    parser.add_argument(
        "--frames",
        type=count("--frames", 1, MAX_FRAMES_PER_ROW),
        default=None,
        metavar="N",
        help="frames averaged (default: the session's)",
    )


def _add_log(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import text
    from qrfield.runconfig import add_run_arguments

    parser.add_argument("folder", metavar="FOLDER", help="the session folder")
    parser.add_argument(
        "--truth",
        metavar="X,Y,Z,A,B,G",
        help="the pose measured by hand: x, y, z (mm) and alpha, beta, gamma (degrees); 'virtual' (or "
        "'bench') = the virtual bench's own pose; without --truth every field is asked for (interactive)",
    )
    parser.add_argument(
        "--combo", type=text("--combo"), metavar="NAME", help="the rotation combination of the row"
    )
    parser.add_argument(
        "--note", type=text("--note"), default="", metavar="T", help="a one-line note for the row"
    )
    parser.add_argument(
        "--force-combo",
        action="store_true",
        help="log a row whose --combo the signs of its angles contradict (refused otherwise, as the "
        "app asks first)",
    )
    add_frames_argument(parser)
    # Camera, QR side and solver are the session's own: only the source and detection are chosen here.
    add_run_arguments(
        parser, only=("run", "detector", "virtual", "picamera"), run_skip=("camera", "side_mm", "method")
    )


#: ``--truth`` words that mean the virtual bench's own pose ("bench": the older spelling).
TRUTH_WORDS = ("virtual", "bench")


def _parse_truth(text: str, combo: str | None, combinations: Any) -> Any:
    """GroundTruth from ``--truth X,Y,Z,A,B,G`` and ``--combo``; GroundTruthError names each bad field."""
    from qrfield.arguments import split_list
    from qrfield.sessions import FIELDS, GroundTruthError, parse_ground_truth

    parts = split_list(text)  # commas, semicolons or spaces, as every list (docs/cli.md)
    if len(parts) != 6:
        word = text.strip().lower()
        # A word is a mistyped 'virtual' more likely than a short list of numbers: say so.
        near = difflib.get_close_matches(word, TRUTH_WORDS, n=1, cutoff=0.6) if word.isalpha() else []
        hint = f"did you mean {near[0]!r}? " if near else ""
        raise GroundTruthError(
            {
                "truth": f"{text!r}: {hint}give 6 numbers X,Y,Z,ALPHA,BETA,GAMMA (mm, degrees; dots for "
                "decimals; separated by commas, semicolons or spaces; a unit joined to its number: 300mm), "
                "or 'virtual' for the virtual bench's own pose"
            }
        )
    fields = dict(zip(FIELDS[:6], parts, strict=True))
    fields["combo"] = combo or ""
    return parse_ground_truth(fields, combinations)


def _run_log(args: argparse.Namespace) -> int:
    from qrfield.engine import FrameLoop, SayEvents
    from qrfield.handeye import InFrame, PoseFrame
    from qrfield.runconfig import effective_settings
    from qrfield.sessions import Session, SessionSettings, known_combinations, validate_field
    from qrfield.sessions.recorder import RowRecorder, session_run_config
    from qrfield.sources import may_be_live_camera

    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames must be at least 1, got {args.frames}")
    combinations = known_combinations()
    follow = (args.truth or "").strip().lower() in TRUTH_WORDS  # "bench": the older spelling
    truth = None
    if args.truth and not follow:
        truth = _parse_truth(args.truth, args.combo, combinations)
    elif follow:
        _, message = validate_field("combo", args.combo or "", combinations)
        if message:
            raise ValueError(f"--combo: {message}")
    session = Session.open(args.folder)
    try:
        for warning in session.warnings:
            say(f"warning: {warning}")
        problem = combo_problem(truth, args.force_combo, session.info.pose_frame) if truth else ""
        if problem:  # before the frames: nothing measured in vain
            raise ValueError(problem)
        effective = effective_settings(args, resolve_camera=False)  # the session's camera is used
        for problem in effective.store.problems:
            say(f"settings: {problem}")
        # The app's rule for a row whose frames pause (a loaded machine, a slow camera): it waits
        # up to the frame timeout of app.json's 'session' section, not the loop's 1 s "source down".
        args.frame_timeout_s = effective.store.group("session", SessionSettings).frame_timeout_s
        config = session_run_config(effective.run_config(camera=session.info.camera), session.info)
        recorder = RowRecorder(session.info)  # the one row recorder, a sink fed every frame
        pose_frame = PoseFrame.from_saved(session.info.pose_frame, session.info.handeye, session.info.name)
        pose_frame.check_source(may_be_live_camera(config.source))
        # The rows are in the session's frame: the recorder sees each result through it.
        sink = recorder if pose_frame.identity else InFrame(recorder, pose_frame)
        loop = FrameLoop(config, events=SayEvents(say), sinks=(sink,))
        with loop_thread(loop) as thread:

            def ended() -> bool:
                return not thread.is_alive()

            if truth is not None or follow:
                return _log_one(session, recorder, truth, args, follow, ended)
            return _log_interactive(session, recorder, args, combinations, ended)
    finally:
        session.close()


@contextlib.contextmanager
def loop_thread(loop: Any) -> Iterator[threading.Thread]:
    """Run a frame loop on a daemon thread for the block (SIGTERM ends the block as Ctrl-C does);
    then stop the loop and join its thread (it closes the source)."""
    thread = threading.Thread(target=loop.run, name="frame loop", daemon=True)
    # SIGTERM like Ctrl-C: stop collecting, log nothing half-done (on the main thread only).
    previous = signal.signal(signal.SIGTERM, interrupt)
    thread.start()
    try:
        yield thread
    finally:
        loop.stop()
        thread.join(5.0)
        signal.signal(signal.SIGTERM, previous)


def _log_one(session: Any, recorder: Any, truth: Any, args: Any, follow: bool, ended: Any) -> int:
    frames = args.frames or session.info.frames_per_row
    say(f"measuring row {session.next_row}: {frames} frames, solver {session.info.solver}")
    measurement = recorder.measure(
        truth,
        frames,
        note=args.note,
        follow_bench=follow,
        until=ended,
        combo=args.combo,
        frame_timeout_s=args.frame_timeout_s,
    )
    if measurement is None:
        say(f"nothing logged: {recorder.last_problem}")
        if ended() and recorder.frames_seen and getattr(args, "loop", None) is not True:
            # A file source ended after its frames: an image is one, a folder one per file.
            say("a video, an image or a folder ends: --frames N asks for fewer, --loop repeats it")
        return 1
    return _log(session, measurement, args.force_combo)


def combo_problem(truth: Any, force: bool, pose_frame: str = "camera") -> str:
    """Why a row's combination must not be logged as it is ("" when it may): the app's rule and
    words (:func:`qrfield.sessions.combo_signs.combination_mismatch`), unless ``force``. The
    combinations tilt the card in the camera frame: a session in the tool or base frame
    (docs/handeye.md), whose angles are another frame's, is not checked."""
    from qrfield.sessions.combo_signs import combination_mismatch, sign_table

    if force or not truth.combo or pose_frame != "camera":
        return ""
    mismatch = combination_mismatch(truth.combo, truth.angles_deg, sign_table())
    return (
        f"--combo: not logged: {mismatch}; fix --combo, or add --force-combo to log it as it is"
        if mismatch
        else ""
    )


def _log(session: Any, measurement: Any, force_combo: bool = False) -> int:
    """Append and fsync one row; 0 and "logged row K" only once it is on disk."""
    # The bench's own pose (--truth virtual) is known only now.
    problem = combo_problem(measurement.truth, force_combo, session.info.pose_frame)
    if problem:
        say(f"error: {problem}")
        return 2
    outcome = session.log(measurement)
    if not outcome.ok:
        outcome = session.retry()
    j = measurement.judgement
    if outcome.ok:
        verdict = "pass" if j.passed else f"fail ({j.reason or 'no converged frame'})"
        a = measurement.average
        print(
            f"logged row {outcome.logged[-1] if outcome.logged else outcome.row}: {verdict}; "
            f"{a.n_converged}/{a.n_frames} frames converged, err_pos {j.err_pos_mm:.2f} mm",
            flush=True,
        )
        return 0
    # This process ends now, so nothing is kept in memory for a retry: the line is printed for the
    # operator to keep, and rows.csv holds no part of it (a failed append is cut back).
    say(
        f"NOT logged: {outcome.reason}; nothing of the row was left in {session.rows_path.name}. Free "
        "space or fix permissions and log it again, or keep the line below"
    )
    for record in session.pending:
        say(f"unwritten line of {session.rows_path.name}: {record.line.decode('utf-8').rstrip()}")
    return 1


def _ask(prompt: str) -> str | None:
    """One line from stdin (None at end of input)."""
    try:
        return input(prompt)
    except EOFError:
        return None


def _log_interactive(session: Any, recorder: Any, args: Any, combinations: Any, ended: Any) -> int:
    """Ask each field (the app's form's validation), measure, log; again until 'q' or end of input."""
    from qrfield.files import MAX_FIELD_CHARS
    from qrfield.sessions import FIELDS, GroundTruth, validate_field
    from qrfield.sessions.groundtruth import UNITS
    from qrfield.texts import TextError, check_text

    last: dict[str, Any] = {}
    # The defaults offered are the last row still in force: a withdrawn row's values were wrong.
    in_force = next((r for r in reversed(session.rows) if not r.withdrawn), None)
    if in_force is not None:
        row = in_force.values
        last = {name: row.get(f"gt_{name}", "") for name in FIELDS[:6]} | {"combo": row.get("combo", "")}
    code = 0
    print(
        f"session {session.info.name}: next row {session.next_row}; type each value (Enter keeps the one in "
        "[brackets]), q to quit",
        flush=True,
    )
    if combinations:
        print(f"combinations: {', '.join(combinations)}", flush=True)
    while not ended():
        values: dict[str, Any] = {}
        for name in (*FIELDS, "note"):
            while True:
                unit = f" ({UNITS[name]})" if UNITS.get(name) else ""
                default = last.get(name, "")
                text = _ask(f"{name}{unit} [{default}]: ")
                if text is None or text.strip().lower() == "q":
                    return code
                text = text.strip() or str(default)
                if name == "note":  # checked here, as --note is: not after the row is measured
                    try:
                        values[name] = check_text(text, "note", max_chars=MAX_FIELD_CHARS)
                        break
                    except TextError as exc:
                        print(f"  {exc}; type it again", flush=True)
                        continue
                value, message = validate_field(name, text, combinations)
                if not message and name == "combo":
                    # Checked against the angles here, so that only the combination is asked again
                    # (it was checked after the note, and the whole row asked again from x).
                    truth = GroundTruth(**{k: values[k] for k in FIELDS[:6]}, combo=value)
                    problem = combo_problem(truth, args.force_combo, session.info.pose_frame)
                    message = problem.removeprefix("--combo: ")
                if not message:
                    values[name] = value
                    last[name] = text
                    break
                print(f"  {name}: {message}", flush=True)
        truth = GroundTruth(**{k: values[k] for k in FIELDS})  # its combination fits (checked above)
        frames = args.frames or session.info.frames_per_row
        print(f"measuring row {session.next_row}: {frames} frames…", flush=True)
        measurement = recorder.measure(
            truth, frames, note=values["note"], until=ended, frame_timeout_s=args.frame_timeout_s
        )
        if measurement is None:
            say(f"nothing logged: {recorder.last_problem}")
            return 1
        code = _log(session, measurement, args.force_combo) or code
        if _ask("Enter for the next row, q to quit: ") in (None, "q", "Q"):
            return code
    return code


# ------------------------------------------------------------------------------------ undo
def _add_undo(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count

    parser.add_argument("folder", metavar="FOLDER", help="the session folder")
    parser.add_argument(
        "--row", type=count("--row", 1), default=None, metavar="K", help="withdraw row K (default: the last)"
    )


def _run_undo(args: argparse.Namespace) -> int:
    from qrfield.sessions import Session

    with Session.open(args.folder) as session:
        outcome = session.undo() if args.row is None else session.withdraw(args.row)
        if not outcome.ok:
            # This process ends now: nothing is kept in memory for a retry (the app's words), and a
            # failed append is cut back, so rows.csv still holds the row in force.
            say(
                f"NOT withdrawn: {outcome.reason}; {session.rows_path.name} is unchanged and row "
                f"{outcome.row} stays in force. Free space or fix permissions and run undo again"
            )
            return 1
        print(f"withdrew row {outcome.row} (its line stays in rows.csv, marked withdrawn)")
    return 0


# ------------------------------------------------------------------------------------ list / show
def _add_list(parser: argparse.ArgumentParser) -> None:
    from qrfield.runconfig import add_config_dir_argument

    parser.add_argument(
        "root",
        nargs="?",
        metavar="ROOT",
        help="the folder that holds sessions (default: the app's sessions folder, as for 'new')",
    )
    add_config_dir_argument(parser)


def _counts(content: Any) -> str:
    active = passed = withdrawn = 0
    for row in content.rows:  # one at a time: rows.csv is never held whole
        if row.withdrawn:
            withdrawn += 1
        else:
            active += 1
            passed += row.passed
    return f"{active} rows, {passed} pass, {withdrawn} withdrawn"


def _run_list(args: argparse.Namespace) -> int:
    from qrfield.runconfig import ConfigStore
    from qrfield.sessions import SessionError, read_session, session_folders
    from qrfield.sessions.folders import configured_root

    if args.root:
        root = Path(args.root)
    else:
        store = ConfigStore()
        for problem in store.problems:
            say(f"settings: {problem}")
        root = configured_root(store)
        say(f"sessions in {root} (the app's sessions folder)")
        if not root.is_dir():
            say(f"no sessions in {root} yet")
            return 0
    if not root.is_dir():
        if root.exists():  # a session's file, or a typo that names a file: not "no such folder"
            raise ValueError(f"{root}: not a folder (give the folder that holds the sessions)")
        raise ValueError(f"{root}: no such folder")
    folders = session_folders(root)
    if not folders:
        say(f"no sessions in {root}")
    for folder in folders:
        try:
            info, content = read_session(folder)
        except (SessionError, OSError) as exc:
            print(f"{folder.name}  (unreadable: {exc})")
            continue
        print(f"{folder.name}  {info.solver}, {info.side_mm:g} mm, {info.camera.name}: {_counts(content)}")
    return 0


def _add_show(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", metavar="FOLDER", help="the session folder")


def _run_show(args: argparse.Namespace) -> int:
    from qrfield.handeye import PoseFrame
    from qrfield.sessions import read_session

    info, content = read_session(args.folder)
    cam = info.camera
    print(f"session {info.name} ({Path(args.folder).resolve()})")
    print(f"  created {info.created}, operator {info.operator or '-'}, app {info.app_version}")
    print(f"  camera {cam.name} {cam.width}x{cam.height} (fx {cam.fx:.1f}), QR side {info.side_mm:g} mm")
    print(f"  solver {info.solver}, {info.frames_per_row} frames per row, criteria {info.criteria.label()}")
    print(
        f"  poses in the {info.pose_frame} frame"
        + (
            f" ({PoseFrame.from_saved(info.pose_frame, info.handeye, info.name).describe()})"
            if info.handeye
            else ""
        )
    )
    if info.notes:
        print(f"  notes: {' '.join(info.notes.split())}")
    print(f"  {_counts(content)}")
    for warning in content.warnings:
        print(f"  warning: {warning}")
    head = f"{'row':>4} {'combo':<18} {'truth x y z (mm), a b g (deg)':<44} {'measured':<44} conv  pass"
    print(head)
    for row in content.rows:
        v = row.values
        truth = " ".join(v.get(f"gt_{k}", "") for k in POSE_NAMES)
        measured = " ".join(v.get(k, "") or "-" for k in POSE_NAMES)
        verdict = "withdrawn" if row.withdrawn else ("pass" if row.passed else "fail")
        conv = f"{v.get('n_converged', '')}/{v.get('n_frames', '')}"
        print(f"{row.number:>4} {row.combo:<18} {truth:<44} {measured:<44} {conv:<5} {verdict}")
    return 0


# ------------------------------------------------------------------------------------ export
def _add_export(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", metavar="FOLDER", help="the session folder")
    parser.add_argument(
        "--out",
        default=None,
        metavar="PATH",
        help="the CSV to write (a folder: rows-clean.csv in it; default: rows-clean.csv in the session's "
        "folder, beside rows.csv, as the app exports); only the rows still in force, units in the "
        "column names (gt_x_mm, err_alpha_deg, ...)",
    )
    parser.add_argument("--force", action="store_true", help="overwrite the CSV if it exists")


def _run_export(args: argparse.Namespace) -> int:
    from qrfield.arguments import refuse_existing
    from qrfield.sessions.export import default_export_path, export_path, write_export

    target = export_path(args.folder, args.out) if args.out else default_export_path(args.folder)
    refuse_existing(target, args.force, "--out" if args.out else "the export")
    done = write_export(args.folder, target, overwrite=args.force)
    for warning in done.warnings:
        say(f"warning: {warning}")
    print(f"exported {done.rows} rows to {done.path}")
    return 0


SUBCOMMANDS: dict[str, Subcommand] = {
    "new": Subcommand(
        "create a session folder (camera, QR side, solver from the options or the config)", _add_new, _run_new
    ),
    "log": Subcommand(
        "measure and log one row (or, without --truth, ask for each field)", _add_log, _run_log
    ),
    "run-plan": Subcommand(
        "log a plan's targets one by one: the virtual bench is set to each, a camera's operator is asked",
        lambda parser: _run_plan().add_arguments(parser),
        lambda args: _run_plan().run(args),
    ),
    "undo": Subcommand("withdraw the last row (a withdrawal record is appended)", _add_undo, _run_undo),
    "list": Subcommand("list the sessions in a folder", _add_list, _run_list),
    "show": Subcommand("print a session's setup and rows", _add_show, _run_show),
    "export": Subcommand(
        "write the rows still in force as a clean CSV (units in the column names)", _add_export, _run_export
    ),
}


def _run_plan() -> Any:
    from qrfield.commands import _run_plan as module

    return module


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="session_command", metavar="SUBCOMMAND", required=True)
    for name, command in SUBCOMMANDS.items():
        sp = sub.add_parser(name, help=command.help, description=command.help)
        command.add_arguments(sp)
        sp.set_defaults(_session_run=command.run)


def run(args: argparse.Namespace) -> int:
    from qrfield.sessions import GroundTruthError, SessionError
    from qrfield.sessions.plan import PlanError

    try:
        return int(args._session_run(args) or 0)
    except PlanError as exc:
        for problem in exc.problems:
            say(f"error: {problem}")
        return 2
    except GroundTruthError as exc:
        for name, message in exc.errors.items():
            say(f"error: {name}: {message}")
        return 2
    except SessionError as exc:
        say(f"error: {exc}")
        return 2
