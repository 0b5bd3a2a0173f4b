"""Camera models: presets, JSON round trip, scaling, lookup by name, clear errors for bad files."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from qrfield.camera import CameraModel, CameraModelError, camera_origin, preset_names, resolve_camera


def test_presets_match_their_datasheet_formula():
    # f_px = focal length / pixel pitch, worked out by hand from the datasheets.
    expected = {
        "picam-v1": (3.60 / 1.4e-3, 2592, 1944),
        "picam-v2": (3.04 / 1.12e-3, 3280, 2464),
        "picam-v3": (4.74 / 1.4e-3, 4608, 2592),
        "picam-hq-6mm": (6.0 / 1.55e-3, 4056, 3040),
        "webcam-60": (640 / math.tan(math.radians(30)), 1280, 720),
    }
    assert set(expected) <= set(preset_names())
    for name, (focal, width, height) in expected.items():
        cam = resolve_camera(name)
        assert cam.size == (width, height)
        assert cam.fx == pytest.approx(focal, abs=1e-3) and cam.fy == pytest.approx(focal, abs=1e-3)
        assert (cam.cx, cam.cy) == ((width - 1) / 2, (height - 1) / 2)
        assert "f_px" in cam.notes  # the formula is written in the file
    assert resolve_camera("webcam-60").fov_deg[0] == pytest.approx(60.0, abs=1e-4)


def test_scaling_keeps_pixel_centres_consistent():
    cam = resolve_camera("picam-v1")  # 2592x1944 -> 648x486 is an exact 1/4
    small = resolve_camera("picam-v1@648x486")
    assert small.fx == pytest.approx(cam.fx / 4)
    # Pixel edges scale: the image centre stays the image centre, (W-1)/2.
    assert small.cx == pytest.approx((648 - 1) / 2) and small.cy == pytest.approx((486 - 1) / 2)
    # A ray through the same point on the sensor lands on corresponding pixels.
    point = np.array([[0.1, -0.05, 1.0]])
    big_px = cv2.projectPoints(point, np.zeros(3), np.zeros(3), cam.K, None)[0].ravel()
    small_px = cv2.projectPoints(point, np.zeros(3), np.zeros(3), small.K, None)[0].ravel()
    assert small_px == pytest.approx((big_px + 0.5) / 4 - 0.5)


def test_scaling_to_another_aspect_ratio_is_refused():
    with pytest.raises(CameraModelError, match="aspect ratio"):
        resolve_camera("picam-v3@640x480")


def test_focal_only_model_has_centred_principal_point():
    cam = CameraModel.from_focal(600.0, 640, 480)
    assert (cam.cx, cam.cy) == (319.5, 239.5)
    assert not cam.has_distortion


def test_json_round_trip(tmp_path):
    cam = CameraModel(
        fx=612.5,
        fy=611.0,
        cx=320.2,
        cy=241.7,
        width=640,
        height=480,
        dist=[0.1, -0.2, 0.001, -0.002, 0.05],
        name="bench-cam",
    )
    path = tmp_path / "bench-cam.json"
    cam.save(path)
    back = CameraModel.load(path)
    assert back == cam
    np.testing.assert_array_equal(back.dist, cam.dist)


def test_cwd_calib_is_a_path_not_a_name_and_never_replaces_a_preset(tmp_path, monkeypatch, capsys):
    # docs/cli.md: ./calib/NAME.json is not searched by name (it silently replaced the shipped preset
    # picam-v2 wherever such a folder happened to be); its path works, and says which file it is.
    (tmp_path / "calib").mkdir()
    CameraModel.from_focal(700.0, 800, 600, name="mine").save(tmp_path / "calib" / "mine.json")
    CameraModel.from_focal(999.0, 3280, 2464, name="picam-v2").save(tmp_path / "calib" / "picam-v2.json")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path / "config"))
    with pytest.raises(CameraModelError, match=r"not searched by name: give its path, --camera calib/mine"):
        resolve_camera("mine")
    cam = resolve_camera("calib/mine.json@400x300")
    assert cam.fx == pytest.approx(350.0) and cam.size == (400, 300)
    assert camera_origin(cam) == "profile calib/mine.json"
    preset = resolve_camera("picam-v2")
    assert preset.fx == pytest.approx(2714.286)  # the datasheet preset, not ./calib's 999 px
    assert camera_origin(preset).startswith("shipped preset ") and preset.path.endswith("calib/picam-v2.json")


def test_users_profile_of_a_preset_name_wins_and_says_so(tmp_path, monkeypatch):
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path))
    (tmp_path / "calib").mkdir()
    CameraModel.from_focal(2500.0, 3280, 2464, name="picam-v2").save(tmp_path / "calib" / "picam-v2.json")
    cam = resolve_camera("picam-v2@640x480")
    assert cam.fx == pytest.approx(2500.0 * 640 / 3280)
    assert camera_origin(cam) == (
        f"profile {tmp_path / 'calib' / 'picam-v2.json'} (it replaces the shipped preset of that name)"
    )


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "not JSON"),
        (json.dumps({"width": 640, "height": 480, "fy": 500, "cx": 320, "cy": 240}), "missing field 'fx'"),
        (
            json.dumps({"width": 640, "height": 480, "fx": -5, "fy": 500, "cx": 320, "cy": 240}),
            "'fx' must be a positive",
        ),
        (
            json.dumps({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 900, "cy": 240}),
            "'cx'.*outside",
        ),
        (
            json.dumps({"width": 640, "height": 480, "fx": "big", "fy": 500, "cx": 320, "cy": 240}),
            "'fx' must be a number",
        ),
        (json.dumps([1, 2, 3]), "expected a JSON object"),
    ],
)
def test_bad_files_name_file_and_field(tmp_path, content, message):
    path = tmp_path / "broken.json"
    path.write_text(content)
    with pytest.raises(CameraModelError, match=message) as info:
        CameraModel.load(path)
    assert str(path) in str(info.value)


def test_unknown_name_lists_presets():
    with pytest.raises(CameraModelError, match="picam-v2"):
        resolve_camera("no-such-camera")


def test_malformed_size():
    with pytest.raises(CameraModelError, match="WxH"):
        resolve_camera("picam-v2@640by480")


def test_camera_and_focal_options_clash_only_when_both_are_typed():
    import argparse

    from qrfield.camera import add_camera_arguments, camera_from_args

    parser = argparse.ArgumentParser()
    add_camera_arguments(parser, default="picam-v2@640x480")
    # --focal-px/--size over the default --camera: the focal-only model.
    cam = camera_from_args(parser.parse_args(["--focal-px", "600", "--size", "640x480"]))
    assert (cam.fx, cam.cx, cam.cy) == (600.0, 319.5, 239.5)
    assert camera_from_args(parser.parse_args([])).name == "picam-v2@640x480"
    typed = parser.parse_args(["--camera", "picam-v1@648x486", "--focal-px", "600", "--size", "640x480"])
    with pytest.raises(CameraModelError, match="not both"):
        camera_from_args(typed)


def test_a_path_with_an_at_sign_is_a_file_not_a_size(tmp_path):
    folder = tmp_path / "me@lab"
    folder.mkdir()
    CameraModel.from_focal(600.0, 640, 480).save(folder / "cam.json")
    assert resolve_camera(str(folder / "cam.json")).fx == 600.0
    assert resolve_camera(str(folder / "cam.json") + "@320x240").fx == pytest.approx(300.0)
