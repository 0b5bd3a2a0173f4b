"""Physical limits (qrfield.limits): every number checked before use, each refusal one line."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from qrfield.camera import CameraModel, CameraModelError, distortion_note
from qrfield.cli import main
from qrfield.limits import FOCAL_PX, SIDE_MM, LimitError, check_corners_in_view

SQUARE_ON = "270,190 370,190 370,290 270,290"  # 100 px square about the centre of 640x480


def test_limits_name_where_and_the_range():
    assert SIDE_MM.check("50", "--side-mm") == 50.0
    with pytest.raises(LimitError, match=r"^--side-mm: QR side 1e-300 mm is below .* 0.1 mm"):
        SIDE_MM.check(1e-300, "--side-mm")
    with pytest.raises(LimitError, match=r"focal length 1e\+308 px is above .* 100000 px"):
        FOCAL_PX.check(1e308, "--focal-px")
    with pytest.raises(LimitError, match="finite"):
        SIDE_MM.check(float("nan"), "x")
    with pytest.raises(LimitError, match="must be a number"):
        SIDE_MM.check(True, "x")


def test_corners_may_lie_a_quarter_of_the_image_outside_no_farther():
    check_corners_in_view([[-160.0, 0], [799, 0], [0, 599], [0, -120]], 640, 480)  # at the margins
    with pytest.raises(LimitError, match=r"--corners: V2 \(1e\+06, 240\) px lies outside the 640x480"):
        check_corners_in_view([[0, 0], [1e6, 240], [0, 0], [0, 0]], 640, 480)


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--side-mm", "1e-300"], ["--side-mm", "0.1 mm"]),
        (["--side-mm", "nan"], ["--side-mm", "finite"]),
        (["--side-mm", "50", "--focal-px", "1e308", "--size", "640x480"], ["--focal-px", "100000 px"]),
        (["--side-mm", "50", "--focal-px", "3", "--size", "640x480"], ["--focal-px", "below"]),
        (["--side-mm", "50", "--focal-px", "500", "--size", "640x100000"], ["image size", "65535"]),
    ],
)
def test_absurd_numbers_are_one_line_naming_the_option(argv, words, capsys):
    camera = [] if "--focal-px" in argv else ["--camera", "picam-v2@640x480"]
    assert main(["solve", "--corners", SQUARE_ON, *camera, *argv]) == 2
    captured = capsys.readouterr()
    assert (
        captured.out == "" and len(captured.err.strip().splitlines()) == 1 and "Traceback" not in captured.err
    )
    assert all(word in captured.err for word in words), captured.err


def test_corners_far_outside_the_image_are_refused_not_solved(capsys):
    # Once "converged" at z = 3 mm.
    far = "1e6,1e6 1.0001e6,1e6 1.0001e6,1.0001e6 1e6,1.0001e6"
    assert main(["solve", "--corners", far, "--camera", "picam-v2@640x480", "--side-mm", "50"]) == 2
    err = capsys.readouterr().err
    assert "--corners: V1 (1e+06, 1e+06) px lies outside the 640x480 image" in err
    assert len(err.strip().splitlines()) == 1


def _camera_file(tmp_path, **changes):
    data = {"width": 640, "height": 480, "fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5}
    data.update(changes)
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    ("dist", "words"),
    [
        # Once accepted, z 24x off. OpenCV 5 inverts it (the scale check refuses it), 4.6 cannot.
        ([1e6, 0, 0, 0, 0], "(stretches the 640x480 image's edge|cannot be inverted)"),
        ([-1.0, 0, 0, 0, 0], "cannot be inverted"),  # folds back inside the image
        ([0.0, 0.0, 0.5, 0.0, 0.0], "cannot be inverted"),  # absurd tangential term
    ],
)
def test_a_lens_model_that_cannot_be_inverted_over_the_image_is_refused(tmp_path, dist, words, capsys):
    path = _camera_file(tmp_path, dist=dist)
    with pytest.raises(CameraModelError, match=rf"camera file {path}: field 'dist' .*{words}"):
        CameraModel.load(path)
    assert main(["solve", "--corners", SQUARE_ON, "--camera", str(path), "--side-mm", "50"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "field 'dist'" in err and str(path) in err


def test_real_lens_models_are_accepted(shared_data):
    # BoofCV's calibration of the real Bumblebee2 (k1 = -0.36, k2 = 0.18): a strong barrel lens.
    root = ET.parse(shared_data / "calibration" / "Bumblebee2_Chess" / "intrinsicLeft.xml").getroot()
    values = {}
    for prop in root.iter("void"):
        child = prop[0] if len(prop) else None
        if child is not None and child.tag in ("double", "int"):
            values[prop.get("property")] = float(child.text)
    radial = [float(d.text) for d in root.iter("double") if d.text][-2:]
    cam = CameraModel(
        fx=values["fx"], fy=values["fy"], cx=values["cx"], cy=values["cy"], width=640, height=480,
        dist=[radial[0], radial[1], 0, 0, 0],
    )  # fmt: skip
    assert distortion_note(cam) == ""  # invertible over the whole image, corners included


def test_a_calibration_that_folds_only_in_the_corners_is_accepted_with_advice():
    # OpenCV's own 5-term calibration of the same Bumblebee2 frames (tests/test_calibration.py):
    # k3 makes the model fold back just inside the image's corners, where no chessboard was seen.
    cam = CameraModel(
        fx=524.6, fy=526.9, cx=312.4, cy=231.7, width=640, height=480,
        dist=[-0.368907, 0.235098, 0.000468826, -0.00061524, -0.111032],
    )  # fmt: skip
    note = distortion_note(cam)
    assert "in the corners of the 640x480 image" in note and "--fix-k3" in note


def test_focal_and_size_limits_in_a_camera_file(tmp_path):
    with pytest.raises(CameraModelError, match=r"field 'fx': focal length 1e\+07 px is above"):
        CameraModel.load(_camera_file(tmp_path, fx=1e7))
    with pytest.raises(CameraModelError, match=r"field 'width': image size 100000 px is above"):
        CameraModel.load(_camera_file(tmp_path, width=100000, cx=50000))
    with pytest.raises(CameraModelError, match=r"field 'dist' must be a list of numbers .* got text"):
        CameraModel.load(_camera_file(tmp_path, dist="0.1"))
    with pytest.raises(CameraModelError, match=r"field 'name' must be text, got a list"):
        CameraModel.load(_camera_file(tmp_path, name=["x"]))


def test_a_deeply_nested_camera_file_is_a_clear_error(tmp_path, capsys):
    path = tmp_path / "deep.json"
    path.write_text('{"width": ' + "[" * 100_000 + "]" * 100_000 + "}")
    assert main(["solve", "--corners", SQUARE_ON, "--camera", str(path), "--side-mm", "50"]) == 2
    err = capsys.readouterr().err
    assert f"camera file {path}: nested 100001 levels deep" in err and "Recursion" not in err


def test_render_refuses_a_camera_above_the_pixel_limit(tmp_path, capsys):
    # 60000 x 60000 would be a 3.6 GB frame.
    argv = ["render", "--focal-px", "500", "--size", "60000x60000", "--side-mm", "50"]
    assert main([*argv, "--pose", "0,0,300,0,0,0", "--out", str(tmp_path / "v.png")]) == 2
    assert "above the limit of 50 MP" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_solver_round_trip_still_exact_with_a_strong_real_lens(camera_vga):
    # The lens check must not change a single solve: the same numbers as before for a real model.
    from qrfield.geometry import Pose
    from qrfield.solvers import solve

    cam = CameraModel(
        fx=524.6, fy=526.9, cx=312.4, cy=231.7, width=640, height=480, dist=[-0.36, 0.175, 0, 0, 0]
    )
    pose = Pose([10.0, -5.0, 300.0], [10.0, -15.0, 20.0])
    result = solve(pose.corners_px(cam, 50.0), cam, 50.0, "ippe")
    assert np.linalg.norm(result.position_mm - pose.position_mm) < 1e-6
