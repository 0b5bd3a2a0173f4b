"""The one row recorder (qrfield.sessions.recorder.RowRecorder) that the app, ``session log`` and the
guide share: fed frame by frame as the frame loop feeds its sinks (hand-made results with known
values: the means and verdicts are worked out here by hand), and on a real frame loop on the virtual
bench, where it must see every processed frame and measure the bench's own pose."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

from qrfield.camera import resolve_camera
from qrfield.engine import FrameLoop
from qrfield.runconfig import RunConfig
from qrfield.seams import LoopEventsBase
from qrfield.sessions import AcceptanceCriteria, GroundTruth
from qrfield.sessions.guide import Guide
from qrfield.sessions.plan import generate_plan
from qrfield.sessions.recorder import NO_BENCH_TRUTH, RowRecorder
from qrfield.sources import VirtualBenchSettings

pytestmark = pytest.mark.timeout(60)
CRITERIA = AcceptanceCriteria()  # 2 degrees, 5 mm
TRUTH = GroundTruth(10.0, -5.0, 300.0, 15.0, -20.0, 10.0, "alpha+beta-gamma+")


def result(values, t_capture: float = float("nan"), truth=None, method: str = "numerical", converged=True):
    """A FrameResult as a sink gets it: the poses by method, the capture time, the bench's truth."""
    v = np.asarray(values, dtype=float)
    pose = SimpleNamespace(converged=converged, position_mm=v[:3], angles_deg=v[3:])
    return SimpleNamespace(t_ms=0, t_capture=t_capture, poses={method: pose}, truth=truth)


def true_pose(values) -> SimpleNamespace:
    v = np.asarray(values, dtype=float)
    return SimpleNamespace(position_mm=v[:3], angles_deg=v[3:])


def test_the_next_frames_captured_after_the_request_make_the_row() -> None:
    recorder = RowRecorder()
    assert recorder.arm(TRUTH, 3, method="numerical", criteria=CRITERIA, note="first")
    assert not recorder.arm(TRUTH, 3)  # one row at a time
    armed = time.monotonic()
    recorder.on_result(result([0, 0, 0, 0, 0, 0], t_capture=armed - 1.0))  # captured before: not counted
    assert recorder.progress == (0, 3)
    for dz in (1.0, 2.0, 6.0):
        recorder.on_result(result([10, -5, 300 + dz, 15, -20, 10], t_capture=time.monotonic()))
    assert not recorder.collecting and recorder.progress is None
    (row,) = recorder.take()
    m = row.measurement
    assert row.problem == "" and row.frames_in == 3 and m.note == "first" and m.truth == TRUTH
    assert m.average.n_frames == 3 and m.average.n_converged == 3
    assert m.average.position_mm[2] == pytest.approx(303.0)  # (301 + 302 + 306) / 3
    assert m.judgement.err_pos_mm == pytest.approx(3.0) and m.judgement.passed  # 3 mm < 5 mm
    assert recorder.take() == [] and recorder.frames_seen == 4


def test_a_followed_truth_is_the_mean_true_pose_of_the_converged_frames() -> None:
    recorder = RowRecorder()
    recorder.arm(TRUTH, 3, follow_bench=True)
    # The bench swings through 180 degrees of gamma: the circular mean of 179 and -179 is 180, not 0;
    # the frame that did not converge is left out of the truth as out of the mean.
    recorder.on_result(result([0, 0, 300, 0, 0, 179], truth=true_pose([2, 0, 300, 0, 0, 179])))
    recorder.on_result(result([0, 0, 300, 0, 0, -179], truth=true_pose([4, 0, 300, 0, 0, -179])))
    recorder.on_result(result([0, 0, 300, 0, 0, 0], truth=true_pose([60, 0, 300, 0, 0, 90]), converged=False))
    (row,) = recorder.take()
    truth = row.measurement.truth
    assert truth.x == pytest.approx(3.0) and abs(truth.gamma) == pytest.approx(180.0)
    assert truth.combo == TRUTH.combo


def test_following_without_true_poses_falls_back_to_the_typed_truth_or_is_refused() -> None:
    recorder = RowRecorder()
    recorder.arm(TRUTH, 1, follow_bench=True)
    recorder.on_result(result([10, -5, 300, 15, -20, 10]))
    assert recorder.take()[0].measurement.truth == TRUTH
    recorder.arm(None, 1, follow_bench=True, combo="beta")
    recorder.on_result(result([10, -5, 300, 15, -20, 10]))
    (row,) = recorder.take()
    assert row.measurement is None and row.problem == NO_BENCH_TRUTH and not row.stopped
    with pytest.raises(ValueError, match="ground truth"):
        recorder.arm(None, 1)


def test_a_row_whose_frames_stop_is_given_up_by_its_timeout_or_by_the_source_going_down() -> None:
    recorder = RowRecorder()
    recorder.arm(TRUTH, 5, frame_timeout_s=3.0)
    recorder.on_result(result([10, -5, 300, 15, -20, 10]))
    recorder.on_source_down("no frame for 1.0 s")  # the row's own timeout decides, not the loop's 1 s
    assert recorder.collecting and recorder.take() == []
    assert recorder.expire(time.monotonic() + 2.0) is None
    ended = recorder.expire(time.monotonic() + 3.5)
    assert ended is not None and ended.problem.startswith("no frame for 3.") and ended.frames_in == 1
    assert ended.stopped and not recorder.collecting and recorder.take() == []
    # Without a timeout, the loop's "source down" ends it (and the owner finds it in take()).
    recorder.arm(TRUTH, 5)
    recorder.on_result(result([10, -5, 300, 15, -20, 10]))
    recorder.on_source_down("end of stream: no more frames")
    (row,) = recorder.take()
    assert (
        row.measurement is None and row.stopped and row.problem == "no frames (end of stream: no more frames)"
    )
    # Cancel and give up end the row at once; nothing is queued.
    recorder.arm(TRUTH, 5)
    assert recorder.cancel() and not recorder.cancel()
    recorder.arm(TRUTH, 5)
    assert recorder.give_up("the source failed").problem == "the source failed"
    assert recorder.take() == [] and recorder.give_up("again") is None


def test_the_guide_measures_its_rows_with_the_same_recorder() -> None:
    """The same frames give the guide's row and a recorder's row the same measurement."""
    target = generate_plan("alpha", [15], z_mm=300, x_mm=10, y_mm=-5)[0]
    guide = Guide("numerical", CRITERIA, frames_per_row=4)
    recorder = RowRecorder()
    guide.set_target(target)
    assert guide.arm()
    recorder.arm(target.truth, 4, method="numerical", criteria=CRITERIA, note=target.note)
    rng = np.random.default_rng(7)
    for k in range(4):
        values = np.array([*target.truth.position_mm, *target.truth.angles_deg]) + rng.normal(0, 0.5, 6)
        frame = result(values, t_capture=time.monotonic())
        frame.t_ms = 50 * k
        guide.on_result(frame)
        recorder.on_result(frame)
    (guided,) = guide.take()
    (row,) = recorder.take()
    a, b = guided.measurement, row.measurement
    assert a.truth == b.truth and a.judgement.passed == b.judgement.passed
    np.testing.assert_array_equal(a.average.position_mm, b.average.position_mm)
    np.testing.assert_array_equal(a.average.angles_deg, b.average.angles_deg)


class CountingEvents(LoopEventsBase):
    def __init__(self) -> None:
        self.processed_count = 0

    def processed(self, frame, result, behind) -> None:
        self.processed_count += 1


def test_on_a_frame_loop_it_sees_every_processed_frame_and_measures_the_bench() -> None:
    bench = VirtualBenchSettings()  # x 10, y -5, z 300 mm; alpha 15, beta -20, gamma 10 degrees
    config = RunConfig("virtual", resolve_camera("picam-v2@640x480"), 50.0, ("numerical",), virtual=bench)
    recorder = RowRecorder()
    events = CountingEvents()
    loop = FrameLoop(config, events=events, sinks=(recorder,), max_frames=40)
    thread = threading.Thread(target=loop.run, name="test frame loop", daemon=True)
    thread.start()
    try:
        measurement = recorder.measure(
            None, 5, follow_bench=True, combo="alpha", until=lambda: not thread.is_alive()
        )
    finally:
        loop.stop()
        thread.join(10)
    assert not thread.is_alive()
    assert recorder.frames_seen == loop.frames_processed == events.processed_count  # every frame
    assert measurement is not None and measurement.average.n_frames == 5
    truth = measurement.truth  # the bench's own pose, as it was set
    assert (truth.x, truth.y, truth.z) == pytest.approx((10.0, -5.0, 300.0))
    assert (truth.alpha, truth.beta, truth.gamma) == pytest.approx((15.0, -20.0, 10.0))
    assert measurement.judgement.passed, measurement.judgement.reason


@pytest.mark.slow
def test_a_terminal_row_waits_through_a_pause_in_the_frames_up_to_its_frame_timeout() -> None:
    """Issue 23 (audit): ``session log`` gave a row up at the loop's first "source down" (1 s
    without a frame: a loaded machine, an 8 MP virtual frame, a slow camera) and said "the source
    stopped before the frames were in". With the app's frame timeout it waits, as the app does,
    and a row given up says why."""

    def feed(recorder: RowRecorder, pause_s: float) -> None:
        while not recorder.collecting:
            time.sleep(0.01)
        recorder.on_result(result([10, -5, 300, 15, -20, 10]))
        recorder.on_source_down("no frame for 1.0 s")  # what the frame loop says after 1 s
        time.sleep(pause_s)
        recorder.on_result(result([10, -5, 302, 15, -20, 10]))

    recorder = RowRecorder()
    feeder = threading.Thread(target=feed, args=(recorder, 0.3))
    feeder.start()
    measurement = recorder.measure(TRUTH, 2, frame_timeout_s=3.0)
    feeder.join()
    assert measurement is not None and recorder.last_problem == ""
    assert measurement.average.position_mm[2] == pytest.approx(301.0)  # (300 + 302) / 2
    # No frame for longer than the timeout: given up, and the reason is kept for the message.
    recorder = RowRecorder()
    feeder = threading.Thread(target=feed, args=(recorder, 1.5))
    feeder.start()
    assert recorder.measure(TRUTH, 2, frame_timeout_s=0.5) is None
    feeder.join()
    assert recorder.last_problem.startswith("no frame for 0.")
    # The loop ending (the source failed for good) is said as such.
    assert RowRecorder().measure(TRUTH, 2, until=lambda: True) is None
