"""The controller's commands (docs/conventions.md, "Serial protocol 2"), answered in order.

Answers are decoded by tests/serial_truth.py (written from the conventions, no shared code); the
expected means and uncertainties are worked out by hand in the comments; time is a fake clock, so
no test here waits for a deadline.
"""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass, field

import numpy as np
import pytest
from serial_truth import command_line, crc16, frames_and_answers, parse_answer_line
from waiting import wait_until

from qrfield import __version__
from qrfield.serial.codec import FrameDecoder
from qrfield.serial.controller import MAX_WAITING, CommandHandler, GripperLink
from qrfield.serial.link import CONNECTED, SerialLinkSettings

pytestmark = pytest.mark.timeout(30)


@dataclass
class Pose:
    position_mm: np.ndarray
    angles_deg: np.ndarray
    converged: bool = True
    position_std_mm: np.ndarray = field(default_factory=lambda: np.array([0.5, 0.5, 2.0]))
    angles_std_deg: np.ndarray = field(default_factory=lambda: np.array([0.2, 0.2, 0.1]))


@dataclass
class Result:
    """The part of a pipeline FrameResult the controller's side reads."""

    t_ms: int
    status: str = "OK"
    primary: Pose | None = None
    ambiguous: bool = False


def ok(t_ms: int, position, angles, ambiguous: bool = False) -> Result:
    return Result(t_ms, "OK", Pose(np.array(position, float), np.array(angles, float)), ambiguous)


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@dataclass
class FakeLink:
    """What the commands need of a link; answers are 'written' when the test says so."""

    sent: list[bytes] = field(default_factory=list)
    streaming: list[bool] = field(default_factory=list)
    rates: list[float] = field(default_factory=list)
    unwritten: int = 0

    def send_line(self, line: bytes) -> bool:
        self.sent.append(line)
        return True

    def set_streaming(self, on: bool) -> None:
        self.streaming.append(on)

    def set_rate(self, hz: float) -> None:
        self.rates.append(hz)

    def answers_waiting(self) -> int:
        return self.unwritten


@dataclass
class Harness:
    clock: Clock = field(default_factory=Clock)
    link: FakeLink = field(default_factory=FakeLink)

    def __post_init__(self) -> None:
        self.handler = CommandHandler(self.link, self.clock)
        self.decoder = FrameDecoder(report_rejected=True)

    def feed(self, data: bytes) -> None:
        for item in self.decoder.feed(data):  # bytes a controller writes
            self.handler.handle(item)

    def command(self, *fields: str) -> None:
        self.feed(command_line(*fields))

    @property
    def sent(self) -> list[bytes]:
        return self.link.sent

    def answers(self) -> list[dict]:
        return [parse_answer_line(line) for line in self.link.sent]


def test_each_command_gets_one_answer_in_order() -> None:
    h = Harness()
    h.handler.context.side_mm, h.handler.context.camera = 50.0, "pi-hq@2028x1520"
    for fields in (
        ("PING",),
        ("HELLO",),
        ("STREAM", "OFF"),
        ("STREAM", "ON"),
        ("RATE", "12.5"),
        ("RATE", "0"),
    ):
        h.command(*fields)
    h.command("STREAM", "MAYBE")
    h.command("HOME")
    h.command("PING", "1")
    h.command("RATE", "1e3")
    h.command("TOOL", "1", "2", "3", "1", "0", "0", "0")
    h.command("HANDEYE")
    h.feed(b"$QRC,PING*0000\r\n")  # a wrong CRC
    h.feed(b"$QRC,PING\r")  # no CRC, a CR alone ends it
    answers = h.answers()
    got = [(a["command"], a["result"], *a["values"]) for a in answers]
    assert got[:6] == [
        ("PING", "OK"),
        ("HELLO", "QRF2", __version__, "50.0", "pi-hq@2028x1520", "camera"),
        ("STREAM", "OK"),
        ("STREAM", "OK"),
        ("RATE", "OK", "12.5"),
        ("RATE", "OK", "0"),
    ]
    assert h.link.streaming == [False, True] and h.link.rates == [12.5, 0.0]
    assert [(a["command"], a["result"]) for a in answers[6:]] == [
        ("STREAM", "ERR"),
        ("HOME", "ERR"),
        ("PING", "ERR"),  # PING takes no argument: an error, not "unknown"
        ("RATE", "ERR"),  # the strict number grammar: no exponent
        ("TOOL", "ERR"),
        ("HANDEYE", "ERR"),
        ("?", "ERR"),
        ("?", "ERR"),
    ]
    assert (
        answers[7]["reason"] == "unknown command" and answers[-2]["reason"] == "CRC" == answers[-1]["reason"]
    )
    assert "hand-eye" in answers[10]["reason"]
    assert all("," not in a.get("reason", "") and len(a.get("reason", "")) <= 40 for a in answers)
    assert h.handler.last_command == "$QRC,PING -> QRA,?,ERR,CRC"


def test_a_meas_holds_the_commands_after_it_until_its_answer_is_out() -> None:
    h = Harness()
    h.command("MEAS", "2")
    h.command("PING")
    h.command("MEAS", "1")
    assert h.sent == []  # the PING waits behind the MEAS: one answer per command, in order
    for t in (1, 2, 3):
        h.handler.on_result(ok(t, [1, 2, 300], [0, 0, 0]), simulated=False)
    kinds = [(a["type"], a.get("command"), a.get("n_used")) for a in h.answers()]
    assert kinds == [("QRM", None, 2), ("QRA", "PING", None), ("QRM", None, 1)]
    assert [a["seq"] for a in h.answers() if a["type"] == "QRM"] == [0, 1]


def test_more_than_16_waiting_commands_overflow_and_say_so_once_drained() -> None:
    h = Harness()
    h.command("MEAS", "1")  # holds the queue
    for _ in range(MAX_WAITING + 4):
        h.command("PING")
    assert h.sent == []
    h.handler.on_result(ok(1, [1, 2, 300], [0, 0, 0]), simulated=False)
    answers = h.answers()
    # MEAS plus 15 PINGs waited (16 in all); 5 PINGs were discarded and that is said last.
    assert answers[0]["type"] == "QRM" and [a["command"] for a in answers[1:16]] == ["PING"] * 15
    assert (answers[16]["command"], answers[16]["reason"], answers[16]["values"]) == (
        "?",
        "OVERFLOW",
        ["OVERFLOW", "5"],
    )
    assert len(answers) == 17
    h.link.unwritten = MAX_WAITING  # answers not yet on the wire count as waiting too
    h.command("PING")  # discarded; nothing of ours waits, so that is said at once
    h.link.unwritten = 0
    h.command("PING")
    assert [a["values"] if a["result"] == "ERR" else a["result"] for a in h.answers()[17:]] == [
        ["OVERFLOW", "1"],
        "OK",
    ]


@pytest.mark.parametrize("arg", [("0",), ("101",), ("x",), (), ("5", "6"), ("-3",)])
def test_meas_with_a_bad_count_is_an_error(arg) -> None:
    h = Harness()
    h.command("MEAS", *arg)
    (answer,) = h.answers()
    assert answer["command"] == "MEAS" and answer["result"] == "ERR" and "1..100" in answer["reason"]


def test_meas_averages_the_next_n_converged_frames_with_a_standard_uncertainty_of_the_mean() -> None:
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
    # By hand (qrfield.sessions.averaging: sem^2 = rho sigma^2 + max(s^2, (1 - rho) sigma^2) / n,
    # rho = FRAME_SHARED_SHARE, frames of a still card share their error): x 10,12,10,12 -> mean
    # 11, s^2 = 4/3; sigma 0.5, rho 0.67: 0.1675 + 1.3333 / 4 = 0.5008 -> 0.7; y (rho 0.68) 0.7;
    # z 300,302: sigma 2, rho 0.68: 2.72 + 0.3333 -> 1.747 -> 1.7. alpha 5,7: sigma 0.2, rho 0.57:
    # 0.0228 + 0.3333 -> 0.597 -> 0.60; beta 0: rho 0.61: 0.0244 + 0.39 * 0.04 / 4 -> 0.168 -> 0.17;
    # gamma 179,-179: circular mean 180.00, deviations +-1, sigma 0.1, rho 0.52: 0.0052 + 0.3333 -> 0.58.
    assert answer["type"] == "QRM" and answer["status"] == "OK" and answer["n_used"] == 4
    assert answer["pose"] == [11.0, 19.0, 301.0, 6.0, 0.0, 180.0]
    assert answer["std"] == [0.7, 0.7, 1.7, 0.6, 0.17, 0.58]
    assert answer["t_ms"] == 205 and answer["seq"] == 0


def test_meas_of_filtered_frames_keeps_their_sigma_as_the_mean_uncertainty() -> None:
    """Frames the stream filter made have already averaged their own noise: the mean's sigma is
    theirs (qrfield.sessions.averaging), not shrunk again by the number of frames."""
    from qrfield.pipeline import FrameResult
    from qrfield.stream import StreamMark

    h = Harness()
    h.command("MEAS", "4")
    for k in range(4):
        pose = Pose(np.array([10.0, 20.0, 300.0 + 0.01 * k]), np.array([5.0, 0.0, 30.0]))
        result = FrameResult(
            k, 33 * k, "OK", poses={"ippe": pose}, stream={"ippe": StreamMark("frame", True, False)}
        )
        h.handler.on_result(result, simulated=False)
    (answer,) = h.answers()
    assert answer["n_used"] == 4 and answer["std"] == [0.5, 0.5, 2.0, 0.2, 0.2, 0.1]


def test_simulated_frames_make_sim_and_ambiguous_live_frames_make_ambig() -> None:
    h = Harness()
    h.command("MEAS", "1")
    h.handler.on_result(ok(5, [1, 2, 3], [4, 5, 6]), simulated=True)
    h.command("MEAS", "2")
    h.handler.on_result(ok(6, [1, 2, 3], [4, 5, 6]), simulated=False)
    h.handler.on_result(ok(7, [1, 2, 3], [4, 5, 6], ambiguous=True), simulated=False)
    h.command("MEAS", "1")
    h.handler.on_result(ok(8, [1, 2, 3], [4, 5, 6], ambiguous=True), simulated=True)
    first, second, third = h.answers()
    # One frame: no spread, so its own sigma (0.5 mm, 2.0 mm, 0.2 deg, ...) is the uncertainty.
    assert (first["status"], first["std"], first["n_used"]) == ("SIM", [0.5, 0.5, 2.0, 0.2, 0.2, 0.1], 1)
    assert (second["status"], second["n_used"]) == ("AMBIG", 2)
    assert third["status"] == "SIM"  # made up: never OK, whatever its flip


@pytest.mark.parametrize(
    ("frames", "down", "status"),
    [
        ([], False, "TIMEOUT"),
        (["ok", "ok"], False, "TIMEOUT"),
        (["noqr", "noqr"], False, "NOQR"),
        (["noqr", "noconv"], False, "NOCONV"),
        (["ok"], True, "NOSRC"),
    ],
)
def test_meas_that_cannot_complete_times_out_with_a_reason(frames, down, status) -> None:
    h = Harness()
    h.command("MEAS", "5")  # deadline 2 s + 5 / 5 s = 3 s after the command
    h.command("PING")  # waits behind it
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
    answer, ping = h.answers()
    assert {k: answer[k] for k in ("type", "status", "pose", "std", "n_used")} == {
        "type": "QRM",
        "status": status,
        "pose": None,
        "std": None,
        "n_used": None,
    }
    assert ping["command"] == "PING"
    h.handler.poll()
    assert len(h.sent) == 2  # answered once


def test_lines_of_other_talkers_are_ignored() -> None:
    h = Harness()
    body = b"QRF,7,100,3,,,,,,,,,,,,,NOQR"
    h.feed(b"$%s*%04X\r\n" % (body, crc16(body)) + command_line("PING").replace(b"$QRC", b"$XYZ"))
    assert h.answers() == [
        {"type": "QRA", "command": "?", "result": "ERR", "values": ["CRC"], "reason": "CRC"}
    ]


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


#: The bound of a wait for the link's thread, s.
WAIT_S = 10.0


def connected_link() -> tuple[FakePort, GripperLink]:
    """A GripperLink on a FakePort (no rate limit, no STALE lines), started and connected; the
    caller closes it."""
    port = FakePort()
    settings = SerialLinkSettings(port="fake", max_rate_hz=1000, stale_after_s=0)
    link = GripperLink(settings, opener=lambda s: port).start()
    if not link.wait_for_state(CONNECTED, 5):
        link.close()  # a test never leaves the link's thread running
        raise AssertionError("the link did not connect to its fake port")
    return port, link


def test_gripper_link_answers_on_its_port_and_sends_ok_only_for_an_unambiguous_live_pose() -> None:
    port, link = connected_link()
    try:
        link.on_result(ok(1, [1, 2, 3], [4, 5, 6]), simulated=True)
        wait_until(lambda: b"SIM*" in port.written, WAIT_S)
        link.on_result(ok(2, [1, 2, 3], [4, 5, 6], ambiguous=True), simulated=False)
        wait_until(lambda: b"AMBIG*" in port.written, WAIT_S)
        link.on_result(ok(3, [1, 2, 3], [4, 5, 6]), simulated=False)
        wait_until(lambda: b",OK*" in port.written, WAIT_S)
        with port.lock:
            port.incoming += command_line("PING") + command_line("MEAS", "2")
        wait_until(lambda: b"$QRA,PING,OK" in port.written, WAIT_S)
        for t in (4, 5):
            link.on_result(ok(t, [1, 2, 3], [4, 5, 6]), simulated=False)
        wait_until(lambda: b"$QRM" in port.written, WAIT_S)
        link.on_source_down("unplugged")
        wait_until(lambda: b"NOSRC" in port.written, WAIT_S)
        assert link.status().last_command.startswith("MEAS,2 -> QRM,0,")
    finally:
        link.close()
    frames, answers = frames_and_answers(bytes(port.written))
    assert [f["status"] for f in frames[:3]] == ["SIM", "AMBIG", "OK"] and frames[-1]["status"] == "NOSRC"
    assert frames[2]["sigma"] == [0.5, 0.5, 2.0, 0.2, 0.2, 0.1]
    assert answers[0]["command"] == "PING" and answers[0]["result"] == "OK"
    assert answers[1]["status"] == "OK" and answers[1]["pose"] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert link.status().answers_sent == 2


def test_the_example_lines_in_docs_serial_md_are_valid() -> None:
    from pathlib import Path

    from serial_truth import parse_frame_line, parse_line

    text = (Path(__file__).resolve().parent.parent / "docs" / "serial.md").read_text(encoding="utf-8")
    lines = re.findall(r"\$Q[A-Z]{2},[^\s`*]*\*[0-9A-F]{4}", text)
    assert len(lines) >= 10
    for line in lines:
        data = line.encode() + b"\r\n"
        parse_frame_line(data) if line.startswith("$QRF") else parse_line(data)
        if line.startswith(("$QRA", "$QRM")):
            parse_answer_line(data)
    assert not math.isnan(len(lines))


def test_a_frame_after_the_meas_deadline_does_not_complete_it() -> None:
    """audit-serial: MEAS,1 must be answered TIMEOUT when no converged frame came within 2 s + 1/5 s
    (docs/conventions.md). The deadline is checked by poll(), which the link's thread runs only
    while its port is open; a converged frame 2.5 s after the command, before the next poll (the
    port just vanished), completed the MEAS as OK, 0.3 s late. Now the frame sees the deadline:
    TIMEOUT, answered once."""
    h = Harness()
    h.command("MEAS", "1")  # deadline 2.2 s after the command
    h.clock.t += 2.5
    h.handler.on_result(ok(2500, [1, 2, 3], [0, 0, 0]), simulated=False)
    h.handler.poll()
    (answer,) = h.answers()
    assert (answer["type"], answer["status"], answer["pose"]) == ("QRM", "TIMEOUT", None)


def test_a_meas_under_way_when_the_link_closes_is_answered_nosrc_before_the_last_line() -> None:
    """audit-serial: a folder or video that ends ends ``qrfield run``, and the link closes; a MEAS
    under way then (and a PING queued behind it) went unanswered, though each command gets one
    answer. Now, closing, the MEAS is answered ``$QRM,...,NOSRC`` (the source is gone, as the last
    ``$QRF`` NOSRC line says), the PING after it, both before that last line."""
    port, link = connected_link()
    try:
        link.on_result(ok(1, [1, 2, 3], [4, 5, 6]), simulated=False)
        with port.lock:
            port.incoming += command_line("MEAS", "5") + command_line("PING")
        wait_until(lambda: link.commands.handled == 2, WAIT_S)
        link.on_result(ok(2, [1, 2, 3], [4, 5, 6]), simulated=False)  # 1 of 5 frames
    finally:
        link.close()
    frames, answers = frames_and_answers(bytes(port.written))
    assert [(a["type"], a["status"] if a["type"] == "QRM" else a["result"]) for a in answers] == [
        ("QRM", "NOSRC"),
        ("QRA", "OK"),
    ]
    assert answers[0]["pose"] is None and frames[-1]["status"] == "NOSRC"
    written = bytes(port.written)
    assert written.index(b"$QRA,PING") < written.rindex(b"NOSRC*")
