"""``qrfield camera list|check``: a clear line without cameras, the stand-ins' modes, and the model
of a stream with the numbers it comes from (checked against hand-computed values)."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest

from qrfield.cli import main
from qrfield.sources import discovery
from qrfield.sources import opencv as opencv_module
from qrfield.sources.picamera_sim import picamera2_class


@pytest.fixture
def no_cameras(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "picamera2", None)  # import picamera2 fails
    monkeypatch.setattr(discovery, "V4L2_SYSFS", discovery.Path("/nonexistent/video4linux"))
    monkeypatch.setattr(discovery.sys, "platform", "linux")


def test_list_on_a_machine_without_cameras_says_so_in_one_line(no_cameras, capsys) -> None:
    assert main(["camera", "list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 1 and out[0].startswith("no cameras found: picamera2: picamera2 is not installed")
    assert "USB: no camera OpenCV can open (no V4L2 devices" in out[0]


def test_list_simulated_shows_the_stand_ins_marked_as_such(no_cameras, capsys) -> None:
    assert main(["camera", "list", "--simulated"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("no cameras found")  # the stand-ins are not cameras
    assert "SIMULATED camera 0: imx708" in out and "[--source picamera2-sim:imx708]" in out
    assert "1536x864 10-bit [120.13 fps - (768, 432)/3072x1728 crop]" in out
    assert "autofocus: LensPosition 0..15 dioptres (default 1)" in out


def test_list_shows_a_picamera2_camera_and_its_modes(monkeypatch, capsys) -> None:
    module = types.ModuleType("picamera2")
    module.Picamera2 = picamera2_class("imx219")  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "picamera2", module)
    monkeypatch.setattr(discovery, "usb_cameras", lambda: ([], "none"))
    assert main(["camera", "list"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("camera 0: imx219") and "(USB: no camera OpenCV can open (none))" in out
    assert "640x480 10-bit [206.65 fps - (1000, 752)/1280x960 crop]" in out


def test_check_shows_the_chosen_mode_crop_and_model_with_its_formula(capsys) -> None:
    argv = ["camera", "check", "--source", "picamera2-sim:imx219", "--camera", "picam-v2"]
    assert main([*argv, "--picamera-width", "1280", "--picamera-height", "720"]) == 0
    out = capsys.readouterr().out
    # By hand: 1640x1232 bounded to 16:9 is 1640x922, centred: (0, 155), x2: (0, 310)/3280x1844;
    # fx = 2714.286 * 1280 / 3280 = 1059.234, fy = 2714.286 * 720 / 1844 = 1059.808.
    assert "mode asked for: 1640x1232 10-bit: the binned full-field-of-view mode for 1280x720" in out
    assert "ScalerCrop: (0, 310)/3280x1844 (the first frame's metadata)" in out
    assert "camera model of the stream: 1280x720 px, fx 1059.2, fy 1059.8, cx 639.5, cy 359.5" in out
    assert "fx = f * out_w / crop_w = 2714.286 * 1280 / 3280 = 1059.234" in out
    assert "frame time: the frame's SensorTimestamp" in out


def test_check_of_the_autofocus_stand_in_shows_manual_focus(capsys) -> None:
    argv = ["camera", "check", "--source", "picamera2-sim:imx708", "--picamera-lens-position", "2"]
    assert main([*argv, "--picamera-width", "640", "--picamera-height", "480"]) == 0
    out = capsys.readouterr().out
    assert "camera model: the imx708's preset picam-v3 (name yours with --camera)" in out
    assert "focus: manual (AfMode 0) at 2 dioptres (lens_position setting)" in out
    assert "ScalerCrop: (576, 0)/3456x2592" in out  # 2304x1296 cropped to 4:3, x2
    # By hand: f = 3385.714 * v(2) / 4.74 with v(2) = 1 / (1/4.74 - 0.002), then * 640 / 3456.
    fx = 3385.714 / (1 - 0.002 * 4.74) * 640 / 3456
    assert f"fx {fx:.1f}" in out


def test_check_without_the_camera_is_one_clear_line(no_cameras, capsys) -> None:
    assert main(["camera", "check"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("qrfield camera check: picamera2 is not installed") and "Traceback" not in err


class Webcam:
    """A VideoCapture of a 1280x720 webcam (no focus or exposure controls)."""

    def __init__(self, *args) -> None:
        self.size = (1280, 720)

    def isOpened(self) -> bool:
        return True

    def set(self, prop, value) -> bool:
        return False

    def get(self, prop) -> float:
        return {3: 1280.0, 4: 720.0}.get(prop, 0.0)

    def read(self):
        return True, np.zeros((720, 1280, 3), np.uint8)

    def release(self) -> None:
        pass


def test_check_of_a_usb_camera_checks_the_model_against_the_frames(monkeypatch, capsys) -> None:
    monkeypatch.setattr(opencv_module.cv2, "VideoCapture", Webcam)
    assert main(["camera", "check", "--source", "usb:0", "--camera", "webcam-60"]) == 0
    out = capsys.readouterr().out
    assert "frames: 3 read at 1280x720" in out and "camera model: webcam-60" in out
    assert main(["camera", "check", "--source", "usb:0", "--camera", "webcam-60@640x360"]) == 1
    assert "delivers 1280x720 frames (asked for 640x360)" in capsys.readouterr().err
