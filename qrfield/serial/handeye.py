"""``$QRC,TOOL`` and ``$QRC,HANDEYE``: hand-eye pairs recorded and solved over serial protocol 2.

docs/conventions.md ("Hand-eye"), docs/serial.md and docs/handeye.md ("Over serial, with the robot").
:class:`HandEyeCommands` puts two handlers into a :class:`~qrfield.serial.controller.CommandHandler`
(through :meth:`GripperLink.add_handeye <qrfield.serial.controller.GripperLink.add_handeye>`), a
frame listener (the camera frame's results) and a poller (the TOOL deadline). The core it calls is
:class:`qrfield.handeye.PairCollector` and :func:`qrfield.handeye.solve_handeye`.

- ``TOOL,<x>,<y>,<z>,<qw>,<qx>,<qy>,<qz>``: the tool frame's pose in the base frame, mm and a unit
  quaternion (norm 1 within 0.001; decimal numbers, an optional sign, no exponent). The next frame
  captured after the command whose pose converged and is not ambiguous makes a pair ->
  ``$QRA,TOOL,OK,<n pairs>``; none within :data:`TOOL_TIMEOUT_S` -> ``$QRA,TOOL,ERR,<why>`` (the
  last frame's problem: no pose, not converged, ambiguous; or no frame; or the source changed).
- ``HANDEYE``: solves the pairs for the configured set-up (``handeye_setup``, or the one of the
  pose frame), saves the calibration (the previous file kept as ``.previous``) and answers
  ``$QRA,HANDEYE,OK,<residual_mm>,<residual_deg>`` (RMS over the pairs, 3 decimals); else
  ``$QRA,HANDEYE,ERR,<what to add or what is wrong>`` (the diversity check's short message) and the
  pairs are kept, so more TOOL commands can follow. After an OK the next TOOL starts a new set.
  The solve runs on a thread of its own: the link keeps streaming, and the commands after HANDEYE
  wait for its answer (one answer per command, in order).

Our decisions where the conventions leave room (docs/serial.md): pairs come from a live camera; in
a run whose source is not one (the virtual bench, a video, a folder: its poses go out as SIM) they
come from that source, and the answers say so with a last field ``SIM`` (``$QRA,TOOL,OK,3,SIM``,
``$QRA,HANDEYE,OK,0.081,0.012,SIM``); a calibration from such pairs is saved as
``handeye-simulated.json`` beside the file, marked ``"simulated": true``, never over the one a live
camera's run reads, and ``qrfield run`` refuses a file so marked with a live camera. The pairs of
one set never mix the two kinds (the later frames make no pair: "source changed").
"""

from __future__ import annotations

import contextlib
import dataclasses
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.handeye.measure import AMBIGUOUS, NO_POSE, NOT_CONVERGED
from qrfield.handeye.pairs import SOURCE_CHANGED, PairCollector
from qrfield.handeye.rigid import QUATERNION_NORM_TOLERANCE, transform_from_quaternion
from qrfield.handeye.setups import HandEyeError
from qrfield.handeye.store import HandEyeCalibration, save_keeping_previous, simulated_path
from qrfield.limits import TOOL_POSITION_MM
from qrfield.serial import codec
from qrfield.status import WireStatus

#: A TOOL with no usable frame within this many seconds is answered with the reason.
TOOL_TIMEOUT_S = 3.0
#: The last field of a TOOL or HANDEYE answer resting on frames that are not a live camera's.
SIM_MARK = WireStatus.SIM
#: The names of TOOL's seven arguments, in order.
TOOL_FIELDS = ("x", "y", "z", "qw", "qx", "qy", "qz")
# A controller's decimal number: an optional sign, digits, optionally a point and digits.
_DECIMAL = re.compile(r"[+-]?[0-9]{1,12}(?:\.[0-9]{1,12})?")


@dataclass(frozen=True)
class PairInfo:
    """One recorded pair, for a person: its label, the tool's position in the base frame and the
    code's position in the camera frame (mm)."""

    label: str
    tool_mm: tuple[float, float, float]
    code_mm: tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class CalibrationDone:
    """A calibration made by HANDEYE: what was saved where (``previous``: the file it replaced, kept).
    Equal only to itself (its matrices do not compare as one truth value)."""

    calibration: HandEyeCalibration
    path: Path
    previous: Path | None
    simulated: bool


@dataclass(frozen=True)
class HandEyeStatus:
    """A snapshot for a display: the pairs of the current set, whether they are simulated, the
    set-up HANDEYE solves for (None: not configured), the command under way ("" / TOOL / HANDEYE),
    the last TOOL or HANDEYE with its answer, the last calibration made and where it is saved."""

    pairs: tuple[PairInfo, ...]
    simulated: bool
    setup: str | None
    busy: str
    last: str
    done: CalibrationDone | None
    save_to: Path


@dataclass
class _Tool:
    reply: Callable[[bytes], None]
    deadline: float
    text: str
    before: int  # pairs before this TOOL: one more means it was recorded


def parse_tool(args: tuple[str, ...]) -> np.ndarray:
    """T_base_tool (4, 4) of TOOL's arguments; HandEyeError whose ``short`` is the answer's reason
    (at most 40 bytes, no commas) for a wrong count, a bad number, a position beyond any robot's
    reach or a quaternion that is not a unit one."""
    if len(args) != len(TOOL_FIELDS):
        raise HandEyeError(
            f"TOOL takes {len(TOOL_FIELDS)} numbers, got {len(args)}", "give TOOL x y z qw qx qy qz"
        )
    values = []
    for name, text in zip(TOOL_FIELDS, args, strict=True):
        if not _DECIMAL.fullmatch(text.strip()):
            raise HandEyeError(f"TOOL {name}: {text!r} is not a decimal number", f"{name} is not a number")
        values.append(float(text))
    limit = TOOL_POSITION_MM
    for name, value in zip("xyz", values[:3], strict=True):
        if not limit.minimum <= value <= limit.maximum:
            raise HandEyeError(
                f"TOOL {name} = {value:g} mm is beyond {limit.maximum:g} mm",
                f"{name} beyond {limit.maximum:g} mm",
            )
    norm = float(np.linalg.norm(values[3:]))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise HandEyeError(
            f"TOOL qw..qz: not a unit quaternion (norm {norm:.6f}, 1 within {QUATERNION_NORM_TOLERANCE:g})",
            f"not a unit quaternion (norm {min(norm, 999.0):.4f})",
        )
    return transform_from_quaternion(values[:3], values[3:])


def timeout_reason(problem: str, timeout_s: float) -> str:
    """TOOL's reason (at most 40 bytes) when no frame within ``timeout_s`` made a pair: the last
    frame's problem (a kind of :mod:`qrfield.handeye.measure`, SOURCE_CHANGED, or "" for none)."""
    within = f"within {timeout_s:g} s"
    return {
        NO_POSE: f"no pose {within}",
        NOT_CONVERGED: f"no converged pose {within}",
        AMBIGUOUS: "ambiguous: tilt the code 10-30 deg",
        SOURCE_CHANGED: "source changed since the first pair",
    }.get(problem, f"no frame {within}")


class HandEyeCommands:
    """TOOL and HANDEYE (see the module docstring); thread-safe.

    ``setup``: what HANDEYE solves for (None: not configured, HANDEYE answers so). ``save_to``: the
    calibration's file (a simulated one goes to :func:`~qrfield.handeye.store.simulated_path` of
    it). ``info``: more fields saved in the file (camera, side_mm, pose_method). ``method``: the
    pose method whose result makes a pair (None: the first). ``calibrated``: called with a
    :class:`CalibrationDone` on the solve's thread before the answer is sent (the link switches its
    stream there). ``clock``: the deadline's clock.
    """

    def __init__(
        self,
        setup: str | None,
        save_to: str | Path,
        *,
        info: dict[str, Any] | None = None,
        method: str | None = None,
        timeout_s: float = TOOL_TIMEOUT_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.setup = setup
        self.save_to = Path(save_to)
        self.info = dict(info or {})
        self.timeout_s = float(timeout_s)
        self.collector = PairCollector(method)
        self.calibrated: list[Callable[[CalibrationDone], None]] = []
        self._clock = clock
        self._lock = threading.Lock()
        self._tool: _Tool | None = None
        self._solving = False
        self._thread: threading.Thread | None = None
        self._last = ""
        self._done: CalibrationDone | None = None

    @classmethod
    def from_settings(cls, settings: Any, config_dir: Any = None, **options: Any) -> HandEyeCommands:
        """From :class:`~qrfield.handeye.HandEyeSettings`: the set-up of
        :func:`~qrfield.handeye.settings.calibration_setup` (HandEyeError when it does not fit the
        frame) and the file of :func:`~qrfield.handeye.frames.calibration_path`."""
        from qrfield.handeye.frames import calibration_path
        from qrfield.handeye.settings import calibration_setup

        return cls(calibration_setup(settings), calibration_path(settings, config_dir), **options)

    def attach(self, handler: Any) -> None:
        """Answer TOOL and HANDEYE on ``handler`` (a CommandHandler) and watch its frames."""
        handler.handlers["TOOL"] = self._start_tool
        handler.handlers["HANDEYE"] = self._start_handeye
        handler.frame_listeners.append(self.on_frame)
        handler.pollers.append(self.poll)
        handler.closers.append(self.abandon)

    # ----- TOOL
    def _start_tool(self, command: Any, reply: Callable[[bytes], None]) -> None:
        try:
            tool = parse_tool(command.args)
        except HandEyeError as exc:
            self._answer(command.text, reply, codec.encode_error("TOOL", exc.short))
            return
        with self._lock:  # armed before it is seen as waiting: a frame never answers the wrong TOOL
            before = len(self.collector)
            self.collector.expect(tool, f"pose {before + 1}")
            self._tool = _Tool(reply, self._clock() + self.timeout_s, command.text, before)

    def on_frame(self, result: Any, simulated: bool) -> None:
        """One frame result in the camera frame (the frame loop's thread): a pair if TOOL waits."""
        with self._lock:
            if self._tool is None:
                return
        self.collector.on_result(result, simulated)
        self._finish_tool(timed_out=False)

    def poll(self) -> None:
        """Answer a TOOL whose deadline has passed (the link's thread)."""
        self._finish_tool(timed_out=True)

    def _finish_tool(self, timed_out: bool) -> None:
        """Answer the waiting TOOL once its pair is recorded, or (``timed_out``) past its deadline."""
        with self._lock:
            tool = self._tool
            if tool is None:
                return
            recorded = len(self.collector) > tool.before
            if not recorded and not (timed_out and self._clock() >= tool.deadline):
                return
            self._tool = None
            if not recorded:
                self.collector.cancel()  # no frame makes the pair after this: look once more
                recorded = len(self.collector) > tool.before
            simulated = self.collector.simulated
            problem = self.collector.last_problem
            count = len(self.collector)
        if recorded:
            line = codec.encode_ok("TOOL", str(count), *((SIM_MARK,) if simulated else ()))
        else:
            line = codec.encode_error("TOOL", timeout_reason(problem, self.timeout_s))
        self._answer(tool.text, tool.reply, line)

    # ----- HANDEYE
    def _start_handeye(self, command: Any, reply: Callable[[bytes], None]) -> None:
        if command.args:
            self._answer(command.text, reply, codec.encode_error("HANDEYE", "HANDEYE takes no argument"))
            return
        if self.setup is None:
            self._answer(command.text, reply, codec.encode_error("HANDEYE", "no set-up: set handeye_setup"))
            return
        thread = threading.Thread(
            target=self._solve, args=(command.text, reply), name="qrfield-handeye", daemon=True
        )
        with self._lock:
            self._solving, self._thread = True, thread
        thread.start()

    def _solve(self, text: str, reply: Callable[[bytes], None]) -> None:
        try:
            line = self._calibrate()
        except HandEyeError as exc:
            line = codec.encode_error("HANDEYE", exc.short or str(exc))
        except OSError as exc:
            line = codec.encode_error("HANDEYE", f"not saved: {exc.strerror or type(exc).__name__}")
        except Exception as exc:  # a faulty solve still answers
            line = codec.encode_error("HANDEYE", f"failed: {type(exc).__name__}")
        with self._lock:
            self._solving = False
        self._answer(text, reply, line)

    def _calibrate(self) -> bytes:
        assert self.setup is not None
        simulated = self.collector.simulated
        result = self.collector.solve(self.setup)
        info = {**self.info, "pairs_from": "serial ($QRC,TOOL)"}
        if simulated:
            info["simulated"] = True
        calibration = HandEyeCalibration.from_result(result, **info)
        path = simulated_path(self.save_to) if simulated else self.save_to
        from qrfield.files import make_folder

        make_folder(path.parent, "hand-eye folder")
        previous = save_keeping_previous(calibration, path)
        done = CalibrationDone(dataclasses.replace(calibration, path=path), path, previous, simulated)
        with self._lock:
            self._done = done
        for listener in list(self.calibrated):
            with contextlib.suppress(Exception):  # a faulty listener must not lose the answer
                listener(done)
        self.collector.clear()  # the next TOOL starts a new set
        marks = (SIM_MARK,) if simulated else ()
        return codec.encode_ok("HANDEYE", f"{result.residual_mm:.3f}", f"{result.residual_deg:.3f}", *marks)

    # ----- for the caller
    def _answer(self, text: str, reply: Callable[[bytes], None], line: bytes) -> None:
        with self._lock:
            self._last = f"{text[:60]} -> {line.decode('ascii', 'replace').split('*')[0][1:]}"
        reply(line)

    def abandon(self) -> None:
        """Closing: a TOOL still waiting for its frame is answered ``ERR,no frame: the run ended``."""
        with self._lock:
            tool, self._tool = self._tool, None
        if tool is not None:
            self._answer(tool.text, tool.reply, codec.encode_error("TOOL", "no frame: the run ended"))

    def clear(self) -> None:
        """Forget the pairs; a TOOL still waiting is answered ``ERR,pairs cleared`` now."""
        with self._lock:
            tool, self._tool = self._tool, None
            self.collector.clear()
        if tool is not None:
            self._answer(tool.text, tool.reply, codec.encode_error("TOOL", "pairs cleared"))

    def status(self) -> HandEyeStatus:
        """A snapshot (any thread)."""
        pairs = tuple(
            PairInfo(
                p.label,
                tuple(float(v) for v in p.tool_in_base[:3, 3]),  # type: ignore[arg-type]
                tuple(float(v) for v in p.code_in_camera[:3, 3]),  # type: ignore[arg-type]
            )
            for p in self.collector.pairs
        )
        with self._lock:
            busy = "HANDEYE" if self._solving else "TOOL" if self._tool is not None else ""
            return HandEyeStatus(
                pairs, self.collector.simulated, self.setup, busy, self._last, self._done, self.save_to
            )

    def close(self, timeout: float = 2.0) -> None:
        """Wait up to ``timeout`` s for a solve under way (its answer is sent before the link closes)."""
        with self._lock:
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
