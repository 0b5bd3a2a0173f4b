"""The whole hand-eye workflow over serial without hardware: a simulated robot, the virtual bench, a
scripted controller (``qrfield serial-demo --robot``, docs/handeye.md).

:func:`run_robot_demo` sets up both ends of a serial line: qrfield's side is the frame loop of
``qrfield run --serial`` (the virtual bench, a :class:`~qrfield.serial.controller.GripperLink` with
:class:`~qrfield.serial.handeye.HandEyeCommands`) on a pty behind a
:class:`~qrfield.serial.relay.UartRelay` (a UART's pace at the chosen baud); the controller's side
is a script standing for a robot program: it moves a :class:`~qrfield.handeye.SimulatedRobot` (a
known camera-to-tool or camera-to-base transform) to each chosen tool pose, which puts the bench's
card where the camera sees the code from there, sends ``$QRC,TOOL`` with that pose and waits for
the answer; then ``$QRC,HANDEYE``. The result says what was sent and answered, the calibration
saved and its error against the known transform.

The bench is not a live camera, so the answers carry SIM and the file is ``handeye-simulated.json``
(:mod:`qrfield.serial.handeye`).
"""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.handeye import HandEyeCalibration, SimulatedRobot
from qrfield.handeye.rigid import difference, quaternion_from_rotation
from qrfield.methods import NUMERICAL
from qrfield.serial import codec

#: The demo's defaults: 15 tool poses, a 50 mm code, 30 frames a second, 115200 baud.
DEFAULT_POSES, DEFAULT_SIDE_MM, DEFAULT_FPS, DEFAULT_BAUD = 15, 50.0, 30.0, 115200
#: How long the script waits for one answer (TOOL answers within its own 3 s timeout).
ANSWER_TIMEOUT_S = 30.0


@dataclass
class RobotDemoResult:
    """What the demo did and found.

    Attributes:
        robot: the simulated cell (its ``transform`` is the truth).
        exchanges: (command line, answer line) for each command, without CR LF, in order.
        pairs: the pairs qrfield recorded; refused: TOOL commands answered ERR.
        handeye: the HANDEYE answer (decoded), or None when none came.
        calibration: the saved file, read back, or None.
        error_mm, error_deg: the saved transform against the robot's, mm and degrees (NaN: none).
    """

    robot: SimulatedRobot
    exchanges: list[tuple[str, str]] = field(default_factory=list)
    pairs: int = 0
    refused: int = 0
    handeye: codec.QraAnswer | None = None
    calibration: HandEyeCalibration | None = None
    error_mm: float = math.nan
    error_deg: float = math.nan


def tool_arguments(tool_in_base: np.ndarray) -> tuple[str, ...]:
    """TOOL's seven fields for a tool pose T_base_tool (4, 4): x, y, z (mm, 3 decimals) and the
    unit quaternion qw, qx, qy, qz (7 decimals), as a controller would print them."""
    q = quaternion_from_rotation(np.asarray(tool_in_base, dtype=float)[:3, :3])
    return (*(f"{v:.3f}" for v in tool_in_base[:3, 3]), *(f"{v:.7f}" for v in q))


class _Controller:
    """The controller's end of the relay: sends commands, collects the $QRA answers in order."""

    def __init__(self, relay: Any) -> None:
        self.relay = relay
        self.decoder = codec.FrameDecoder()
        self.answers: queue.Queue[tuple[bytes, codec.QraAnswer]] = queue.Queue()

    def on_line(self, line: bytes, _arrived: float) -> None:  # the relay's thread
        for item in self.decoder.feed(line):
            if isinstance(item, codec.QraAnswer):
                self.answers.put((line.rstrip(b"\r\n"), item))

    def ask(self, command: str, *args: str) -> tuple[str, codec.QraAnswer]:
        line = codec.encode_command(command, *args)
        self.relay.send(line)
        try:
            text, answer = self.answers.get(timeout=ANSWER_TIMEOUT_S)
        except queue.Empty:
            raise TimeoutError(f"no answer to {command} within {ANSWER_TIMEOUT_S:g} s") from None
        return text.decode("ascii", "replace"), answer


def run_robot_demo(
    setup: str,
    folder: str | Path,
    *,
    poses: int = DEFAULT_POSES,
    seed: int = 0,
    camera: Any = None,
    side_mm: float = DEFAULT_SIDE_MM,
    fps: float = DEFAULT_FPS,
    baud: int = DEFAULT_BAUD,
    robot: SimulatedRobot | None = None,
    on_exchange: Callable[[str, str], None] | None = None,
) -> RobotDemoResult:
    """Run the workflow once (see the module docstring); the calibration is saved in ``folder``.

    ``setup``: eye-in-hand or eye-to-hand; ``poses``: how many tool poses the script visits
    (:meth:`SimulatedRobot.viewing_tool_poses` with ``seed``: the code 250-380 mm away, tilted up to
    32 deg); ``camera``: the bench's model (default the default camera); ``robot``: the cell
    (default :meth:`SimulatedRobot.example`); ``on_exchange(command, answer)``: called as each
    answer comes (the command's thread). Everything it starts is stopped before it returns.
    """
    from qrfield.camera import DEFAULT_CAMERA, resolve_camera
    from qrfield.engine import FrameLoop
    from qrfield.runconfig import RunConfig
    from qrfield.serial.controller import GripperLink
    from qrfield.serial.handeye import HandEyeCommands
    from qrfield.serial.link import CONNECTED, SerialLinkSettings
    from qrfield.serial.relay import UartRelay
    from qrfield.sources import VirtualBenchSettings, VirtualBenchSource
    from qrfield.sources.kinds import VIRTUAL

    camera = camera if camera is not None else resolve_camera(DEFAULT_CAMERA)
    robot = robot if robot is not None else SimulatedRobot.example(setup)
    if robot.setup != setup:
        raise ValueError(f"the robot is {robot.setup}, the demo asked for {setup}")
    if not 5 <= poses <= 100:
        raise ValueError(f"poses must be 5..100 (a calibration needs at least 5), got {poses}")
    tools = robot.viewing_tool_poses(camera, side_mm, poses, seed=seed)
    folder = Path(folder)
    out = RobotDemoResult(robot)
    bench = VirtualBenchSource(camera, side_mm, VirtualBenchSettings(fps=fps))
    config = RunConfig(source=VIRTUAL, camera=camera, side_mm=side_mm, methods=(NUMERICAL,))
    relay = UartRelay(baud / 10.0)
    controller = _Controller(relay)
    relay.on_line = controller.on_line
    link = GripperLink(SerialLinkSettings(port=relay.device, baud=baud, max_rate_hz=10.0))
    link.set_context(side_mm=side_mm, camera=camera.name)
    info = {
        "camera": camera.name,
        "side_mm": float(side_mm),
        "pose_method": NUMERICAL,
        "demo": "serial-demo",
    }
    link.add_handeye(HandEyeCommands(setup, folder / "handeye.json", info=info))

    def opener(*_args: Any, **_kwargs: Any) -> Any:
        bench.open()
        return bench

    loop = FrameLoop(config, sinks=[link], opener=opener)
    thread = threading.Thread(target=loop.run, name="serial-demo-loop", daemon=True)

    def exchange(command: str, *args: str) -> codec.QraAnswer:
        text, answer = controller.ask(command, *args)
        sent = codec.encode_command(command, *args).decode("ascii").rstrip("\r\n")
        out.exchanges.append((sent, text))
        if on_exchange is not None:
            on_exchange(sent, text)
        return answer

    try:
        link.start()
        if not link.wait_for_state(CONNECTED, 10.0):
            raise RuntimeError(f"the demo's serial link did not connect: {link.status().last_error}")
        thread.start()
        _robot_program(robot, tools, bench, exchange, out)
    finally:
        loop.stop()
        if thread.ident is not None:
            thread.join(10.0)
        link.close()
        relay.close()
    done = link.handeye.status().done
    if out.handeye is not None and out.handeye.ok and done is not None:
        _grade(out, HandEyeCalibration.load(done.path), robot)
    return out


def _robot_program(
    robot: SimulatedRobot,
    tools: Any,
    bench: Any,
    exchange: Callable[..., codec.QraAnswer],
    out: RobotDemoResult,
) -> None:
    """The robot program's side of the demo: HELLO, then per tool pose move the arm, wait until it
    stands still and send TOOL (pairs counted, refusals too), then HANDEYE; answers go to ``out``."""
    exchange("HELLO")
    for tool in tools:
        robot.move(tool, bench)  # the robot program moves the arm and waits until it stands still
        answer = exchange("TOOL", *tool_arguments(tool))
        if answer.ok:
            out.pairs = int(answer.fields[1])
        else:
            out.refused += 1
    out.handeye = exchange("HANDEYE")


def _grade(out: RobotDemoResult, calibration: HandEyeCalibration, robot: SimulatedRobot) -> None:
    """The saved calibration against the cell's true transform: its error in mm and degrees."""
    out.calibration = calibration
    err = difference(calibration.transform, robot.transform)
    out.error_mm = float(np.linalg.norm(err[:3]))
    out.error_deg = float(math.degrees(np.linalg.norm(err[3:])))
