"""The controller's commands (docs/conventions.md): PING, STREAM, MEAS answered per the conventions.

Answers are decoded by tests/serial_truth.py (written from the conventions, no shared code); the
expected means and deviations are worked out by hand in the comments; time is a fake clock, so no
test here waits for a deadline.
"""

from __future__ import annotations

import re
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import pytest
from serial_truth import command_line, frames_and_answers, parse_answer_line

from qrfield.serial_controller import CommandHandler, GripperLink
from qrfield.serial_frames import FrameDecoder
from qrfield.serial_link import CONNECTED, SerialLinkSettings

pytestmark = pytest.mark.timeout(30)


@dataclass
class Pose:
    position_mm: np.ndarray
    angles_deg: np.ndarray
    converged: bool = True


@dataclass
class Result:
    """The part of a pipeline FrameResult the controller's side reads."""

    t_ms: int
    status: str = "OK"
    primary: Pose | None = None


def ok(t_ms: int, position, angles) -> Result:
    return Result(t_ms, "OK", Pose(np.array(position, float), np.array(angles, float)))


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@dataclass
class Harness:
    clock: Clock = field(default_factory=Clock)
    sent: list[bytes] = field(default_factory=list)
    streaming: list[bool] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.handler = CommandHandler(self.sent.append, self.streaming.append, self.clock)
        self.decoder = FrameDecoder()

    def command(self, *fields: str) -> None:
        for item in self.decoder.feed(command_line(*fields)):  # bytes a controller writes
            self.handler.handle(item)

    def answers(self) -> list[dict]:
        return [parse_answer_line(line) for line in self.sent]


def test_ping_stream_and_unknown_commands_are_answered_at_once() -> None:
    h = Harness()
    h.command("PING")
    h.command("STREAM", "OFF")
    h.command("STREAM", "ON")
    h.command("STREAM", "MAYBE")
    h.command("HOME")
    assert h.streaming == [False, True]
    answers = h.answers()
    assert answers[:3] == [
        {"type": "QRA", "command": c, "result": "OK"} for c in ("PING", "STREAM", "STREAM")
    ]
    assert answers[3]["command"] == "STREAM" and answers[3]["result"] == "ERR"
    assert answers[4]["command"] == "HOME" and answers[4]["result"] == "ERR"
    assert all("," not in a.get("reason", "") and len(a.get("reason", "")) <= 40 for a in answers)


@pytest.mark.parametrize("arg", [("0",), ("101",), ("x",), (), ("5", "6"), ("-3",)])
def test_meas_with_a_bad_count_is_an_error(arg) -> None:
    h = Harness()
    h.command("MEAS", *arg)
    (answer,) = h.answers()
    assert answer["command"] == "MEAS" and answer["result"] == "ERR" and "1..100" in answer["reason"]


def test_meas_averages_the_next_n_converged_frames_with_circular_angles() -> None:
    h = Harness()
    h.handler.on_result(ok(10, [99, 99, 99], [0, 0, 0]), simulated=False)  # before MEAS: not counted
    h.command("MEAS", "4")
    frames = [
        ok(40, [10, 20, 300], [5, 0, 179]),
        Result(73, "NOQR"),  # no code: skipped, not counted
        ok(106, [12, 18, 302], [7, 0, -179]),
        Result(139, "NOCONV", Pose(np.full(3, np.nan), np.full(3, np.nan), converged=False)),
        ok(172, [10, 20, 300], [5, 0, 179]),
    ]
    for result in frames:
        h.handler.on_result(result, simulated=False)
    assert h.sent == []  # three converged so far
    h.handler.on_result(ok(205, [12, 18, 302], [7, 0, -179]), simulated=False)
    (answer,) = h.answers()
    # By hand: x 10,12,10,12 -> mean 11, sample std sqrt(4 * 1^2 / 3) = 1.1547 -> 1.2 (1 decimal);
    # y 20,18,.. -> 19, 1.2; z 300,302,.. -> 301, 1.2; alpha 5,7,.. -> 6.00, 1.15; beta 0, 0.00;
    # gamma 179,-179,..: circular mean 180.00 (not 0), deviations +-1 -> 1.15.
    assert answer["type"] == "QRM" and answer["status"] == "OK" and answer["n_used"] == 4
    assert answer["pose"] == [11.0, 19.0, 301.0, 6.0, 0.0, 180.0]
    assert answer["std"] == [1.2, 1.2, 1.2, 1.15, 0.0, 1.15]
    assert answer["t_ms"] == 205 and answer["seq"] == 0  # the last frame averaged; the first answer
    raw = h.sent[0].decode()
    assert ",180.00," in raw and ",1.15," in raw  # 2 decimals for angles, as in $QRF


def test_one_frame_has_zero_spread_and_a_simulated_frame_makes_it_sim() -> None:
    h = Harness()
    h.command("MEAS", "1")
    h.handler.on_result(ok(5, [1, 2, 3], [4, 5, 6]), simulated=True)
    h.command("MEAS", "2")
    h.handler.on_result(ok(6, [1, 2, 3], [4, 5, 6]), simulated=False)
    h.handler.on_result(ok(7, [1, 2, 3], [4, 5, 6]), simulated=True)
    first, second = h.answers()
    assert (first["status"], first["std"], first["n_used"], first["seq"]) == ("SIM", [0.0] * 6, 1, 0)
    assert (second["status"], second["n_used"], second["seq"]) == ("SIM", 2, 1)


def test_a_second_meas_while_collecting_is_busy() -> None:
    h = Harness()
    h.command("MEAS", "3")
    h.command("MEAS", "3")
    (answer,) = h.answers()
    assert answer["result"] == "ERR" and "busy" in answer["reason"]


@pytest.mark.parametrize(
    ("frames", "down", "status"),
    [
        ([], False, "TIMEOUT"),  # no frames at all
        (["ok", "ok"], False, "TIMEOUT"),  # fewer than n converged
        (["noqr", "noqr"], False, "NOQR"),  # the card is not seen
        (["noqr", "noconv"], False, "NOCONV"),  # the last frame: seen, not converged
        (["ok"], True, "NOSRC"),  # the source went down
    ],
)
def test_meas_that_cannot_complete_times_out_with_a_reason(frames, down, status) -> None:
    h = Harness()
    h.command("MEAS", "5")  # deadline 2 s + 5 / 5 s = 3 s after the command
    for k, kind in enumerate(frames):
        result = {
            "ok": ok(k, [1, 2, 3], [0, 0, 0]),
            "noqr": Result(k, "NOQR"),
            "noconv": Result(k, "NOCONV"),
        }[kind]
        h.handler.on_result(result, simulated=False)
    if down:
        h.handler.on_source_down()
    h.clock.t += 2.99
    h.handler.poll()
    assert h.sent == []
    h.clock.t += 0.02
    h.handler.poll()
    (answer,) = h.answers()
    assert answer == {"type": "QRM", "seq": 0, "t_ms": answer["t_ms"], "status": status} | {
        "pose": None,
        "std": None,
        "n_used": None,
    }
    h.handler.poll()
    assert len(h.sent) == 1  # answered once


def test_lines_of_other_talkers_are_ignored() -> None:
    h = Harness()
    for item in h.decoder.feed(
        b"$QRF,7,100,,,,,,,NOQR*6D\r\n" + command_line("PING").replace(b"QRC", b"XYZ")
    ):
        h.handler.handle(item)
    assert h.sent == []


class FakePort:
    """A port whose incoming bytes the test supplies and whose written bytes it reads."""

    def __init__(self) -> None:
        self.incoming = bytearray()
        self.written = bytearray()
        self.lock = threading.Lock()

    def write(self, data: bytes) -> int:
        with self.lock:
            self.written += data
        return len(data)

    def read(self, size: int = 1) -> bytes:
        with self.lock:
            data, self.incoming[:] = bytes(self.incoming[:size]), self.incoming[size:]
        return data

    def close(self) -> None:
        pass


def wait_for(predicate, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def test_gripper_link_answers_on_its_port_and_sends_ok_only_for_a_live_camera() -> None:
    port = FakePort()
    settings = SerialLinkSettings(port="fake", max_rate_hz=1000, stale_after_s=0)
    link = GripperLink(settings, opener=lambda s: port).start()
    try:
        assert link.wait_for_state(CONNECTED, 5)
        link.on_result(ok(1, [1, 2, 3], [4, 5, 6]), simulated=True)
        wait_for(lambda: b"SIM*" in port.written)
        link.on_result(ok(2, [1, 2, 3], [4, 5, 6]), simulated=False)
        wait_for(lambda: b",OK*" in port.written)
        with port.lock:
            port.incoming += command_line("PING") + command_line("MEAS", "2")
        wait_for(lambda: b"$QRA,PING,OK" in port.written)
        for t in (3, 4):
            link.on_result(ok(t, [1, 2, 3], [4, 5, 6]), simulated=False)
        wait_for(lambda: b"$QRM" in port.written)
        link.on_source_down("unplugged")
        wait_for(lambda: b"NOSRC" in port.written)
    finally:
        link.close()
    frames, answers = frames_and_answers(bytes(port.written))
    assert [f["status"] for f in frames[:2]] == ["SIM", "OK"] and frames[-1]["status"] == "NOSRC"
    assert answers[0] == {"type": "QRA", "command": "PING", "result": "OK"}
    assert answers[1]["status"] == "OK" and answers[1]["pose"] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert link.status().answers_sent == 2


def test_the_example_lines_in_docs_serial_md_are_valid() -> None:
    from pathlib import Path

    from serial_truth import parse_frame_line, parse_line

    text = (Path(__file__).resolve().parent.parent / "docs" / "serial.md").read_text(encoding="utf-8")
    lines = re.findall(r"\$Q[A-Z]{2},[^\s`*]*\*[0-9A-F]{2}", text)
    assert len(lines) >= 10
    for line in lines:
        data = line.encode() + b"\r\n"
        parse_frame_line(data) if line.startswith("$QRF") else parse_line(data)
        if line.startswith(("$QRA", "$QRM")):
            parse_answer_line(data)
