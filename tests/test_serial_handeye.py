"""$QRC,TOOL and $QRC,HANDEYE (qrfield.serial.handeye) on the command handler, answers decoded by
tests/serial_truth.py.

The frames are made here: at each tool pose the code's pose in the camera is composed by hand from
a chosen camera-to-tool transform and the code's place (the chain of frames, not the solver's
model), with a little noise; the recovered transform is compared with the chosen one. Time for the
TOOL deadline is a fake clock.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, field

import numpy as np
import pytest
from serial_truth import command_line, parse_answer_line
from test_serial_controller import Clock, FakeLink

from qrfield.handeye.rigid import difference, quaternion_from_rotation, transform_from_pose
from qrfield.serial.codec import FrameDecoder
from qrfield.serial.controller import CommandHandler
from qrfield.serial.handeye import TOOL_TIMEOUT_S, HandEyeCommands, parse_tool

pytestmark = pytest.mark.timeout(60)

# The cell, eye-in-hand: the camera 60 mm beside the flange, the code on the table.
X = transform_from_pose([60.0, -15.0, 40.0], [2.0, -3.0, 90.0])  # camera_to_tool
Y = transform_from_pose([450.0, 30.0, 0.0], [180.0, 0.0, 0.0])  # code in base
# Views: the code 280-340 mm in front of the camera, turned about different axes.
VIEWS = [
    ([5.0, -3.0, 300.0], [12.0, -8.0, 20.0]),
    ([-20.0, 10.0, 320.0], [-15.0, 10.0, -40.0]),
    ([15.0, 20.0, 280.0], [20.0, 15.0, 70.0]),
    ([0.0, -25.0, 340.0], [-10.0, -20.0, -80.0]),
    ([25.0, 5.0, 310.0], [5.0, 25.0, 10.0]),
    ([-10.0, -10.0, 290.0], [-25.0, -5.0, 45.0]),
    ([10.0, 15.0, 330.0], [15.0, -25.0, -15.0]),
]


def tool_for(code_in_camera: np.ndarray) -> np.ndarray:
    """By hand: T_base_marker = T_base_tool X C, so T_base_tool = Y C^-1 X^-1."""
    return Y @ np.linalg.inv(code_in_camera) @ np.linalg.inv(X)


def tool_args(tool: np.ndarray) -> tuple[str, ...]:
    q = quaternion_from_rotation(tool[:3, :3])
    return (*(f"{v:.4f}" for v in tool[:3, 3]), *(f"{v:.9f}" for v in q))


@dataclass
class Pose:
    position_mm: np.ndarray
    angles_deg: np.ndarray
    converged: bool = True
    ambiguous: bool = False
    reason: str = ""
    pose_cov: np.ndarray = field(default_factory=lambda: np.diag([0.05, 0.05, 0.2, 0.03, 0.03, 0.01]) ** 2)


@dataclass
class Result:
    index: int
    pose: Pose | None
    t_capture: float = field(default_factory=time.monotonic)
    t_ms: int = 0
    status: str = "OK"

    @property
    def primary(self) -> Pose | None:
        return self.pose

    @property
    def poses(self) -> dict:
        return {"numerical": self.pose}


def seen(k: int, rng: np.random.Generator, **changes) -> Result:
    position, angles = VIEWS[k]
    noise = rng.normal(0, [0.05, 0.05, 0.2, 0.03, 0.03, 0.01])
    return Result(k, Pose(np.array(position) + noise[:3], np.array(angles) + noise[3:], **changes))


class Harness:
    def __init__(self, tmp_path, setup: str | None = "eye-in-hand") -> None:
        self.clock = Clock()
        self.link = FakeLink()
        self.handler = CommandHandler(self.link, self.clock)
        self.decoder = FrameDecoder(report_rejected=True)
        self.handeye = HandEyeCommands(
            setup, tmp_path / "handeye.json", info={"camera": "test"}, clock=self.clock
        )
        self.handeye.attach(self.handler)

    def command(self, *fields: str) -> None:
        for item in self.decoder.feed(command_line(*fields)):
            self.handler.handle(item)

    def frame(self, result: Result, simulated: bool = False) -> None:
        self.handler.on_result(result, simulated)

    def answers(self) -> list[dict]:
        self.handeye.close(30.0)  # a HANDEYE's solve has answered
        return [parse_answer_line(line) for line in self.link.sent]


def test_tool_records_pairs_and_handeye_recovers_the_transform_saving_the_file(tmp_path) -> None:
    rng = np.random.default_rng(28)
    (tmp_path / "handeye.json").write_text('{"older": true}')
    h = Harness(tmp_path)
    for k, (position, angles) in enumerate(VIEWS):
        h.command("TOOL", *tool_args(tool_for(transform_from_pose(position, angles))))
        h.frame(seen(k, rng))
    h.command("HANDEYE")
    h.command("PING")
    answers = h.answers()
    got = [(a["command"], a["result"], *a["values"]) for a in answers]
    assert got[: len(VIEWS)] == [("TOOL", "OK", str(k + 1)) for k in range(len(VIEWS))]
    handeye = answers[len(VIEWS)]
    assert (handeye["command"], handeye["result"], len(handeye["values"])) == ("HANDEYE", "OK", 2)
    assert got[-1] == ("PING", "OK")  # after the HANDEYE answer: one answer per command, in order
    residual_mm, residual_deg = map(float, handeye["values"])
    assert re_three_decimals(handeye["values"])
    saved = json.loads((tmp_path / "handeye.json").read_text())
    assert json.loads((tmp_path / "handeye.json.previous").read_text()) == {"older": True}
    assert saved["setup"] == "eye-in-hand" and saved["n_pairs"] == len(VIEWS) and saved["camera"] == "test"
    assert "simulated" not in saved
    assert abs(saved["residual_mm"] - residual_mm) < 5e-4 and abs(saved["residual_deg"] - residual_deg) < 5e-4
    # Noise of 0.05-0.2 mm and 0.01-0.03 deg per pose: residuals of that order.
    assert 0.01 < residual_mm < 0.5 and residual_deg < 0.1
    err = difference(np.array(saved["camera_to_tool"]), X)
    assert np.linalg.norm(err[:3]) < 2.0 and math.degrees(np.linalg.norm(err[3:])) < 0.3
    status = h.handeye.status()
    assert status.pairs == () and status.done.calibration.n_pairs == len(VIEWS)  # a new set begins
    assert status == h.handeye.status()  # a display compares snapshots to redraw only on a change
    assert status.done.path == tmp_path / "handeye.json" and status.done.previous is not None
    h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[0]))))
    h.frame(seen(0, rng))
    assert parse_answer_line(h.link.sent[-1])["values"] == ["1"]


def re_three_decimals(values: list[str]) -> bool:
    return all(len(v.split(".")[1]) == 3 for v in values)


def test_a_handeye_holds_the_commands_after_it_until_its_answer(tmp_path) -> None:
    h = Harness(tmp_path)
    h.command("HANDEYE")
    h.command("PING")
    answers = h.answers()
    assert [(a["command"], a["result"]) for a in answers] == [("HANDEYE", "ERR"), ("PING", "OK")]
    assert answers[0]["reason"] == "0 pairs: at least 5 needed"


def test_pairs_turned_about_one_axis_are_refused_naming_what_to_add_and_kept(tmp_path) -> None:
    rng = np.random.default_rng(3)
    h = Harness(tmp_path)
    # Every view turned about the optical axis only: the tool turns about one axis.
    views = [([5.0, -3.0, 300.0], [0.0, 0.0, g]) for g in (-60, -30, 0, 30, 60)]
    for k, (position, angles) in enumerate(views):
        h.command("TOOL", *tool_args(tool_for(transform_from_pose(position, angles))))
        h.frame(Result(k, Pose(np.array(position) + rng.normal(0, 0.05, 3), np.array(angles, float))))
    h.command("HANDEYE")
    answers = h.answers()
    assert [a["result"] for a in answers] == ["OK"] * 5 + ["ERR"]
    reason = answers[-1]["reason"]
    assert reason.startswith("one turn axis: add turns about tool ") and len(reason) <= 40
    assert len(h.handeye.status().pairs) == 5 and not (tmp_path / "handeye.json").exists()


@pytest.mark.parametrize(
    ("args", "reason"),
    [
        ((), "give TOOL x y z qw qx qy qz"),
        (("1", "2", "3", "1", "0", "0"), "give TOOL x y z qw qx qy qz"),
        (("1", "2", "3", "1", "0", "0", "0", "9"), "give TOOL x y z qw qx qy qz"),
        (("1", "2", "abc", "1", "0", "0", "0"), "z is not a number"),
        (("1", "2", "3", "1e0", "0", "0", "0"), "qw is not a number"),
        (("1", "2", "3", "nan", "0", "0", "0"), "qw is not a number"),
        (("1", "2", "3", "1", "", "0", "0"), "qx is not a number"),
        (("1", "2", "200000", "1", "0", "0", "0"), "z beyond 100000 mm"),
        (("1", "2", "3", "0.98", "0", "0", "0"), "not a unit quaternion (norm 0.9800)"),
        (("1", "2", "3", "0", "0", "0", "0"), "not a unit quaternion (norm 0.0000)"),
    ],
)
def test_bad_tool_arguments_are_one_clear_error_and_nothing_waits(tmp_path, args, reason) -> None:
    h = Harness(tmp_path)
    h.command("TOOL", *args)
    h.command("PING")
    answers = h.answers()
    assert [(a["command"], a["result"]) for a in answers] == [("TOOL", "ERR"), ("PING", "OK")]
    assert answers[0]["reason"] == reason
    assert len(h.handeye.status().pairs) == 0


def test_quaternion_norm_within_0_001_is_accepted_and_normalised() -> None:
    tool = parse_tool(("1", "2", "3", "0.9995", "0", "0", "0"))
    np.testing.assert_allclose(tool[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(tool[:3, 3], [1, 2, 3])
    # A half turn about z, written as a controller would: (0, 0, 0, 1).
    tool = parse_tool(("-1.5", "+2", "0", "0", "0", "0", "1"))
    np.testing.assert_allclose(tool[:3, :3], np.diag([-1.0, -1.0, 1.0]), atol=1e-12)


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"ambiguous": True}, "ambiguous: tilt the code 10-30 deg"),
        ({"converged": False}, "no converged pose within 3 s"),
        (None, "no pose within 3 s"),
        ("no frame", "no frame within 3 s"),
    ],
)
def test_no_usable_frame_within_the_timeout_says_why(tmp_path, change, reason) -> None:
    rng = np.random.default_rng(5)
    h = Harness(tmp_path)
    h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[0]))))
    h.command("PING")
    for k in range(3):
        if change is None:
            h.frame(Result(k, None, status="NOQR"))
        elif isinstance(change, dict):
            h.frame(seen(0, rng, **change))
    h.clock.t += TOOL_TIMEOUT_S - 0.01
    h.handler.poll()
    assert h.link.sent == []  # still waiting; the PING behind it too
    h.clock.t += 0.02
    h.handler.poll()
    answers = h.answers()
    assert [(a["command"], a["result"]) for a in answers] == [("TOOL", "ERR"), ("PING", "OK")]
    assert answers[0]["reason"] == reason
    # A frame after the answer makes no pair.
    h.frame(seen(0, rng))
    assert len(h.handeye.status().pairs) == 0


def test_a_frame_captured_before_the_tool_command_makes_no_pair(tmp_path) -> None:
    rng = np.random.default_rng(6)
    h = Harness(tmp_path)
    early = seen(0, rng)
    early.t_capture = time.monotonic() - 0.5  # captured while the robot may still have moved
    h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[0]))))
    h.frame(early)
    assert h.link.sent == []
    h.frame(seen(0, rng))
    assert parse_answer_line(h.link.sent[0])["values"] == ["1"]


def test_simulated_frames_make_sim_pairs_saved_apart_and_never_mixed_with_live_ones(tmp_path) -> None:
    rng = np.random.default_rng(7)
    h = Harness(tmp_path)
    for k, view in enumerate(VIEWS[:5]):
        h.command("TOOL", *tool_args(tool_for(transform_from_pose(*view))))
        h.frame(seen(k, rng), simulated=True)
    h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[5]))))
    h.frame(seen(5, rng), simulated=False)  # a live camera's frame: not in a simulated set
    h.clock.t += TOOL_TIMEOUT_S + 0.1
    h.handler.poll()
    h.command("HANDEYE")
    answers = h.answers()
    got = [(a["command"], a["result"], *a["values"]) for a in answers]
    assert got[:5] == [("TOOL", "OK", str(k + 1), "SIM") for k in range(5)]
    assert got[5] == ("TOOL", "ERR", "source changed since the first pair")
    assert got[6][:2] == ("HANDEYE", "OK") and got[6][-1] == "SIM" and len(got[6]) == 5
    assert not (tmp_path / "handeye.json").exists()  # the file a live camera's run reads
    saved = json.loads((tmp_path / "handeye-simulated.json").read_text())
    assert saved["simulated"] is True and saved["n_pairs"] == 5


def test_handeye_without_a_set_up_or_with_an_argument_is_an_error(tmp_path) -> None:
    h = Harness(tmp_path, setup=None)
    h.command("HANDEYE")
    h.command("HANDEYE", "eye-in-hand")
    reasons = [a["reason"] for a in h.answers()]
    assert reasons == ["no set-up: set handeye_setup", "HANDEYE takes no argument"]


def test_a_file_that_cannot_be_written_is_an_error_and_the_pairs_stay(tmp_path) -> None:
    rng = np.random.default_rng(8)
    blocker = tmp_path / "file"
    blocker.write_text("")
    h = Harness(tmp_path)
    h.handeye.save_to = blocker / "handeye.json"  # a folder that cannot be made
    for k, view in enumerate(VIEWS[:6]):
        h.command("TOOL", *tool_args(tool_for(transform_from_pose(*view))))
        h.frame(seen(k, rng))
    h.command("HANDEYE")
    answer = h.answers()[-1]
    assert (answer["command"], answer["result"]) == ("HANDEYE", "ERR") and answer["reason"].startswith(
        "not saved"
    )
    assert len(h.handeye.status().pairs) == 6


def pose_result(position, angles, std=(0.05, 0.05, 0.2, 0.03, 0.03, 0.01)):
    """A real PoseResult (qrfield.solvers) at a pose, with a diagonal covariance."""
    from qrfield.geometry import rotation_matrix
    from qrfield.solvers import PoseResult

    cov = np.diag(np.square(std))
    return PoseResult(
        method="numerical",
        position_mm=np.array(position, float),
        angles_deg=np.array(angles, float),
        rotation=rotation_matrix(angles),
        vertices_mm=np.zeros((4, 3)),
        converged=True,
        iterations=3,
        residual_mm=0.0,
        reprojection_px=0.1,
        reason="",
        corners_px=np.zeros((4, 2)),
        position_std_mm=np.array(std[:3]),
        angles_std_deg=np.array(std[3:]),
        pose_cov=cov,
    )


def frame_result(index, position, angles):
    from qrfield.pipeline import FrameResult

    return FrameResult(
        index,
        index * 50,
        "OK",
        poses={"numerical": pose_result(position, angles)},
        t_capture=time.monotonic(),
    )


def in_tool(x, position, angles):
    """By hand: the code's pose in the tool frame through x."""
    from qrfield.geometry import angles_from_rotation, rotation_matrix

    return x[:3, :3] @ np.array(position) + x[:3, 3], angles_from_rotation(
        x[:3, :3] @ rotation_matrix(angles)
    )


def test_the_link_streams_in_the_tool_frame_and_a_handeye_switches_it_to_the_new_calibration(tmp_path):
    import os
    import threading

    from serial_truth import frames_and_answers

    from qrfield.handeye import HandEyeCalibration, PoseFrame
    from qrfield.serial.controller import GripperLink
    from qrfield.serial.link import CONNECTED, SerialLinkSettings

    old = transform_from_pose([70.0, -15.0, 40.0], [2.0, -3.0, 91.0])  # 10 mm and 1 deg off X
    cov = np.diag([0.3, 0.3, 0.3, 0.05, 0.05, 0.05]) ** 2
    calibration = HandEyeCalibration("eye-in-hand", old, 0.1, 0.02, 15, "test", cov)
    master, slave = os.openpty()
    data = bytearray()
    stop = threading.Event()

    def read() -> None:
        while not stop.is_set():
            try:
                data.extend(os.read(master, 4096))
            except OSError:
                return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    link = GripperLink(
        SerialLinkSettings(port=os.ttyname(slave), max_rate_hz=0), pose_frame=PoseFrame("tool", calibration)
    )
    handeye = link.add_handeye(HandEyeCommands("eye-in-hand", tmp_path / "handeye.json"))
    rng = np.random.default_rng(11)
    probe = ([8.0, -4.0, 305.0], [10.0, -12.0, 25.0])

    def answers() -> list[dict]:
        return frames_and_answers(bytes(data))[1]

    def wait_for(n: int) -> None:
        deadline = time.monotonic() + 20
        while len(answers()) < n:
            assert time.monotonic() < deadline, answers()
            time.sleep(0.01)

    try:
        link.start()
        assert link.wait_for_state(CONNECTED, 10)
        os.write(master, command_line("HELLO"))
        wait_for(1)
        link.on_result(frame_result(0, *probe), simulated=False)
        time.sleep(0.2)
        for k, view in enumerate(VIEWS):
            os.write(master, command_line("TOOL", *tool_args(tool_for(transform_from_pose(*view)))))
            deadline = time.monotonic() + 20
            while handeye.status().busy != "TOOL":  # the command has arrived: frames after it count
                assert time.monotonic() < deadline
                time.sleep(0.005)
            position, angles = VIEWS[k]
            noise = rng.normal(0, [0.05, 0.05, 0.2, 0.03, 0.03, 0.01])
            link.on_result(frame_result(k + 1, np.add(position, noise[:3]), np.add(angles, noise[3:])), False)
            wait_for(k + 2)
        os.write(master, command_line("HANDEYE"))
        wait_for(len(VIEWS) + 2)
        link.on_result(frame_result(99, *probe), simulated=False)
        handled = link.commands.handled
        os.write(master, command_line("MEAS", "1"))
        deadline = time.monotonic() + 20
        while link.commands.handled == handled:  # the MEAS is in: the next frame is its
            assert time.monotonic() < deadline
            time.sleep(0.005)
        link.on_result(frame_result(100, *probe), simulated=False)
        os.write(master, command_line("HELLO"))
        wait_for(len(VIEWS) + 4)
    finally:
        link.close()
        stop.set()
        os.close(slave)
        os.close(master)
        reader.join(5)
    frames, got = frames_and_answers(bytes(data))
    assert got[0]["values"][-1] == "tool" and got[-1]["values"][-1] == "tool"  # HELLO before and after
    assert got[len(VIEWS) + 1]["command"] == "HANDEYE" and got[len(VIEWS) + 1]["result"] == "OK"
    # Before the HANDEYE: the probe through the old calibration, its sigmas with the calibration's.
    (first,) = [f for f in frames if f["status"] == "OK" and f["t_ms"] == 0]
    p_old, a_old = in_tool(old, *probe)
    np.testing.assert_allclose(first["pose"][:3], p_old, atol=0.051)
    np.testing.assert_allclose(first["pose"][3:], a_old, atol=0.0051)
    assert all(s >= 0.3 for s in first["sigma"][:3]) and first["status"] == "OK"
    # After it: the same probe through the new calibration (within the solve's error of X), in
    # $QRF and $QRM alike.
    p_new, a_new = in_tool(X, *probe)
    assert np.linalg.norm(p_new - p_old) > 5.0  # the two calibrations tell apart
    (last,) = [f for f in frames if f["status"] == "OK" and f["t_ms"] in (4950, 5000)][-1:]
    meas = got[len(VIEWS) + 2]
    for pose in (last["pose"], meas["pose"]):
        assert np.linalg.norm(np.array(pose[:3]) - p_new) < 1.0
        assert np.abs(np.array(pose[3:]) - a_new).max() < 0.2
    assert link.pose_frame.calibration.path == tmp_path / "handeye.json"


@pytest.mark.slow
def test_a_frame_seen_while_the_next_tool_is_armed_never_answers_it(tmp_path) -> None:
    # The frame loop's thread hands a frame over at the moment the next TOOL is being armed (here:
    # from inside the arming, on another thread): it must not answer that TOOL with the previous
    # pair's count (it once did: the first pair's "done" was still set) nor make its pair.
    import threading

    from qrfield.handeye.pairs import PairCollector

    rng = np.random.default_rng(9)
    h = Harness(tmp_path)
    helpers: list[threading.Thread] = []

    class ArmedMidFrame(PairCollector):
        def expect(self, *args, **kwargs) -> None:
            helper = threading.Thread(target=h.frame, args=(seen(0, rng),))
            helpers.append(helper)
            helper.start()
            helper.join(0.3)  # the frame thread runs now, or waits until the arming is done
            super().expect(*args, **kwargs)

    h.handeye.collector = ArmedMidFrame()
    for n in (1, 2, 3):
        h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[n]))))
        for helper in helpers:
            helper.join(5)
        assert len(h.link.sent) == n - 1  # the frame captured before the arming made no pair
        h.frame(seen(n, rng))
        assert [parse_answer_line(line)["values"][0] for line in h.link.sent] == [
            str(k) for k in range(1, n + 1)
        ]
    assert len(h.handeye.status().pairs) == 3


def test_clearing_the_pairs_answers_a_waiting_tool_and_starts_a_new_set(tmp_path) -> None:
    rng = np.random.default_rng(10)
    h = Harness(tmp_path)
    for k in (0, 1):
        h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[k]))))
        h.frame(seen(k, rng))
    h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[2]))))
    h.handeye.clear()  # the operator's Clear pairs while the TOOL waits
    h.frame(seen(2, rng))
    h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[3]))))
    h.frame(seen(3, rng))
    got = [(a["result"], *a["values"]) for a in h.answers()]
    assert got == [("OK", "1"), ("OK", "2"), ("ERR", "pairs cleared"), ("OK", "1")]


def test_status_snapshots_compare_across_two_calibrations(tmp_path) -> None:
    # The Serial tab redraws when the snapshot changes: two calibrations' snapshots must compare
    # (their matrices once made the comparison raise).
    rng = np.random.default_rng(12)
    h = Harness(tmp_path)
    shown = []
    for _ in range(2):
        for k, view in enumerate(VIEWS):
            h.command("TOOL", *tool_args(tool_for(transform_from_pose(*view))))
            h.frame(seen(k, rng))
        h.command("HANDEYE")
        h.handeye.close(30.0)
        shown.append(h.handeye.status())
    assert (
        shown[0].done != shown[1].done
        and shown[0].done.calibration.n_pairs == shown[1].done.calibration.n_pairs
    )
    same_but_done = dataclasses.replace(shown[1], last=shown[0].last)
    assert same_but_done != shown[0]
    assert (tmp_path / "handeye.json.previous").is_file()  # the first, kept when the second was saved


def test_closing_answers_a_waiting_tool_and_a_meas_queued_behind_it(tmp_path) -> None:
    """audit-serial: the run ends (a folder or video ends) while a TOOL waits for its frame and a
    MEAS and a PING wait behind it: each command still gets its one answer, in order, when the
    link closes (CommandHandler.finish, which GripperLink.close calls): the TOOL ERR (no frame),
    the MEAS NOSRC with empty fields, the PING OK. Before, none was answered."""
    h = Harness(tmp_path)
    h.command("TOOL", *tool_args(tool_for(transform_from_pose(*VIEWS[0]))))
    h.command("MEAS", "3")
    h.command("PING")
    assert h.link.sent == []
    h.handler.finish()
    got = [parse_answer_line(line) for line in h.link.sent]
    assert [(a["type"], a["command"] if a["type"] == "QRA" else "MEAS") for a in got] == [
        ("QRA", "TOOL"),
        ("QRM", "MEAS"),
        ("QRA", "PING"),
    ]
    assert got[0]["result"] == "ERR" and got[0]["reason"] == "no frame: the run ended"
    assert got[1]["status"] == "NOSRC" and got[1]["pose"] is None and got[2]["result"] == "OK"
