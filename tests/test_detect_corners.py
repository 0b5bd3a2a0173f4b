"""Detected corners against the renderer's exact vertex pixels (independent truth)."""

from __future__ import annotations

import numpy as np
import pytest

from qrfield.detect import Detector, DetectorSettings
from qrfield.detect.refine import refine_corners
from qrfield.geometry import Pose
from qrfield.render import render_view
from qrfield.sampling import random_visible_poses

SIDE_MM = 100.0


@pytest.fixture(scope="module")
def seeded_views(camera_vga):
    """30 seeded workspace views, noise sigma 2 grey levels, blur 0.6 px (the benchmark's conditions)."""
    poses = random_visible_poses(camera_vga, SIDE_MM, 30, seed=11)
    return [
        render_view(camera_vga, SIDE_MM, p, noise_sigma=2.0, blur_px=0.6, seed=i) for i, p in enumerate(poses)
    ]


@pytest.mark.slow
def test_refined_corners_match_the_rendered_truth(seeded_views):
    # `qrfield benchmark detect` measures 0.04 px RMS on 200 such views; 0.1 px leaves room for other
    # seeds and is still below the 0.15 px target. Raw backend corners are ~1 px off, so
    # this bound cannot pass without a working refinement.
    detector = Detector()
    errors, found = [], 0
    for view in seeded_views:
        detections = detector.detect(view.image)
        if not detections:
            continue
        found += 1
        (d,) = detections
        assert d.text == view.text
        assert d.refined
        errors.append(np.linalg.norm(d.corners_px - view.corners_px, axis=1))
    assert found >= 28
    errors = np.concatenate(errors)
    assert np.sqrt(np.mean(errors**2)) < 0.1
    assert errors.max() < 0.5


def test_refinement_beats_the_backend_corners(seeded_views):
    raw = Detector(DetectorSettings(refine=False))
    fine = Detector()
    raw_err, fine_err = [], []
    for view in seeded_views[:12]:
        a, b = raw.detect(view.image), fine.detect(view.image)
        if a and b:
            raw_err.append(np.linalg.norm(a[0].corners_px - view.corners_px, axis=1))
            fine_err.append(np.linalg.norm(b[0].corners_px - view.corners_px, axis=1))
    assert len(raw_err) >= 10
    assert np.sqrt(np.mean(np.square(fine_err))) < 0.3 * np.sqrt(np.mean(np.square(raw_err)))


def test_refine_recovers_a_misplaced_v3(camera_vga):
    # Backends extrapolate V3 (no finder pattern) and can miss it by several pixels.
    view = render_view(
        camera_vga,
        SIDE_MM,
        Pose([5.0, -8.0, 420.0], [15.0, -20.0, 35.0]),
        noise_sigma=2.0,
        blur_px=0.6,
        seed=3,
    )
    rough = view.corners_px + np.array([[0.8, -0.6], [-0.7, 0.9], [3.5, 2.5], [0.6, 0.7]])
    fit = refine_corners(view.image, rough, view.modules)
    assert fit.ok, fit.reason
    assert np.abs(fit.corners_px - view.corners_px).max() < 0.2
    assert np.all(fit.corner_rms_px < 0.2)


def test_clean_frontal_view_is_exact(camera_vga):
    view = render_view(camera_vga, SIDE_MM, Pose([0.0, 0.0, 500.0], [0.0, 0.0, 0.0]))
    (d,) = Detector().detect(view.image)
    assert np.abs(d.corners_px - view.corners_px).max() < 0.05
    assert d.quality > 0.97
    assert d.modules == view.modules


@pytest.mark.parametrize("gamma", [0.0, 90.0, 180.0, 270.0])
@pytest.mark.parametrize("tilt", [(0.0, 0.0), (25.0, -15.0)])
@pytest.mark.parametrize("backend", ["zxing", "zxing-x2", "opencv-aruco", "opencv", "finders"])
def test_every_backend_reports_v1_to_v4_in_design_order(camera_vga, backend, gamma, tilt):
    # A wrong order puts a corner a whole side (~125 px) away; backends stay within a few px (V3,
    # which they extrapolate, up to ~4 px).
    view = render_view(
        camera_vga,
        SIDE_MM,
        Pose([10.0, 5.0, 380.0], [tilt[0], tilt[1], gamma]),
        noise_sigma=2.0,
        blur_px=0.6,
        seed=1,
    )
    detections = Detector(DetectorSettings(backends=backend, refine=False)).detect(view.image)
    assert len(detections) == 1, f"{backend} found {len(detections)} codes"
    assert np.linalg.norm(detections[0].corners_px - view.corners_px, axis=1).max() < 8.0
    refined = Detector(DetectorSettings(backends=backend)).detect(view.image)[0]
    assert np.linalg.norm(refined.corners_px - view.corners_px, axis=1).max() < 0.3


def test_colour_input_gives_the_grey_result(camera_vga):
    pose = Pose([0.0, 10.0, 450.0], [10.0, 5.0, 20.0])
    grey = render_view(camera_vga, SIDE_MM, pose, noise_sigma=2.0, seed=5)
    colour = render_view(camera_vga, SIDE_MM, pose, noise_sigma=2.0, seed=5, color=True)
    a, b = Detector().detect(grey.image), Detector().detect(colour.image)
    assert len(a) == len(b) == 1
    np.testing.assert_allclose(a[0].corners_px, b[0].corners_px, atol=1e-9)
    bgra = np.dstack([colour.image, np.full(grey.image.shape, 255, np.uint8)])
    np.testing.assert_allclose(Detector().detect(bgra)[0].corners_px, a[0].corners_px, atol=1e-9)


def test_json_dict(camera_vga):
    view = render_view(camera_vga, SIDE_MM, Pose([0.0, 0.0, 400.0], [0.0, 0.0, 0.0]), text="hello")
    (d,) = Detector().detect(view.image)
    data = d.to_json_dict()
    assert data["text"] == "hello"
    assert np.allclose(data["corners"], view.corners_px, atol=0.05)
    assert data["refined"] is True and data["backend"] == "zxing" and len(data["corner_quality_px"]) == 4


@pytest.mark.parametrize(
    "position, angles",
    [
        ([111.4, 4.0, 304.5], [-24.6, -39.4, 21.8]),
        ([135.7, -30.8, 634.1], [30.5, -37.9, 63.9]),
        ([27.8, 70.2, 242.2], [45.2, -7.2, -107.3]),
    ],
)
def test_strong_perspective_is_found_by_the_finder_patterns(camera_vga, position, angles):
    # Tilted about 45 degrees off-centre in a wide view: neither zxing-cpp nor OpenCV reads these.
    view = render_view(camera_vga, SIDE_MM, Pose(position, angles), noise_sigma=2.0, blur_px=0.6, seed=7)
    for backend in ("zxing", "zxing-x2", "opencv", "opencv-aruco"):
        assert Detector(DetectorSettings(backends=backend)).detect(view.image) == []
    (d,) = Detector().detect(view.image)
    assert d.backend == "finders" and d.text == view.text and d.refined
    assert np.abs(d.corners_px - view.corners_px).max() < 0.3


def test_a_backend_corner_far_off_is_reseeded_from_the_finder_patterns(camera_vga):
    # Backends occasionally miss a corner by more than the refinement's search window (seen: 6 px).
    from qrfield.detect.backends import Candidate

    view = render_view(
        camera_vga,
        SIDE_MM,
        Pose([-20.0, 10.0, 350.0], [20.0, 25.0, -40.0]),
        noise_sigma=2.0,
        blur_px=0.6,
        seed=9,
    )
    rough = view.corners_px + np.array([[0.5, -0.5], [6.0, -4.0], [1.0, 1.0], [-0.5, 0.5]])
    detector = Detector()
    d = detector.accept(view.image, Candidate(rough, view.text, "zxing", view.modules))
    assert d is not None and d.refined
    assert np.abs(d.corners_px - view.corners_px).max() < 0.3
