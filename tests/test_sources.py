"""Camera sources: one contract test runs every source through the FrameSource interface, then
each source's own behaviour (truth, looping, skipped files, picamera2 via a fake module, auto)."""

from __future__ import annotations

import sys
import time
import types
from pathlib import Path
from typing import ClassVar

import cv2
import numpy as np
import pytest

from qrfield.geometry import Pose
from qrfield.sources import (
    PICAMERA2_MISSING,
    EndOfStream,
    Frame,
    FrameSource,
    ImageFolderSource,
    Picamera2Settings,
    Picamera2Source,
    SourceError,
    UsbCameraSource,
    VideoFileSource,
    VirtualBenchSettings,
    VirtualBenchSource,
    make_source,
    open_source,
)
from qrfield.sources import opencv as opencv_module

VIDEO_FRAMES = 6
SIZE = (64, 48)


def write_video(path: Path, frames: int = VIDEO_FRAMES) -> Path:
    """A small MJPG .avi whose frame i is uniformly grey at level 30 + 30 i."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, SIZE, False)
    assert writer.isOpened(), "this OpenCV build cannot write MJPG .avi"
    for i in range(frames):
        writer.write(np.full(SIZE[::-1], 30 + 30 * i, np.uint8))
    writer.release()
    return path


class FakePicamera2:
    """Stands in for picamera2.Picamera2: records what the source asks of the camera."""

    instances: ClassVar[list[FakePicamera2]] = []

    def __init__(self, camera_num: int = 0) -> None:
        self.camera_num = camera_num
        self.controls: list[dict] = []
        self.config: dict | None = None
        self.started = self.closed = False
        self.captured = 0
        FakePicamera2.instances.append(self)

    def create_video_configuration(self, main: dict) -> dict:
        return {"main": main}

    def configure(self, config: dict) -> None:
        self.config = config

    def set_controls(self, controls: dict) -> None:
        self.controls.append(dict(controls))

    def start(self) -> None:
        self.started = True

    def capture_array(self, stream: str = "main") -> np.ndarray:
        width, height = self.config["main"]["size"]
        self.captured += 1
        image = np.zeros((height, width, 4), np.uint8)  # XRGB8888-like: 4 channels
        image[..., 0] = self.captured % 256
        return image

    def capture_metadata(self) -> dict:
        return {"ExposureTime": 12345, "AnalogueGain": 2.5}

    def stop(self) -> None:
        self.started = False

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def fake_picamera2(monkeypatch: pytest.MonkeyPatch) -> type[FakePicamera2]:
    module = types.ModuleType("picamera2")
    module.Picamera2 = FakePicamera2  # type: ignore[attr-defined]
    FakePicamera2.instances = []
    monkeypatch.setitem(sys.modules, "picamera2", module)
    return FakePicamera2


@pytest.fixture
def no_picamera2(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "picamera2", None)  # makes `import picamera2` fail


@pytest.fixture
def video_file(tmp_path: Path) -> Path:
    return write_video(tmp_path / "clip.avi")


@pytest.fixture
def image_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "images"
    folder.mkdir()
    for name, level in (("b.png", 100), ("a.png", 50), ("c.png", 150)):
        cv2.imwrite(str(folder / name), np.full((40, 60), level, np.uint8))
    (folder / "notes.txt").write_text("not an image")
    return folder


def usb_via_video(monkeypatch: pytest.MonkeyPatch, video: Path) -> UsbCameraSource:
    """A USB source whose cv2.VideoCapture(index) is really reading the test video."""
    real = cv2.VideoCapture
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", lambda index, *a: real(str(video)))
    return UsbCameraSource(0)


def all_sources(kind: str, monkeypatch, tmp_path, camera) -> FrameSource:
    if kind == "virtual":
        return VirtualBenchSource(camera, 50.0, VirtualBenchSettings(fps=0.0))
    if kind == "usb":
        return usb_via_video(monkeypatch, write_video(tmp_path / "usb.avi"))
    if kind == "video":
        return VideoFileSource(write_video(tmp_path / "v.avi"))
    if kind == "folder":
        folder = tmp_path / "f"
        folder.mkdir()
        for i in range(3):
            cv2.imwrite(str(folder / f"{i}.png"), np.full((40, 60, 3), 40 * i, np.uint8))
        return ImageFolderSource(folder)
    if kind == "picamera2":
        module = types.ModuleType("picamera2")
        module.Picamera2 = FakePicamera2  # type: ignore[attr-defined]
        monkeypatch.setitem(sys.modules, "picamera2", module)
        return Picamera2Source(Picamera2Settings(width=96, height=64))
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["virtual", "usb", "video", "folder", "picamera2"])
def test_every_source_honours_the_contract(kind, monkeypatch, tmp_path, camera_vga) -> None:
    source = all_sources(kind, monkeypatch, tmp_path, camera_vga)
    assert isinstance(source.name, str) and source.name
    assert isinstance(source.description, str) and source.description
    with pytest.raises(SourceError, match="before open"):
        source.read()
    before = time.monotonic()
    with source:
        assert source.is_open
        frames = [source.read() for _ in range(3)]
    after = time.monotonic()
    assert not source.is_open
    assert [f.index for f in frames] == [0, 1, 2]
    for frame in frames:
        assert isinstance(frame, Frame)
        assert frame.image.dtype == np.uint8 and frame.image.ndim in (2, 3)
        assert frame.image.ndim == 2 or frame.image.shape[2] == 3
        assert before <= frame.t_capture <= after
    assert [f.t_capture for f in frames] == sorted(f.t_capture for f in frames)
    assert (frames[0].truth is not None) == (kind == "virtual")
    source.close()  # closing twice is harmless
    with pytest.raises(SourceError):
        source.read()
    source.open()  # and a closed source can be opened again, restarting its count
    assert source.read().index == 0
    source.close()


def test_virtual_bench_frames_carry_their_true_pose(camera_vga) -> None:
    settings = VirtualBenchSettings(fps=0.0, noise_sigma=0.0, blur_px=0.0)
    source = VirtualBenchSource(camera_vga, 50.0, settings)
    with source:
        first = source.read()
        assert np.allclose(first.truth.position_mm, [10.0, -5.0, 300.0])
        assert np.allclose(first.truth.angles_deg, [15.0, -20.0, 10.0])
        # The card is where the truth says: dark modules inside the projected square, grey outside.
        corners = first.truth.corners_px(camera_vga, 50.0)
        inside = np.zeros(first.image.shape, np.uint8)
        cv2.fillConvexPoly(inside, np.round(corners).astype(np.int32), 1)
        assert first.image[inside == 1].min() < 40 and first.image[0, 0] == 110
        source.set_settings(settings.with_pose(Pose([0, 0, 500], [0, 0, 45])))
        second = source.read()
        assert np.allclose(second.truth.position_mm, [0, 0, 500]) and np.allclose(
            second.truth.angles_deg, [0, 0, 45]
        )


def test_virtual_bench_wobble_moves_within_its_amplitude(camera_vga) -> None:
    source = VirtualBenchSource(camera_vga, 50.0, VirtualBenchSettings(wobble_deg=5.0, wobble_period_s=2.0))
    base = source.settings.pose.angles_deg
    poses = [source.true_pose(t) for t in np.linspace(0.0, 2.0, 9)]
    alphas = np.array([p.angles_deg[0] for p in poses])
    assert alphas.max() == pytest.approx(base[0] + 5.0) and alphas.min() == pytest.approx(base[0] - 5.0)
    assert all(p.angles_deg[2] == base[2] for p in poses)


def test_virtual_bench_out_of_view_pose_still_delivers_a_frame(camera_vga) -> None:
    settings = VirtualBenchSettings(fps=0.0).with_pose(Pose([1500.0, 0.0, 300.0], [0, 0, 0]))
    with VirtualBenchSource(camera_vga, 50.0, settings) as source:
        frame = source.read()
        assert frame.image.shape == (480, 640) and frame.truth is not None
        assert any("out of view" in note for note in source.notes)


def test_video_file_ends_or_loops(video_file: Path) -> None:
    with VideoFileSource(video_file) as source:
        levels = [float(source.read().image.mean()) for _ in range(VIDEO_FRAMES)]
        with pytest.raises(EndOfStream):
            source.read()
    assert np.allclose(levels, [30 + 30 * i for i in range(VIDEO_FRAMES)], atol=4)  # MJPG is lossy
    with VideoFileSource(video_file, loop=True) as source:
        again = [float(source.read().image.mean()) for _ in range(VIDEO_FRAMES + 2)]
    assert np.allclose(again[VIDEO_FRAMES:], again[:2], atol=1)


def test_missing_or_undecodable_video_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match="no such file"):
        VideoFileSource(tmp_path / "nope.avi").open()
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"not a video at all" * 10)
    with pytest.raises(SourceError, match=r"junk\.avi"):
        source = VideoFileSource(junk)
        source.open()
        source.read()


def test_folder_reads_sorted_and_reports_unreadable_files(image_folder: Path) -> None:
    (image_folder / "b2.png").write_bytes(b"\x89PNG broken")
    with ImageFolderSource(image_folder) as source:
        frames = [source.read() for _ in range(3)]
        with pytest.raises(EndOfStream):
            source.read()
    assert [f.label for f in frames] == ["a.png", "b.png", "c.png"]
    assert [int(f.image.mean()) for f in frames] == [50, 100, 150]
    assert [p.name for p in source.skipped] == ["b2.png"]
    assert any("b2.png" in note for note in source.notes)


def test_folder_of_only_broken_images_raises(tmp_path: Path) -> None:
    (tmp_path / "x.jpg").write_bytes(b"garbage")
    with pytest.raises(SourceError, match="none of its 1 image files"), ImageFolderSource(tmp_path) as source:
        source.read()
    (tmp_path / "empty").mkdir()
    with pytest.raises(SourceError, match="no image files"):
        ImageFolderSource(tmp_path / "empty").open()
    with pytest.raises(SourceError, match="no such folder"):
        ImageFolderSource(tmp_path / "x.jpg").open()


def test_picamera2_missing_gives_the_install_hint(no_picamera2) -> None:
    with pytest.raises(SourceError) as info:
        Picamera2Source().open()
    assert str(info.value) == PICAMERA2_MISSING
    assert "sudo apt install python3-picamera2" in str(info.value)


def test_picamera2_sets_resolution_and_locks_exposure(fake_picamera2) -> None:
    source = Picamera2Source(Picamera2Settings(width=320, height=240, settle_frames=3))
    with source:
        camera = fake_picamera2.instances[-1]
        assert camera.config == {"main": {"size": (320, 240), "format": "RGB888"}} and camera.started
        frames = [source.read() for _ in range(4)]
        assert frames[0].image.shape == (240, 320, 3)
        assert camera.controls == [{"AeEnable": False, "ExposureTime": 12345, "AnalogueGain": 2.5}]
    assert camera.closed and not camera.started


def test_picamera2_fixed_exposure_is_set_before_start(fake_picamera2) -> None:
    with Picamera2Source(Picamera2Settings(exposure_us=5000, gain=1.5)) as source:
        source.read()
        assert fake_picamera2.instances[-1].controls == [
            {"AeEnable": False, "ExposureTime": 5000, "AnalogueGain": 1.5}
        ]


class DeadCapture:
    """A VideoCapture that opens (or not) and then never delivers a frame: an unplugged camera."""

    def __init__(self, opened: bool) -> None:
        self.opened = opened

    def isOpened(self) -> bool:
        return self.opened

    def read(self):
        return False, None

    def set(self, *args) -> bool:
        return True

    def release(self) -> None:
        pass


def test_usb_camera_absent_or_unplugged(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", lambda index, *a: DeadCapture(False))
    with pytest.raises(SourceError, match="cannot open USB camera 3"):
        UsbCameraSource(3).open()
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", lambda index, *a: DeadCapture(True))
    with UsbCameraSource(0) as source, pytest.raises(SourceError, match="stopped delivering"):
        source.read()


def test_auto_falls_back_to_the_virtual_bench_and_says_why(no_picamera2, monkeypatch) -> None:
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", lambda index, *a: DeadCapture(False))
    source = open_source("auto", side_mm=40.0)
    try:
        assert isinstance(source, VirtualBenchSource) and source.side_mm == 40.0
        note = source.notes[0]
        assert note.startswith("auto chose virtual bench")
        assert "picamera2 is not installed" in note and "cannot open USB camera 0" in note
    finally:
        source.close()


def test_a_picamera2_that_fails_to_import_is_a_source_error_and_auto_moves_on(tmp_path, monkeypatch) -> None:
    # The OS's picamera2 under a numpy 2 in the venv raises ValueError while importing (simplejpeg).
    package = tmp_path / "picamera2"
    package.mkdir()
    (package / "__init__.py").write_text(
        'raise ValueError("numpy.dtype size changed, may indicate binary incompatibility")\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "picamera2", raising=False)
    with pytest.raises(SourceError, match=r"fails to import .*numpy\.dtype size changed.*numpy<2"):
        Picamera2Source().open()
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", lambda index, *a: DeadCapture(False))
    source = open_source("auto")
    try:
        assert isinstance(source, VirtualBenchSource)
        assert "picamera2 is installed but fails to import" in source.notes[0]
    finally:
        source.close()


def test_auto_prefers_picamera2(fake_picamera2) -> None:
    source = open_source("auto")
    try:
        assert isinstance(source, Picamera2Source) and source.notes[0].startswith(
            "auto chose Raspberry Pi camera"
        )
    finally:
        source.close()


def test_source_specs(tmp_path: Path, video_file: Path, image_folder: Path, camera_vga) -> None:
    assert isinstance(make_source("virtual"), VirtualBenchSource)
    assert isinstance(make_source("picamera2"), Picamera2Source)
    usb = make_source("usb:2", camera=camera_vga)
    assert isinstance(usb, UsbCameraSource) and (usb.index, usb.width, usb.height) == (2, 640, 480)
    assert isinstance(make_source(str(video_file), loop=True), VideoFileSource)
    assert isinstance(make_source(str(image_folder)), ImageFolderSource)
    with pytest.raises(SourceError, match="usb:0"):
        make_source("usb:x")
    with pytest.raises(SourceError, match="not one of auto, virtual, picamera2, usb:N"):
        make_source(str(tmp_path / "missing"))


class CountingSource(FrameSource):
    """Frames whose pixel value is their index; fails after ``limit`` frames."""

    name = "counting"

    def __init__(self, limit: int) -> None:
        super().__init__()
        self.limit = limit

    def _open_impl(self) -> None:
        pass

    def _read_impl(self, index: int) -> Frame:
        if index >= self.limit:
            raise SourceError("unplugged")
        time.sleep(0.001)
        return Frame(np.full((2, 2), index % 256, np.uint8), time.monotonic(), index)

    def _close_impl(self) -> None:
        pass


def test_latest_frame_reader_keeps_only_the_newest_frame_then_reports_the_failure() -> None:
    from qrfield.sources import LatestFrameReader

    source = CountingSource(limit=50)
    source.open()
    reader = LatestFrameReader(source).start()
    while reader.running:  # let the reader run ahead of a slow consumer
        time.sleep(0.01)
    newest = reader.get(timeout=1.0)
    assert newest.index == 49  # the older unread frames were dropped, not queued
    assert reader.dropped == 49 and reader.read_count == 50
    with pytest.raises(SourceError, match="unplugged"):
        reader.get(timeout=1.0)
    assert reader.stop()
    source.close()


def test_latest_frame_reader_reads_an_on_request_source_one_frame_ahead_only() -> None:
    from qrfield.sources import LatestFrameReader

    source = CountingSource(limit=1000)
    source.live = False
    source.open()
    reader = LatestFrameReader(source).start()
    first = reader.get(timeout=2.0)
    time.sleep(0.05)  # a slow consumer: a live reader would have read dozens of frames meanwhile
    second = reader.get(timeout=2.0)
    assert (first.index, second.index) == (0, 1) and reader.dropped == 0
    assert reader.read_count <= 3
    assert reader.stop()
    source.close()
