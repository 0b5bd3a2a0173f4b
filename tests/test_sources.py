"""Camera sources: one contract test runs every source through the FrameSource interface, then
each source's own behaviour (truth, looping, skipped files, picamera2 via a fake module, auto)."""

from __future__ import annotations

import dataclasses
import sys
import time
import types
from pathlib import Path
from typing import ClassVar

import cv2
import numpy as np
import pytest

from qrfield.camera import CameraModel, resolve_camera
from qrfield.geometry import Pose
from qrfield.pipeline import Pipeline
from qrfield.sources import (
    PICAMERA2_MISSING,
    EndOfStream,
    Frame,
    FrameSource,
    ImageFolderSource,
    Picamera2Settings,
    Picamera2Source,
    SimulatedPicamera2Source,
    SourceError,
    UsbCameraSettings,
    UsbCameraSource,
    VideoFileSource,
    VirtualBenchSettings,
    VirtualBenchSource,
    make_source,
    open_source,
)
from qrfield.sources import opencv as opencv_module
from qrfield.sources.picamera_sim import picamera2_class

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


@pytest.fixture
def stand_in(monkeypatch: pytest.MonkeyPatch):
    """``import picamera2`` gives the stand-in (an IMX219 camera showing the bench's card); returns
    a function that switches it to another sensor or scene and returns its Picamera2 class."""

    def install(sensor: str = "imx219", scene: VirtualBenchSettings | None = None) -> type:
        module = types.ModuleType("picamera2")
        module.Picamera2 = picamera2_class(sensor, scene or VirtualBenchSettings(noise_sigma=1.0))  # type: ignore[attr-defined]
        monkeypatch.setitem(sys.modules, "picamera2", module)
        return module.Picamera2  # type: ignore[attr-defined]

    install()
    return install


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
    if kind == "picamera2":  # the real source class, with the stand-in as the picamera2 module
        module = types.ModuleType("picamera2")
        module.Picamera2 = picamera2_class("imx219")  # type: ignore[attr-defined]
        monkeypatch.setitem(sys.modules, "picamera2", module)
        return Picamera2Source(Picamera2Settings(width=96, height=64), profile=camera)
    if kind == "picamera2-sim":
        return make_source("picamera2-sim:imx708", camera=resolve_camera("picam-v3@640x360"))
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["virtual", "usb", "video", "folder", "picamera2", "picamera2-sim"])
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
    assert (frames[0].truth is not None) == (kind in ("virtual", "picamera2-sim")) == source.simulated
    assert source.live == (kind in ("usb", "picamera2", "picamera2-sim"))
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


def test_virtual_bench_notes_stay_bounded_over_a_long_run() -> None:
    # A card wobbling across the image edge: every out-of-view frame has its own vertex pixels in
    # the text, and the bench made a note of each: ``notes`` grew a string a frame for as long as
    # it ran (and the frame loop copied the list each frame). One note each time the card leaves
    # the view, at most MAX_VIEW_NOTES over the bench's life.
    from qrfield.sources.virtual import MAX_VIEW_NOTES

    camera = CameraModel.from_focal(100.0, 80, 60)  # tiny frames: fast to render
    # At z 300 mm the card's right edge leaves the 80 px image beyond x = 96 mm.
    settings = VirtualBenchSettings(fps=0.0, noise_sigma=0.0, blur_px=0.0)
    with VirtualBenchSource(camera, 50.0, settings) as source:
        for i in range(10):  # one excursion, the card moving at the edge: one note
            source.set_settings(settings.with_pose(Pose([100.0 + 0.5 * i, 0.0, 300.0], [0, 0, 0])))
            source.read()
        assert len(source.notes) == 1 and "out of view" in source.notes[0]
        for i in range(MAX_VIEW_NOTES + 2):  # in view, out of view, again and again
            source.set_settings(settings.with_pose(Pose([0.0, 0.0, 300.0], [0, 0, 0])))
            source.read()
            source.set_settings(settings.with_pose(Pose([110.0 + 0.5 * i, 0.0, 300.0], [0, 0, 0])))
            source.read()
        assert len(source.notes) == MAX_VIEW_NOTES
        assert "not noted" in source.notes[-1]


def test_video_file_ends_or_loops(video_file: Path) -> None:
    with VideoFileSource(video_file) as source:
        levels = [float(source.read().image.mean()) for _ in range(VIDEO_FRAMES)]
        with pytest.raises(EndOfStream):
            source.read()
    assert np.allclose(levels, [30 + 30 * i for i in range(VIDEO_FRAMES)], atol=4)  # MJPG is lossy
    with VideoFileSource(video_file, loop=True) as source:
        again = [float(source.read().image.mean()) for _ in range(VIDEO_FRAMES + 2)]
    assert np.allclose(again[VIDEO_FRAMES:], again[:2], atol=1)


def test_a_video_files_frames_carry_the_files_own_times(video_file: Path) -> None:
    """The file was written at 10 frames/s: frame i is at i / 10 s on its clock, however fast it is
    decoded; a loop's next pass starts VIDEO_LOOP_GAP_S after the last frame, never back at 0."""
    with VideoFileSource(video_file, loop=True) as source:
        times = [source.read().t_media for _ in range(VIDEO_FRAMES + 2)]
    first = [0.1 * i for i in range(VIDEO_FRAMES)]
    assert times[:VIDEO_FRAMES] == pytest.approx(first, abs=1e-9)
    again = first[-1] + opencv_module.VIDEO_LOOP_GAP_S
    assert times[VIDEO_FRAMES:] == pytest.approx([again, again + 0.1], abs=1e-9)


def test_a_clip_in_mpeg4_part_2_says_its_corners_are_coarser_than_their_std(tmp_path: Path) -> None:
    """OpenCV's mp4v writer (FFmpeg reports FMP4) codes a small code's edges coarsely enough that
    its corners move several times their std (docs/headless.md): the source says so; MJPG does not."""
    notes = {}
    for fourcc, name in (("mp4v", "clip.mp4"), ("MJPG", "clip.avi")):
        writer = cv2.VideoWriter(str(tmp_path / name), cv2.VideoWriter_fourcc(*fourcc), 10.0, SIZE, False)
        if not writer.isOpened():
            pytest.skip(f"this OpenCV build cannot write {fourcc}")
        for i in range(3):
            writer.write(np.full(SIZE[::-1], 60 * i, np.uint8))
        writer.release()
        with VideoFileSource(tmp_path / name) as source:
            notes[fourcc] = list(source.notes)
    assert any("MPEG-4 Part 2" in note and "std" in note for note in notes["mp4v"]), notes
    assert notes["MJPG"] == []


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
    (tmp_path / "notes.txt").write_text("not an image", encoding="utf-8")
    with pytest.raises(SourceError, match="no such folder"):
        ImageFolderSource(tmp_path / "notes.txt").open()


@pytest.mark.slow
def test_one_image_file_as_a_source_goes_through_the_image_reader(tmp_path: Path, capfd) -> None:
    """Issue 23: ``--source photo.png`` went to OpenCV's video decoder (FFmpeg): no pixel limit,
    no PNG inflation cap (a 100x100 PNG inflating to 60 MB cost 8 s of CPU), and FFmpeg's
    "[png @ 0x...] chunk too big" lines on stderr. It is read as an image now."""
    import struct
    import zlib

    photo = tmp_path / "photo.png"
    image = np.random.default_rng(3).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    assert cv2.imwrite(str(photo), image)
    source = make_source(str(photo))
    assert isinstance(source, ImageFolderSource)
    with source:
        assert np.array_equal(source.read().image, image)  # the file's own pixels
        with pytest.raises(EndOfStream):
            source.read()

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    def png(name: str, width: int, height: int, data: bytes) -> str:
        header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
        body = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", data) + chunk(b"IEND", b"")
        (tmp_path / name).write_bytes(body)
        return str(tmp_path / name)

    compressor = zlib.compressobj(9)
    bomb = b"".join(compressor.compress(bytes(1 << 20)) for _ in range(60)) + compressor.flush()
    cases = {
        png("huge.png", 10000, 6000, zlib.compress(bytes(6001))): "above the limit of 50 MP",
        png("bomb.png", 100, 100, bomb): "inflates to more than the 10100 bytes",
        png("short.png", 100, 100, zlib.compress(bytes(101 * 50))): "damaged or truncated PNG",
    }
    capfd.readouterr()
    for path, why in cases.items():
        with pytest.raises(SourceError, match=why) as caught, make_source(path) as source:
            source.read()
        assert str(caught.value).startswith(f"image {path}: ") and "\n" not in str(caught.value)
    assert capfd.readouterr().err == ""


def test_picamera2_missing_gives_the_install_hint(no_picamera2) -> None:
    with pytest.raises(SourceError) as info:
        Picamera2Source().open()
    assert str(info.value) == PICAMERA2_MISSING
    assert "sudo apt install python3-picamera2" in str(info.value)


def measured_z(source: FrameSource, named: CameraModel, frames: int = 3) -> list[float]:
    """z (mm) of the card in ``frames`` frames, measured with the model the source says its frames
    have (``source.camera``), else the one named: what ``qrfield run`` does."""
    camera = getattr(source, "camera", None) or named
    pipeline = Pipeline(camera, 50.0, ("ippe",))
    zs = []
    for _ in range(frames):
        result = pipeline.process(source.read())
        assert result.status == "OK", result.reason
        zs.append(float(result.primary.position_mm[2]))
    return zs


def test_picamera2_at_640x480_on_an_imx219_measures_300_mm_as_300_mm(stand_in) -> None:
    # The bug of issue 12: picamera2 picks the IMX219's cropped 640x480 mode for a 640x480 stream,
    # so picam-v2@640x480 (full field of view) measured a card at 300 mm as about 120 mm.
    named = resolve_camera("picam-v2@640x480")
    with open_source("picamera2", camera=named, picamera=Picamera2Settings(width=640, height=480)) as source:
        zs = measured_z(source, named)
    assert np.allclose(zs, 300.0, atol=5.0), zs


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sensor", "profile", "size", "mode"),
    [
        ("imx219", "picam-v2@640x480", (640, 480), "full"),
        ("imx219", "picam-v2", (1280, 720), "full"),  # the 16:9 crop of the 4:3 sensor, no own profile
        ("imx708", "picam-v3", (1536, 864), "full"),
        ("imx708", "picam-v3", (640, 480), "full"),  # the 4:3 crop of the 16:9 sensor
        ("imx219", "picam-v2", (640, 480), "picamera2"),  # picamera2's cropped 640x480 mode, mapped
        ("imx708", "picam-v3", (1536, 864), "picamera2"),  # the IMX708's cropped 1536x864 mode
        ("imx219", "picam-v2", (640, 480), "1920x1080"),  # a mode chosen by size
    ],
)
def test_the_stream_model_follows_mode_crop_and_focus(sensor, profile, size, mode) -> None:
    named = resolve_camera(profile)
    settings = Picamera2Settings(width=size[0], height=size[1], sensor_mode=mode)
    with make_source(f"picamera2-sim:{sensor}", camera=named, picamera=settings) as source:
        zs = measured_z(source, named)
        truth = source.backend.instances[-1].stream_truth()  # the stand-in's own derivation
        assert pytest.approx(truth.K, abs=1e-6) == source.camera.K
    assert np.allclose(zs, 300.0, atol=5.0), zs


def test_the_full_field_mode_is_asked_for_and_recorded(stand_in) -> None:
    with Picamera2Source(Picamera2Settings(), profile=resolve_camera("picam-v2")) as source:
        camera = sys.modules["picamera2"].Picamera2.instances[-1]
        assert camera.camera_configuration()["sensor"] == {"bit_depth": 10, "output_size": (1640, 1232)}
        info = source.stream
        assert info.mode.size == (1640, 1232) and info.scaler_crop == (0, 2, 3280, 2460)
        assert source.camera.sensor_crop == (0, 2, 3280, 2460)
        assert source.camera.sensor_mode == "1640x1232 10-bit"
        # The record: mode and crop in the description (qrfield run's first note), the model next.
        assert "sensor mode 1640x1232 10-bit, ScalerCrop (0, 2)/3280x2460" in source.description
        assert any(n.startswith("camera model: 640x480 px, fx 529.6") for n in source.notes)
        report = "\n".join(info.lines())
        assert "1640x1232 10-bit [41.85 fps - (0, 0)/3280x2464 crop]" in report
        assert "fx = f * out_w / crop_w = 2714.286 * 640 / 3280 = 529.617" in report


def test_a_profile_that_does_not_say_its_sensor_crop_is_refused(stand_in) -> None:
    focal_only = CameraModel.from_focal(530.0, 640, 480)
    with pytest.raises(SourceError, match=r"no 'sensor_crop'.*sensor crop \(0, 2\)/3280x2460"):
        Picamera2Source(profile=focal_only).open()


def test_a_profile_of_another_sensor_is_refused_and_names_the_right_one(stand_in) -> None:
    stand_in("imx708")
    with pytest.raises(SourceError, match=r"3280x2464 sensor, but camera 0's sensor, the imx708, .*picam-v3"):
        Picamera2Source(profile=resolve_camera("picam-v2@640x480")).open()


def test_a_profile_calibrated_at_a_cropped_mode_is_mapped_to_the_full_field_mode(stand_in) -> None:
    # A profile calibrated on the cropped 640x480 mode (sensor crop (1000, 752)/1280x960) used on
    # the full-field stream: f 1357.1 px there is 529.6 px here.
    cropped = resolve_camera("picam-v2").through_crop((1000, 752, 1280, 960), (640, 480))
    with Picamera2Source(profile=cropped) as source:
        assert source.camera.fx == pytest.approx(2714.286 * 640 / 3280, abs=1e-3)
        assert np.allclose(measured_z(source, cropped), 300.0, atol=5.0)


def test_autofocus_camera_is_in_manual_focus_at_the_set_lens_position(stand_in) -> None:
    cls = stand_in("imx708")
    settings = Picamera2Settings(width=1536, height=864, lens_position=2.5)
    with Picamera2Source(settings, profile=resolve_camera("picam-v3")) as source:
        camera = cls.instances[-1]
        controls = camera.controls.make_dict()
        assert controls["AfMode"] == 0 and controls["LensPosition"] == 2.5
        source.read()
        assert camera.capture_metadata()["LensPosition"] == 2.5
        assert source.stream.lens_position == 2.5 and source.camera.lens_position == 2.5
        assert any("lens at 2.50 dioptres" in n for n in source.notes)


def test_lens_position_comes_from_the_profile_and_a_different_one_is_a_warning(stand_in) -> None:
    stand_in("imx708")
    calibrated = dataclasses.replace(resolve_camera("picam-v3@1536x864"), lens_position=2.0)
    with Picamera2Source(Picamera2Settings(width=1536, height=864), profile=calibrated) as source:
        assert source.stream.lens_position == 2.0  # the setting's -1: the profile's lens position
        assert not any(n.startswith("warning") for n in source.notes)
    settings = Picamera2Settings(width=1536, height=864, lens_position=3.5)
    with Picamera2Source(settings, profile=calibrated) as source:
        warning = [n for n in source.notes if n.startswith("warning")]
        assert warning and "3.5 dioptres differs from the 2 dioptres" in warning[0]
        # The thin lens (f = 4.74 mm): v(3.5) / v(2.0) = (1/4.74 - 0.002) / (1/4.74 - 0.0035).
        expected = (1 / 4.74 - 0.002) / (1 / 4.74 - 0.0035)
        assert source.camera.fx / calibrated.scaled(1536, 864).fx == pytest.approx(expected, rel=1e-9)


def test_a_lens_position_the_lens_cannot_reach_is_refused(stand_in) -> None:
    stand_in("imx708")
    with pytest.raises(SourceError, match=r"lens position 20 dioptres .* outside this camera's 0\.\.15"):
        Picamera2Source(Picamera2Settings(lens_position=20.0), profile=resolve_camera("picam-v3")).open()


def test_a_camera_without_autofocus_gets_no_focus_controls(stand_in) -> None:
    with Picamera2Source(Picamera2Settings(lens_position=3.0), profile=resolve_camera("picam-v2")) as source:
        source.read()
        assert "AfMode" not in sys.modules["picamera2"].Picamera2.instances[-1].controls.make_dict()
        assert source.stream.autofocus is False and source.camera.lens_position is None


def test_frame_time_is_the_sensor_timestamp(stand_in) -> None:
    with Picamera2Source(profile=resolve_camera("picam-v2")) as source:
        times = [source.read().t_capture for _ in range(4)]
    # The stand-in's frames are whole frame durations apart (33.333 ms; more when the reader is slow
    # and frames go by unread); delivery times would jitter.
    steps = np.diff(times) / 0.033333
    assert np.all(steps > 0.99) and np.allclose(steps, np.round(steps), atol=1e-3), steps


def test_a_sensor_timestamp_on_another_clock_is_noted_and_not_used(stand_in) -> None:
    cls = stand_in("imx219")
    cls.CLOCK_OFFSET_NS = 3600 * 10**9  # e.g. CLOCK_BOOTTIME an hour ahead after a suspend
    with Picamera2Source(profile=resolve_camera("picam-v2")) as source:
        before = time.monotonic()
        frame = source.read()
        assert before - 1.0 <= frame.t_capture <= time.monotonic()
        assert any("SensorTimestamp is" in n and "delivery times" in n for n in source.notes)


def test_a_digital_zoom_mid_stream_stops_the_source_with_a_clear_error(stand_in) -> None:
    with Picamera2Source(profile=resolve_camera("picam-v2")) as source:
        source.read()
        sys.modules["picamera2"].Picamera2.instances[-1].set_controls({"ScalerCrop": (820, 616, 1640, 1232)})
        with pytest.raises(SourceError, match=r"ScalerCrop changed from \(0, 2\)/3280x2460"):
            source.read()


def test_picamera2_locks_exposure_after_settling(stand_in) -> None:
    with Picamera2Source(Picamera2Settings(width=320, height=240, settle_frames=3)) as source:
        camera = sys.modules["picamera2"].Picamera2.instances[-1]
        frames = [source.read() for _ in range(4)]
        assert frames[0].image.shape == (240, 320, 3) and camera.started
        # The stand-in's automatic exposure reports 10000 us at gain 2.0.
        assert {"AeEnable": False, "ExposureTime": 10000}.items() <= camera.controls.make_dict().items()
        assert "exposure locked at 10000 us, gain 2.00" in source.notes
    assert camera.closed and not camera.started


def test_picamera2_fixed_exposure_is_set_before_start(stand_in) -> None:
    with Picamera2Source(Picamera2Settings(exposure_us=5000, gain=1.5)) as source:
        frame_metadata = sys.modules["picamera2"].Picamera2.instances[-1].capture_metadata()
        source.read()
    assert (frame_metadata["ExposureTime"], frame_metadata["AnalogueGain"]) == (5000, 1.5)


def test_bad_sensor_mode_settings_are_clear_errors(stand_in) -> None:
    with pytest.raises(SourceError, match=r"give full .* picamera2 .* WxH"):
        Picamera2Source(Picamera2Settings(sensor_mode="binned"))
    with pytest.raises(
        SourceError, match="no such mode; its modes are 1640x1232, 1920x1080, 3280x2464, 640x480"
    ):
        Picamera2Source(Picamera2Settings(sensor_mode="800x600")).open()


def test_a_missing_camera_number_is_a_source_error(stand_in) -> None:
    with pytest.raises(SourceError, match="no camera 1"):
        Picamera2Source(Picamera2Settings(camera_num=1)).open()


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

    def get(self, prop) -> float:
        return 0.0

    def release(self) -> None:
        pass


class UvcCapture:
    """A VideoCapture on a V4L2 (UVC) webcam, as OpenCV's V4L2 backend behaves.

    set() returns False for a property the driver does not offer (VideoCapture::set: "true if the
    property is supported by the backend"), and get() reads back what the device took; a size is
    snapped to one the camera offers in the current pixel format (V4L2 VIDIOC_S_FMT adjusts the
    request); frames come at that size. ``offered`` maps FOURCC -> sizes.
    """

    def __init__(self, offered: dict[str, list[tuple[int, int]]], controls: tuple[str, ...] = ()) -> None:
        self.offered = offered
        self.fourcc = next(iter(offered))
        self.size = offered[self.fourcc][0]
        self.props = {name: 0.0 for name in controls}
        if "autofocus" in self.props:
            self.props["autofocus"] = 1.0
            self.props["focus"] = 40.0  # where the autofocus happens to be
        if "auto_exposure" in self.props:
            self.props["auto_exposure"] = 3.0  # V4L2 aperture priority
            self.props["exposure"] = 156.0
        self.log: list[tuple[str, float]] = []

    NAMES: ClassVar[dict[int, str]] = {
        cv2.CAP_PROP_AUTOFOCUS: "autofocus",
        cv2.CAP_PROP_FOCUS: "focus",
        cv2.CAP_PROP_AUTO_EXPOSURE: "auto_exposure",
        cv2.CAP_PROP_EXPOSURE: "exposure",
    }

    def isOpened(self) -> bool:
        return True

    def set(self, prop, value) -> bool:
        if prop == cv2.CAP_PROP_FOURCC:
            text = "".join(chr((int(value) >> (8 * i)) & 0xFF) for i in range(4))
            if text in self.offered:
                self.fourcc = text
                self.size = min(self.offered[text], key=lambda s: abs(s[0] - self.size[0]))
            self.log.append(("fourcc", text))
            return True
        if prop in (cv2.CAP_PROP_FRAME_WIDTH, cv2.CAP_PROP_FRAME_HEIGHT):
            want = (
                (int(value), self.size[1]) if prop == cv2.CAP_PROP_FRAME_WIDTH else (self.size[0], int(value))
            )
            self.size = min(
                self.offered[self.fourcc], key=lambda s: abs(s[0] - want[0]) + abs(s[1] - want[1])
            )
            return True
        name = self.NAMES.get(prop)
        if name not in self.props:
            return False
        if name == "focus" and self.props.get("autofocus"):
            return True  # refused while the autofocus runs, as UVC drivers do (-EBUSY)
        if name == "exposure" and self.props.get("auto_exposure") != 1.0:
            return True
        self.props[name] = float(value)
        self.log.append((name, float(value)))
        return True

    def get(self, prop) -> float:
        if prop == cv2.CAP_PROP_FOURCC:
            return float(sum(ord(c) << (8 * i) for i, c in enumerate(self.fourcc)))
        name = self.NAMES.get(prop)
        return self.props.get(name, 0.0) if name else 0.0

    def read(self):
        return True, np.full((self.size[1], self.size[0], 3), 90, np.uint8)

    def release(self) -> None:
        pass


WEBCAM = {"YUYV": [(640, 480), (1280, 720)], "MJPG": [(640, 480), (1280, 720), (1920, 1080)]}


def usb_on(monkeypatch: pytest.MonkeyPatch, capture: UvcCapture) -> UvcCapture:
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", lambda index, *a: capture)
    return capture


def test_usb_camera_uses_mjpg_above_640x480_and_locks_focus_and_exposure(monkeypatch) -> None:
    cap = usb_on(monkeypatch, UvcCapture(WEBCAM, ("autofocus", "focus", "auto_exposure", "exposure")))
    camera = resolve_camera("webcam-60@1920x1080")
    with UsbCameraSource(0, 1920, 1080, camera=camera, settings=UsbCameraSettings(settle_frames=2)) as source:
        assert cap.fourcc == "MJPG" and source.size == (1920, 1080)  # YUYV offers no 1080p here
        assert cap.props["autofocus"] == 0.0 and "autofocus off, focus held at 40" in source.notes
        frames = [source.read() for _ in range(3)]
        assert frames[0].image.shape == (1080, 1920, 3)
        assert cap.props["auto_exposure"] == 1.0 and cap.props["exposure"] == 156.0  # manual, as settled
        assert "exposure locked at 156 (driver units)" in source.notes
    assert "MJPG" in source.description


def test_usb_camera_at_640x480_keeps_the_drivers_format_and_sets_a_fixed_focus(monkeypatch) -> None:
    cap = usb_on(monkeypatch, UvcCapture(WEBCAM, ("autofocus", "focus")))
    with UsbCameraSource(0, 640, 480, settings=UsbCameraSettings(focus=120)) as source:
        source.read()
        assert cap.fourcc == "YUYV" and ("fourcc", "MJPG") not in cap.log
        assert cap.props["focus"] == 120.0 and "autofocus off, focus fixed at 120" in source.notes
        # Past the settle frames the source tries to lock the exposure: this camera offers none.
        for _ in range(UsbCameraSettings().settle_frames):
            source.read()
        assert any("offers no manual exposure" in n for n in source.notes), source.notes
        assert not any("exposure locked" in n for n in source.notes)


def test_usb_camera_without_focus_or_exposure_controls_says_so(monkeypatch) -> None:
    usb_on(monkeypatch, UvcCapture({"YUYV": [(640, 480)]}))
    with UsbCameraSource(0, 640, 480, settings=UsbCameraSettings(settle_frames=1)) as source:
        source.read()
    assert any("no autofocus switch" in n for n in source.notes)
    assert any("offers no manual exposure" in n for n in source.notes)


def test_usb_frames_of_another_size_than_the_camera_model_are_a_clear_error(monkeypatch) -> None:
    usb_on(monkeypatch, UvcCapture({"YUYV": [(640, 480), (1280, 720)]}))
    camera = resolve_camera("webcam-60@1920x1080")
    with pytest.raises(
        SourceError, match=r"delivers 1280x720 frames \(asked for 1920x1080\).*is for 1920x1080"
    ):
        UsbCameraSource(0, 1920, 1080, camera=camera).open()


def test_usb_camera_absent_or_unplugged(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", lambda index, *a: DeadCapture(False))
    with pytest.raises(SourceError, match="cannot open USB camera 3"):
        UsbCameraSource(3).open()
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", lambda index, *a: DeadCapture(True))
    with pytest.raises(SourceError, match="stopped delivering"):  # opens, but never a frame
        UsbCameraSource(0).open()
    cap = usb_on(monkeypatch, UvcCapture({"YUYV": [(640, 480)]}))
    with UsbCameraSource(0) as source:
        source.read()
        cap.read = DeadCapture(True).read  # unplugged mid-session
        with pytest.raises(SourceError, match="stopped delivering"):
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


def test_auto_prefers_picamera2(stand_in) -> None:
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
    sim = make_source("picamera2-sim:imx708")
    assert isinstance(sim, SimulatedPicamera2Source) and sim.simulated and sim.name == "picamera2-sim:imx708"
    assert sim.description.startswith("SIMULATED")
    with pytest.raises(SourceError, match="no simulated sensor 'imx999'"):
        make_source("picamera2-sim:imx999")
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


def test_a_damaged_video_file_prints_nothing_from_ffmpeg(tmp_path: Path) -> None:
    """A video whose MJPEG frames are damaged: FFmpeg printed "[mjpeg @ 0x...] huffman table decode
    error" on the console (issue 23's audit); the source says it in one line (SourceError) and
    nothing else reaches stderr. In a fresh process: FFmpeg reads its log level once."""
    import os
    import subprocess

    good = tmp_path / "good.avi"
    writer = cv2.VideoWriter(str(good), cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    for k in range(20):
        writer.write(np.full((48, 64, 3), k * 10, np.uint8))
    writer.release()
    data = bytearray(good.read_bytes())
    for k in range(200, len(data), 97):
        data[k] ^= 0x55
    bad = tmp_path / "bad.avi"
    bad.write_bytes(bytes(data))
    script = (
        "import sys\n"
        "from qrfield.sources import VideoFileSource, SourceError, EndOfStream\n"
        "source = VideoFileSource(sys.argv[1])\n"
        "try:\n"
        "    source.open()\n"
        "    while True:\n"
        "        source.read()\n"
        "except (SourceError, EndOfStream) as exc:\n"
        "    print(type(exc).__name__, exc)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    done = subprocess.run(
        [sys.executable, "-c", script, str(bad)], capture_output=True, text=True, timeout=120, env=env
    )
    assert done.returncode == 0, done.stderr
    assert "SourceError" in done.stdout or "EndOfStream" in done.stdout, done.stdout
    assert done.stderr == ""
