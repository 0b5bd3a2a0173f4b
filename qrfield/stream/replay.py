"""A drawn sequence (qrfield.testing.sequences) solved frame by frame with the stream stage off, and
those solver results replayed through a fresh stream stage in any mode: what the stream benchmark
and the sequence tests both do, so that every mode sees the same frames."""

from __future__ import annotations

from typing import Any

from qrfield.testing.sequences import FPS, Sequence


def solve_sequence(sequence: Sequence) -> list[Any]:
    """Each frame of ``sequence`` through the default pipeline (every method in
    :data:`qrfield.methods.METHODS`, the tracker on) with the stream stage off, as a frame loop
    would solve it frame by frame: a list of :class:`qrfield.pipeline.FrameResult`, one per frame,
    each carrying its drawn truth (``truth``) and times ``1000 + i / FPS`` s; a sequence with
    capture times and frame numbers of its own (``times_s``, ``indices``:
    :class:`qrfield.testing.varied_sequences.VariedSequence`) is given those instead."""
    from qrfield.methods import METHODS
    from qrfield.pipeline import Pipeline
    from qrfield.sources.base import Frame
    from qrfield.stream import StreamSettings

    pipeline = Pipeline(sequence.camera, sequence.side_mm, METHODS, stream=StreamSettings(continuity=False))
    count = len(sequence.frames)
    times = getattr(sequence, "times_s", ()) or [i / FPS for i in range(count)]
    indices = getattr(sequence, "indices", ()) or range(count)
    out = []
    for (image, pose), t, i in zip(sequence.frames, times, indices, strict=True):
        out.append(pipeline.process(Frame(image, 1000.0 + t, i, truth=pose)))
    return out


def replay(results: list[Any], settings: Any, side_mm: float) -> list[Any]:
    """Frames solved by :func:`solve_sequence` through a fresh :class:`qrfield.stream.StreamStage`
    with ``settings`` (a :class:`qrfield.stream.StreamSettings`), ``side_mm`` the code's side in mm:
    copies whose ``poses`` are the stage's answers from each frame's own solve (``frame_poses``)."""
    import copy

    from qrfield.stream import StreamStage

    stage = StreamStage(settings)
    out = []
    for result in results:
        again = copy.copy(result)
        again.poses = dict(result.frame_poses or result.poses)
        again.stream = {}
        cov = None if result.detection is None else result.detection.pose_cov
        if again.poses:
            stage.apply(again, side_mm, cov)
        out.append(again)
    return out
