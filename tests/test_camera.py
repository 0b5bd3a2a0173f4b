"""Camera models: presets, JSON round trip, scaling, lookup by name, clear errors for bad files."""

from __future__ import annotations

import dataclasses
import json
import math

import cv2
import numpy as np
import pytest

from qrfield.camera import CameraModel, CameraModelError, camera_origin, preset_names, resolve_camera
from qrfield.geometry import Pose
from qrfield.render import render_view


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


# ---------------------------------------------------------------------- camera models follow the stream


def test_through_crop_matches_hand_computed_values():
    # docs/conventions.md: f_out = f * out_w / crop_w; c_out = (c - crop_x + 0.5) * out_w / crop_w - 0.5.
    sensor = CameraModel(1000.0, 1100.0, 400.0, 300.0, 800, 600, sensor_crop=(0, 0, 800, 600))
    small = sensor.through_crop((100, 50, 400, 300), (200, 150))
    assert (small.fx, small.fy) == (500.0, 550.0)  # 1000 * 200 / 400, 1100 * 150 / 300
    assert (small.cx, small.cy) == (149.75, 124.75)  # (400 - 100 + 0.5) / 2 - 0.5, (300 - 50 + 0.5) / 2 - 0.5
    assert small.size == (200, 150) and small.sensor_crop == (100, 50, 400, 300)
    # The IMX219's cropped 640x480 mode: the centre 1280x960 of picam-v2, f 2714.286 / 2.
    vga = resolve_camera("picam-v2").through_crop((1000, 752, 1280, 960), (640, 480))
    assert vga.fx == pytest.approx(1357.143, abs=1e-3) and (vga.cx, vga.cy) == (319.5, 239.5)


def test_a_model_of_a_crop_maps_through_another_crop_as_the_full_sensor_does():
    sensor = CameraModel(1000.0, 1100.0, 400.0, 300.0, 800, 600, sensor_crop=(0, 0, 800, 600))
    small = sensor.through_crop((100, 50, 400, 300), (200, 150))
    # From the crop's own model, mapped through (300, 200)/200x150 to 100x75, by hand from the
    # full sensor: f 1000 * 100 / 200 = 500, c (400 - 300 + 0.5) / 2 - 0.5 = 49.75.
    again = small.through_crop((300, 200, 200, 150), (100, 75))
    assert np.allclose(again.K, [[500, 0, 49.75], [0, 550, 49.75], [0, 0, 1]])
    back = small.through_crop((0, 0, 800, 600), (800, 600))
    assert np.allclose(back.K, sensor.K)


def test_through_crop_agrees_with_the_sensor_image_cropped_and_binned_by_opencv():
    # Independent truth: render the whole sensor, crop it and average 2x2 pixels (OpenCV INTER_AREA,
    # what binning does); the model through_crop gives must render the same image.
    sensor = CameraModel(800.0, 800.0, 319.5, 239.5, 640, 480, sensor_crop=(0, 0, 640, 480))
    pose = Pose([12.0, -8.0, 250.0], [20.0, -15.0, 30.0])
    whole = render_view(sensor, 40.0, pose, supersample=4).image.astype(float)
    x, y, w, h = crop = (96, 64, 384, 288)
    binned = cv2.resize(whole[y : y + h, x : x + w], (192, 144), interpolation=cv2.INTER_AREA)
    model = sensor.through_crop(crop, (192, 144))
    rendered = render_view(model, 40.0, pose, supersample=4).image.astype(float)
    off = dataclasses.replace(model, cx=model.cx + 0.25)  # a quarter-pixel error is plain to see
    off_rendered = render_view(off, 40.0, pose, supersample=4).image.astype(float)
    assert np.abs(rendered - binned).mean() < 0.2 < 1.0 < np.abs(off_rendered - binned).mean()


def test_through_crop_refuses_a_model_that_does_not_say_its_sensor_crop():
    with pytest.raises(CameraModelError, match=r"no 'sensor_crop'.*sensor crop \(0, 2\)/3280x2460"):
        CameraModel.from_focal(530.0, 640, 480).through_crop((0, 2, 3280, 2460), (640, 480))
    with pytest.raises(CameraModelError, match="reaches outside the 3280x2464 sensor"):
        resolve_camera("picam-v2").through_crop((2000, 0, 1640, 1232), (640, 480))


def test_presets_state_the_whole_sensor_and_scaling_keeps_it():
    for name in ("picam-v1", "picam-v2", "picam-v3", "picam-hq-6mm"):
        cam = resolve_camera(name)
        assert cam.sensor_crop == (0, 0, cam.width, cam.height) and cam.sensor_resolution == cam.size
    assert resolve_camera("picam-v2@640x480").sensor_crop == (0, 0, 3280, 2464)
    assert resolve_camera("webcam-60").sensor_crop is None  # a webcam's sensor geometry is unknown


def test_sensor_fields_round_trip_through_json_and_bad_ones_name_the_field(tmp_path):
    cam = resolve_camera("picam-v3").through_crop(
        (576, 0, 3456, 2592), (640, 480), sensor_mode="2304x1296 10-bit"
    )
    cam = dataclasses.replace(cam, lens_position=2.5)
    path = tmp_path / "cam.json"
    cam.save(path)
    data = json.loads(path.read_text())
    assert data["sensor_crop"] == [576, 0, 3456, 2592] and data["sensor_mode"] == "2304x1296 10-bit"
    assert data["lens_position"] == 2.5 and data["sensor_resolution"] == [4608, 2592]
    assert CameraModel.load(path) == cam
    for key, value, message in [
        ("sensor_crop", [0, 0, 100], "'sensor_crop' must be a list of 4 whole numbers"),
        ("sensor_crop", [0, 0, 5000, 2592], r"sensor crop \(0, 0\)/5000x2592 reaches outside"),
        ("sensor_crop", [0, 0, 1.5, 2], "whole numbers"),
        ("lens_position", -1, "'lens_position' must be positive"),
        ("lens_position", "near", "'lens_position' must be a number"),
        ("sensor_mode", 7, "'sensor_mode' must be text"),
    ]:
        path.write_text(json.dumps({**data, key: value}))
        with pytest.raises(CameraModelError, match=message) as info:
            CameraModel.load(path)
        assert str(path) in str(info.value)


def test_a_datasheet_model_follows_the_focus_by_the_thin_lens_equation():
    # picam-v3: f = 4.74 mm, taken at infinity focus. At 3 dioptres (33 cm) the lens sits at
    # v = 1 / (1/4.74 - 3/1000) = 4.808 mm, so the focal lengths in pixels grow by v / f.
    near, text = resolve_camera("picam-v3").at_lens_position(3.0)
    expected = 1 / (1 / 4.74 - 0.003) / 4.74
    assert near.fx == pytest.approx(3385.714 * expected, abs=1e-3) and near.lens_position == 3.0
    assert "datasheet model" in text and f"{expected:.5f}" in text
    calibrated = dataclasses.replace(resolve_camera("picam-v3"), lens_position=3.0)
    same, text = calibrated.at_lens_position(3.0)
    assert same.fx == calibrated.fx and "holds at" in text
    unknown = dataclasses.replace(calibrated, focal_length_mm=None)
    kept, text = unknown.at_lens_position(5.0)
    assert kept.fx == calibrated.fx and "differs from the 3 dioptres" in text
