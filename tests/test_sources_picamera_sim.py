"""The picamera2 stand-in is checked against what picamera2, libcamera and the kernel drivers publish
(the numbers here are copied from those sources, named beside each), and its images against a
full-resolution render cropped and resized by OpenCV: an independent truth for every figure."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from qrfield.camera import resolve_camera
from qrfield.geometry import Pose
from qrfield.render import render_view
from qrfield.sources.picamera_sim import picamera2_class
from qrfield.sources.virtual import VirtualBenchSettings

STILL = VirtualBenchSettings(noise_sigma=0.0, blur_px=0.0)


def started(model: str, main_size: tuple[int, int], scene: VirtualBenchSettings = STILL, **config):
    """A stand-in camera of sensor ``model``, configured (picamera2's video configuration) and started."""
    camera = picamera2_class(model, scene, 50.0)(0)
    main = {"size": main_size, "format": "RGB888"}
    camera.configure(camera.create_video_configuration(main=main, **config))
    camera.start()
    return camera


def test_imx219_modes_are_those_the_driver_lists():
    # raspberrypi/linux PR 5498 (libcamera-hello --list-cameras), 10-bit modes.
    camera = picamera2_class("imx219")(0)
    ten_bit = [(m["size"], m["fps"], m["crop_limits"]) for m in camera.sensor_modes if m["bit_depth"] == 10]
    assert ten_bit == [
        ((640, 480), 206.65, (1000, 752, 1280, 960)),
        ((1640, 1232), 41.85, (0, 0, 3280, 2464)),
        ((1920, 1080), 47.57, (680, 692, 1920, 1080)),
        ((3280, 2464), 21.19, (0, 0, 3280, 2464)),
    ]
    assert camera.sensor_resolution == (3280, 2464) and camera.sensor_format == "SRGGB10_CSI2P"
    assert "AfMode" not in camera.camera_controls


def test_main_640x480_alone_gets_the_cropped_mode_as_on_a_real_pi():
    # picamera2 issue 1233 / the measurement: 640x480 alone picks the 640x480 mode, whose
    # image is the centre 1280x960 of the sensor, so the focal length is 2714.3 / 2 = 1357.1 px.
    camera = started("imx219", (640, 480))
    assert camera.camera_configuration()["sensor"] == {"bit_depth": 10, "output_size": (640, 480)}
    assert camera.capture_metadata()["ScalerCrop"] == (1000, 752, 1280, 960)
    assert camera.stream_truth().fx == pytest.approx(2714.286 / 2, abs=1e-3)


def test_sensor_output_size_picks_the_binned_mode_and_the_isp_crops_to_4_3():
    # Hand-computed from libcamera: 1640x1232 bounded to 4:3 is 1640x1230, centred at (820, 616):
    # (0, 1)/1640x1230 in mode pixels, x2 to full resolution: (0, 2)/3280x2460.
    camera = started("imx219", (640, 480), sensor={"output_size": (1640, 1232)})
    assert camera.camera_configuration()["sensor"]["output_size"] == (1640, 1232)
    assert camera.capture_metadata()["ScalerCrop"] == (0, 2, 3280, 2460)
    # 16:9 from the same mode: 1640x922 centred at y 616 -> y 155 -> (0, 310)/3280x1844.
    camera = started("imx219", (1280, 720), sensor={"output_size": (1640, 1232)})
    assert camera.camera_controls["ScalerCrop"][2] == (0, 310, 3280, 1844)


def test_imx708_small_16_9_request_gets_its_cropped_1536x864_mode():
    # rpicam-hello --list-cameras: 1536x864 [120.13 fps - (768, 432)/3072x1728 crop].
    camera = started("imx708", (1536, 864))
    assert camera.camera_configuration()["sensor"]["output_size"] == (1536, 864)
    assert camera.capture_metadata()["ScalerCrop"] == (768, 432, 3072, 1728)


@pytest.mark.parametrize(
    ("sensor", "main", "config"),
    [
        ("imx219", (640, 480), {}),
        ("imx219", (640, 480), {"sensor": {"output_size": (1640, 1232)}}),
        ("imx708", (640, 480), {"sensor": {"output_size": (2304, 1296)}}),
        ("imx708", (1536, 864), {}),
    ],
)
def test_frames_are_the_full_resolution_view_cropped_and_resized(sensor, main, config):
    # Independent truth: the full-resolution profile renders the whole sensor; OpenCV crops it to
    # the ScalerCrop and resizes it (area average) to the output. The stand-in must show that image.
    pose = Pose([3.0, -2.0, 600.0], [10.0, -15.0, 20.0])
    full = resolve_camera({"imx219": "picam-v2", "imx708": "picam-v3"}[sensor])
    if sensor == "imx708":
        # Focused on the card (1 / 0.6 m), so no defocus blur; the lens then sits further from the
        # sensor than at infinity focus (thin lens: v = 1 / (1/f - P/1000), f = 4.74 mm).
        lens = 1000.0 / 600.0
        config["controls"] = {"AfMode": 0, "LensPosition": lens}
        scale = 1 / (1 / 4.74 - lens / 1000) / 4.74
        full = type(full)(full.fx * scale, full.fy * scale, full.cx, full.cy, full.width, full.height)
    camera = started(sensor, main, STILL.with_pose(pose), **config)
    for _ in range(2):  # the lens moves at most 1.5 dioptres a frame
        camera.capture_metadata()
    request = camera.capture_request()
    frame, metadata = request.make_array("main")[..., 0].astype(np.float32), request.get_metadata()
    request.release()
    x, y, w, h = metadata["ScalerCrop"]
    whole = render_view(full, 50.0, pose, supersample=1).image.astype(np.float32)
    expected = cv2.resize(whole[y : y + h, x : x + w], main, interpolation=cv2.INTER_AREA)
    difference = np.abs(expected - frame).mean()
    shifted = np.abs(expected[:, 1:] - frame[:, :-1]).mean()  # what a 1 px error looks like
    assert difference < 0.1 * shifted, (difference, shifted)


def test_controls_not_advertised_are_refused_as_picamera2_does():
    camera = picamera2_class("imx219")(0)
    with pytest.raises(RuntimeError, match="Control AfMode is not advertised by libcamera"):
        camera.set_controls({"AfMode": 0})


def test_lens_moves_only_in_manual_mode_at_most_1_5_dioptres_a_frame_and_within_0_to_15():
    camera = started("imx708", (640, 480))
    assert camera.camera_controls["LensPosition"] == (0.0, 15.0, 1.0)  # af.cpp limits, imx708.json
    camera.set_controls({"AfMode": 2, "LensPosition": 5.0})  # continuous: LensPosition is ignored
    assert camera.capture_metadata()["LensPosition"] == 1.0
    camera.set_controls({"AfMode": 0, "LensPosition": 20.0})
    positions = [camera.capture_metadata()["LensPosition"] for _ in range(12)]
    assert positions[:3] == [2.5, 4.0, 5.5] and positions[-1] == 15.0  # slew 1.5 per frame, clamped


def test_sensor_modes_cannot_be_read_while_running():
    camera = started("imx219", (640, 480))
    with pytest.raises(RuntimeError, match="stopped before configuring"):
        camera.sensor_modes  # noqa: B018 (the property configures the camera)


def test_frames_come_at_the_frame_rate_with_sensor_timestamps():
    camera = started("imx219", (640, 480))
    stamps = [camera.capture_metadata()["SensorTimestamp"] for _ in range(4)]
    # FrameDurationLimits (33333, 33333) us; a reader slower than that misses frames, as on a Pi.
    steps = np.diff(stamps) / 33333000
    assert np.all(steps >= 1) and np.all(steps == np.round(steps)), steps


def test_a_camera_that_is_not_there_is_an_index_error():
    with pytest.raises(IndexError):
        picamera2_class("imx219")(1)
