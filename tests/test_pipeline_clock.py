"""The stream's clock (FrameResult.t_ms): the capture clock for a live source, the recording's own
clock for a video file (Frame.t_media), so a file's poses do not depend on how fast it is decoded."""

from __future__ import annotations

import numpy as np
import pytest

from qrfield.methods import METHODS
from qrfield.pipeline import Pipeline
from qrfield.sources.base import Frame
from qrfield.stream import StreamSettings
from qrfield.testing.sequences import FPS, make_sequence


def _frames(times, media):
    sequence = make_sequence("frontal far 1.4 px", 5, 12)
    return sequence, [
        Frame(image, t, i, truth=pose, t_media=None if media is None else media[i])
        for i, ((image, pose), t) in enumerate(zip(sequence.frames, times, strict=True))
    ]


def _run(sequence, frames):
    pipeline = Pipeline(sequence.camera, sequence.side_mm, METHODS, stream=StreamSettings(filter_s=0.2))
    return [pipeline.process(frame) for frame in frames]


@pytest.mark.slow
def test_a_recording_decoded_fast_is_timed_and_filtered_on_its_own_clock() -> None:
    """12 frames recorded at 30 frames/s but decoded in 8 ms each (t_capture 8 ms apart): t_ms is
    the recording's (0, 33, 67, ...), and the filtered poses are those of the same frames captured
    live at 30 frames/s; on the decode clock the filter's steps are 4x too short."""
    real = [500.0 + i / FPS for i in range(12)]
    fast = [500.0 + 0.008 * i for i in range(12)]
    sequence, live = _frames(real, None)
    recorded = _frames(fast, [i / FPS for i in range(12)])[1]
    on_decode_clock = _frames(fast, None)[1]
    want = _run(sequence, live)
    got = _run(sequence, recorded)
    assert [r.t_ms for r in got] == [round(1000 * i / FPS) for i in range(12)]
    assert sum(r.stream["numerical"].filtered for r in got) >= 6
    differs = False
    for a, b, c in zip(want, got, _run(sequence, on_decode_clock), strict=True):
        want_pose, got_pose = a.poses["numerical"], b.poses["numerical"]
        np.testing.assert_allclose(got_pose.angles_deg, want_pose.angles_deg, atol=1e-9)
        np.testing.assert_allclose(got_pose.position_mm, want_pose.position_mm, atol=1e-9)
        differs |= not np.allclose(c.poses["numerical"].angles_deg, want_pose.angles_deg, atol=1e-3)
    assert differs  # the decode clock would have changed what the filter reports


def test_a_recording_that_starts_again_never_steps_the_clock_back() -> None:
    """A source reopened (the engine resets the pipeline with the clock running on) or a recording
    whose clock steps back starts a second after the stream's last frame."""
    sequence = make_sequence("still 450 mm", 1, 1)
    image = sequence.frames[0][0]
    pipeline = Pipeline(sequence.camera, sequence.side_mm, ("ippe",))
    first = [pipeline.process(Frame(image, 10.0 + 0.001 * i, i, t_media=0.5 * i)).t_ms for i in range(3)]
    assert first == [0, 500, 1000]
    back = pipeline.process(Frame(image, 10.01, 3, t_media=0.0)).t_ms
    pipeline.reset(pipeline.t0)
    reopened = pipeline.process(Frame(image, 10.02, 4, t_media=0.0)).t_ms
    assert back == 2000 and reopened == 3000
    live = pipeline.process(Frame(image, 14.5, 5)).t_ms
    assert live == 4500  # a live frame: the capture clock
