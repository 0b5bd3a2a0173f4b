"""``qrfield run`` keeps only the newest frame of a live camera (it never falls behind a buffering
camera) and still reads every frame of a file or folder."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from qrfield import cli
from qrfield.sources import Frame, FrameSource

CAMERA_FPS = 100.0  # the fake camera's frame rate
PROCESS_S = 0.04  # the injected processing time per frame: 4 camera frames


class BufferingCamera(FrameSource):
    """A live camera that captures on a fixed clock and buffers: frame i is captured at
    ``t_start + i / fps`` whether or not it is read, and read() hands out the oldest unread frame
    (waiting for it if it is not captured yet), as a USB or Pi camera driver's queue does."""

    name = "fakecam"

    def __init__(self, live: bool = True) -> None:
        super().__init__()
        self.live = live
        self.t_start = 0.0

    def _open_impl(self) -> None:
        self.t_start = time.monotonic()

    def _read_impl(self, index: int) -> Frame:
        t_capture = self.t_start + index / CAMERA_FPS
        delay = t_capture - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        return Frame(np.full((120, 160), 200, np.uint8), t_capture, index)

    def _close_impl(self) -> None:
        pass


@pytest.fixture
def slow_pipeline(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every frame takes at least PROCESS_S to process."""
    from qrfield.pipeline import Pipeline

    original = Pipeline.process

    def slow(self, frame):
        time.sleep(PROCESS_S)
        return original(self, frame)

    monkeypatch.setattr(Pipeline, "process", slow)


def run_on(monkeypatch, capsys, source: FrameSource, frames: int) -> tuple[list[dict], list[float], str]:
    """Run ``qrfield run --json-lines`` on ``source``; (JSON lines, ms of lag of each emitted line
    behind its capture, stderr)."""
    import qrfield.commands.run as run_cmd
    import qrfield.sources as sources

    def fake_open(spec, **kwargs):
        source.open()
        return source

    emitted_at: list[float] = []
    original_emit = run_cmd._json_line

    def emit(result, simulated: bool) -> str:
        emitted_at.append(time.monotonic())
        return original_emit(result, simulated)

    monkeypatch.setattr(sources, "open_source", fake_open)
    monkeypatch.setattr(run_cmd, "_json_line", emit)
    code = cli.main(["run", "--headless", "--source", "fake", "--frames", str(frames), "--json-lines"])
    out = capsys.readouterr()
    assert code == 0, out.err
    lines = [json.loads(line) for line in out.out.splitlines()]
    # t_ms counts from the first frame processed (frame 0, captured at t_start).
    lags = [1000.0 * (t - source.t_start) - line["t_ms"] for t, line in zip(emitted_at, lines, strict=True)]
    return lines, lags, out.err


@pytest.mark.slow
@pytest.mark.usefixtures("slow_pipeline")
def test_a_live_camera_is_read_latest_only_so_the_lag_stays_bounded(monkeypatch, capsys) -> None:
    frames = 15
    # Control: the same camera read frame by frame falls behind by ~(PROCESS_S - 1/fps) per frame.
    lines_in_turn, lags_in_turn, _ = run_on(monkeypatch, capsys, BufferingCamera(live=False), frames)
    assert [line["frame"] for line in lines_in_turn] == list(range(frames))
    assert lags_in_turn[-1] > 0.6 * (frames - 1) * (PROCESS_S - 1 / CAMERA_FPS) * 1000

    lines, lags, err = run_on(monkeypatch, capsys, BufferingCamera(live=True), frames)
    print("lag ms in turn", np.round(lags_in_turn), "latest only", np.round(lags))
    assert len(lines) == frames
    indexes = [line["frame"] for line in lines]
    assert indexes == sorted(set(indexes)) and indexes[-1] > frames  # newer frames were taken
    # The lag does not grow with the run: the last frames trail no more than the first ones do
    # (a frame's processing plus a few camera frames), far below the in-turn reader's lag.
    assert max(lags[-5:]) < 0.5 * lags_in_turn[-1]
    assert max(lags[-5:]) < max(lags[:5]) + 4 * PROCESS_S * 1000
    # Every frame up to the last one taken was either processed or counted as dropped.
    match = re.search(r"done after (\d+) frames; (\d+) newer camera frames .* dropped", err)
    assert match, err
    assert int(match[1]) == frames and int(match[2]) >= indexes[-1] + 1 - frames > 0


def write_folder(folder: Path, count: int) -> None:
    folder.mkdir()
    for i in range(count):
        cv2.imwrite(str(folder / f"img{i:02d}.png"), np.full((120, 160), 10 * i, np.uint8))


def write_video(path: Path, count: int) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (160, 120))
    assert writer.isOpened()
    for i in range(count):
        writer.write(np.full((120, 160, 3), 10 * i, np.uint8))
    writer.release()


@pytest.mark.usefixtures("slow_pipeline")
@pytest.mark.parametrize("kind", ["folder", "video"])
def test_files_and_folders_still_yield_every_frame(kind, tmp_path: Path, capsys) -> None:
    count = 6
    path = tmp_path / ("images" if kind == "folder" else "clip.avi")
    (write_folder if kind == "folder" else write_video)(path, count)
    code = cli.main(["run", "--headless", "--source", str(path), "--frames", str(count), "--json-lines"])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert [json.loads(line)["frame"] for line in out.out.splitlines()] == list(range(count))
    assert "dropped" not in out.err and f"done after {count} frames" in out.err
