"""``qrfield run --serial`` into a pty, as a gripper controller sees it (docs/conventions.md).

The controller's end of the pty is read here and every line is checked with tests/serial_truth.py
(written from the conventions, sharing no code with the link): the virtual bench sends SIM, never
OK; ``--source auto`` without a camera falls back to nothing; a missing camera sends NOSRC at least
once a second; PING, HELLO, RATE, STREAM and MEAS,5 are answered; the last line before exit (on
SIGTERM, or when a folder ends) is NOSRC; a second run on the same port is refused naming the
first; unknown settings stop the run at start; a port that never opens is exit code 1; and a stdout
nobody reads holds up neither the serial line nor SIGTERM. Waits are bounded polls with margins of
several times what the machine needs; timings come from the lines' own t_ms.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from serial_truth import command_line, frames_and_answers

from qrfield import __version__
from qrfield.camera import DEFAULT_CAMERA, resolve_camera
from qrfield.geometry import angle_difference

pytestmark = pytest.mark.timeout(90)
REPO = Path(__file__).resolve().parent.parent
# The virtual bench's default pose (qrfield.sources.VirtualBenchSettings): mm and degrees.
BENCH = np.array([10.0, -5.0, 300.0, 15.0, -20.0, 10.0])


def env() -> dict[str, str]:
    out = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    out["PYTHONPATH"] = str(REPO)
    return out


class Controller:
    """The controller's end of a pty: a thread collects what the link writes; ``send`` writes."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        self.tty = os.ttyname(self.slave)
        self.data = bytearray()
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        while True:
            try:
                chunk = os.read(self.master, 4096)
            except OSError:
                return
            if not chunk:
                return
            with self.lock:
                self.data += chunk

    def send(self, *fields: str) -> None:
        os.write(self.master, command_line(*fields))

    def lines(self) -> tuple[list[dict], list[dict]]:
        with self.lock:
            data = bytes(self.data)
        return frames_and_answers(data)

    def wait(self, predicate, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not predicate(*self.lines()):
            assert time.monotonic() < deadline, f"timed out waiting for {what}: {self.lines()}"
            time.sleep(0.02)

    def close(self) -> None:
        for fd in (self.slave, self.master):
            with contextlib.suppress(OSError):
                os.close(fd)


@pytest.fixture
def controller():
    peer = Controller()
    yield peer
    peer.close()


def start_run(*args: str, stdout=subprocess.DEVNULL) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "qrfield", "run", *args]
    return subprocess.Popen(cmd, stdout=stdout, stderr=subprocess.PIPE, text=True, env=env(), cwd=REPO)


def finish(proc: subprocess.Popen, stop: bool = True) -> str:
    """stderr, once ``proc`` has ended (``stop``: ask it to, with SIGTERM)."""
    if stop and proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    return err


def meets_criteria(values: list[float], truth: np.ndarray) -> bool:
    v = np.asarray(values)
    return bool(
        np.linalg.norm(v[:3] - truth[:3]) < 5.0 and np.all(np.abs(angle_difference(v[3:], truth[3:])) <= 2.0)
    )


def test_the_bench_sends_sim_and_ping_stream_meas_are_answered(controller) -> None:
    proc = start_run(
        "--source", "virtual", "--virtual-fps", "20", "--method", "numerical", "--serial", controller.tty
    )
    try:
        controller.wait(lambda f, a: sum(x["status"] == "SIM" for x in f) >= 5, 30, "SIM frames")
        controller.send("PING")
        controller.send("HELLO")
        controller.send("RATE", "10")
        controller.wait(lambda f, a: len(a) >= 3, 10, "the PING, HELLO and RATE answers")
        controller.send("STREAM", "OFF")
        controller.wait(lambda f, a: len(a) >= 4, 10, "the STREAM,OFF answer")
        time.sleep(0.3)  # frames already on the wire when the command came
        quiet = len(controller.lines()[0])
        time.sleep(1.0)  # 20 poses a second would have been sent meanwhile
        assert len(controller.lines()[0]) == quiet, "$QRF lines kept coming after STREAM,OFF"
        controller.send("STREAM", "ON")
        controller.wait(lambda f, a: len(f) > quiet and len(a) >= 5, 10, "frames again after STREAM,ON")
        sent_at = time.monotonic()
        controller.send("MEAS", "5")
        controller.wait(lambda f, a: any(x["type"] == "QRM" for x in a), 10, "the $QRM answer")
        waited = time.monotonic() - sent_at
    finally:
        err = finish(proc)
    frames, answers = controller.lines()
    assert {f["status"] for f in frames[:-1]} <= {"SIM", "STALE"}, "the virtual bench must never send OK"
    assert frames[-1]["status"] == "NOSRC", "the last line before exit on SIGTERM"
    assert all(meets_criteria(f["pose"], BENCH) for f in frames if f["status"] == "SIM")
    assert all(f["age_ms"] is not None and f["age_ms"] < 5000 for f in frames if f["status"] == "SIM")
    got = [(a["command"], a["result"], *a["values"]) for a in answers[:5]]
    assert got[0] == ("PING", "OK") and got[2] == ("RATE", "OK", "10")
    camera = resolve_camera(DEFAULT_CAMERA).name  # the model the run measured with
    assert got[1] == ("HELLO", "QRF2", __version__, "50.0", camera, "camera")
    assert got[3:] == [("STREAM", "OK"), ("STREAM", "OK")]
    meas = answers[5]
    assert meas["status"] == "SIM" and meas["n_used"] == 5 and meets_criteria(meas["pose"], BENCH)
    assert all(s < 1.0 for s in meas["std"])  # a still bench: tenths of a mm, hundredths of a degree
    assert waited < 2.0 + 5 / 5, f"MEAS,5 took {waited:.2f} s"  # the conventions' own deadline
    assert "poses go out as SIM" in err and "Traceback" not in err


def test_auto_without_a_camera_never_falls_back_to_the_bench_under_serial(controller) -> None:
    if any(Path(f"/dev/video{i}").exists() for i in range(2)):
        pytest.skip("this machine has a camera: auto would use it")
    proc = start_run("--source", "auto", "--serial", controller.tty)
    err = finish(proc, stop=False)
    assert proc.returncode == 1, err
    assert "does not fall back to the virtual bench" in err and "--allow-virtual" in err
    frames, _ = controller.lines()
    assert not [f for f in frames if f["status"] in ("OK", "SIM")]
    # Allowed explicitly, the bench's poses flow, as SIM.
    proc = start_run("--source", "auto", "--allow-virtual", "--frames", "5", "--serial", controller.tty)
    err = finish(proc, stop=False)
    assert proc.returncode == 0, err
    controller.wait(lambda f, a: any(x["status"] == "SIM" for x in f), 10, "SIM frames")
    assert "OK" not in {f["status"] for f in controller.lines()[0]}


def test_a_missing_camera_sends_nosrc_at_least_once_a_second(controller) -> None:
    proc = start_run("--source", "usb:9", "--retry-s", "1", "--serial", controller.tty)
    try:
        controller.wait(lambda f, a: sum(x["status"] == "NOSRC" for x in f) >= 7, 30, "NOSRC frames")
    finally:
        err = finish(proc)
    assert proc.returncode == 0, err  # stopped by SIGTERM: retrying is not a failure
    frames, _ = controller.lines()
    assert {f["status"] for f in frames} == {"NOSRC"} and all(f["pose"] is None for f in frames)
    stamps = [f["t_ms"] for f in frames]
    gaps = np.diff(stamps)
    assert np.all(gaps > 0) and gaps.max() <= 1000, stamps  # docs/conventions.md: at least once a second
    assert "cannot open source 'usb:9'" in err


def test_a_port_that_never_opens_is_exit_code_1(tmp_path: Path) -> None:
    proc = start_run("--source", "virtual", "--frames", "3", "--serial", str(tmp_path / "ttyGone"))
    err = finish(proc, stop=False)
    assert proc.returncode == 1, err
    assert "could not be opened during the whole run" in err and "Traceback" not in err


def test_a_blocked_stdout_holds_up_neither_the_serial_line_nor_sigterm(controller) -> None:
    read_end, write_end = os.pipe()  # stdout into a pipe that nobody reads: it fills up and blocks
    try:
        proc = start_run(
            "--source",
            "virtual",
            "--virtual-fps",
            "20",
            "--json-lines",
            "--serial",
            controller.tty,
            stdout=write_end,
        )
        os.close(write_end)
        controller.wait(lambda f, a: len(f) >= 5, 30, "the first frames")
        time.sleep(10.0)  # ~200 JSON lines of ~1 kB: far beyond the pipe's 64 kB
        frames, _ = controller.lines()
        t_sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
        exit_s = time.monotonic() - t_sent
    finally:
        os.close(read_end)
    # The poses kept coming, fresh (SIM with a new capture time each), to the end of the 10 s.
    fresh = [f for f in frames if f["status"] == "SIM"]
    last_t = fresh[-1]["t_ms"]
    recent = [f for f in fresh if f["t_ms"] > last_t - 5000]
    assert len(recent) >= 20 and len({f["t_ms"] for f in recent}) == len(recent), [f["t_ms"] for f in fresh]
    assert last_t >= 8000, "the serial line stopped getting fresh poses"
    assert "lines not written" in err  # stdout really was blocked
    assert proc.returncode == 0 and exit_s < 2.0, (exit_s, err)


def test_a_folder_that_ends_says_nosrc_as_its_last_line(controller, tmp_path: Path) -> None:
    import cv2

    folder = tmp_path / "frames"
    folder.mkdir()
    for k in range(3):
        cv2.imwrite(str(folder / f"{k}.png"), np.full((120, 160), 200, np.uint8))  # no code: NOQR
    proc = start_run("--source", str(folder), "--serial", controller.tty)
    err = finish(proc, stop=False)
    assert proc.returncode == 0, err
    controller.wait(lambda f, a: f and f[-1]["status"] == "NOSRC", 10, "NOSRC at the end")
    frames, _ = controller.lines()
    # Three NOQR frames (a newer one may replace one not yet sent), then NOSRC, repeated while the
    # run lasts (every 0.5 s: a slow machine's run sends several), and NOSRC last. On a loaded
    # machine a NOSRC may also come between frames (no frame for a second is "no frames": the
    # protocol's rule for any source), so only what follows the last frame is fixed.
    statuses = [f["status"] for f in frames]
    assert set(statuses) <= {"NOQR", "STALE", "NOSRC"} and statuses[0] == "NOQR"
    last_frame = max(i for i, s in enumerate(statuses) if s == "NOQR")
    assert statuses[last_frame + 1 :] and set(statuses[last_frame + 1 :]) <= {"NOSRC", "STALE"}
    assert statuses[-1] == "NOSRC"
    assert frames[-1]["age_ms"] is not None


def test_a_second_run_on_the_same_port_is_refused_naming_the_first(controller) -> None:
    first = start_run("--source", "virtual", "--virtual-fps", "10", "--serial", controller.tty)
    try:
        controller.wait(lambda f, a: len(f) >= 3, 30, "the first run's lines")
        second = start_run("--source", "virtual", "--serial", controller.tty)
        err = finish(second, stop=False)
        assert second.returncode == 2, err
        (line,) = [x for x in err.splitlines() if "error" in x]
        assert f"serial port {controller.tty} is in use by pid {first.pid}" in line and "qrfield" in line
        seqs = [f["seq"] for f in controller.lines()[0]]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # one stream, one seq counter
        assert first.poll() is None
    finally:
        finish(first)


@pytest.mark.parametrize(
    ("args", "app_json", "message"),
    [
        (["--detect-backends", "x"], None, "unknown detector backend(s) x"),
        ([], {"detector": {"backends": "x"}}, "key detector.backends"),
        ([], {"run": {"method": "nope"}}, "key run.method"),
        (["--serial", "socket://localhost:9"], None, "only device paths and loop://"),
    ],
)
def test_unknown_settings_stop_the_run_at_start_with_exit_2(tmp_path: Path, args, app_json, message) -> None:
    import json

    config = tmp_path / "config"
    config.mkdir()
    if app_json is not None:
        (config / "app.json").write_text(json.dumps(app_json))
    proc = start_run("--config-dir", str(config), "--source", "virtual", "--serial", "loop://", *args)
    err = finish(proc, stop=False)
    assert proc.returncode == 2, err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    if app_json is not None:
        assert str(config / "app.json") in err
