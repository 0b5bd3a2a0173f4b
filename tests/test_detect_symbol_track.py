"""The warm fit's float helpers (qrfield.detect.symbol_track) against OpenCV and brute force."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from qrfield.detect.symbol_track import _maps_inside, _shifted
from qrfield.homography import square_to_quad_floats


def _random_quad(rng: np.random.Generator) -> np.ndarray:
    """A convex, clockwise-in-the-image quad (V1..V4) of 40-300 px in a 640x480 frame, in perspective."""
    centre = rng.uniform([150, 120], [490, 360])
    size = rng.uniform(40, 300)
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64) * size / 2
    angle = rng.uniform(-np.pi, np.pi)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    quad = square @ rot.T + centre
    return quad + rng.normal(0, size * 0.08, (4, 2))  # a perspective-like distortion of the square


@pytest.mark.parametrize("n", [21, 25, 57])
def test_the_closed_form_homography_is_opencvs(n: int) -> None:
    rng = np.random.default_rng(n)
    square = np.array([[0, 0], [n, 0], [n, n], [0, n]], dtype=np.float64)
    for _ in range(200):
        quad = _random_quad(rng)
        h = np.array(square_to_quad_floats(float(n), quad.tolist())).reshape(3, 3)
        # The homography through four points is unique: it maps them exactly, and the square's
        # centre to where the quad's diagonals cross (lines stay lines).
        mapped = cv2.perspectiveTransform(square.reshape(1, 4, 2), h).reshape(4, 2)
        np.testing.assert_allclose(mapped, quad, atol=1e-9)
        centre = cv2.perspectiveTransform(np.full((1, 1, 2), n / 2.0), h).reshape(2)
        d1, d2 = quad[2] - quad[0], quad[3] - quad[1]
        s, _ = np.linalg.solve(np.column_stack([d1, -d2]), quad[1] - quad[0])
        np.testing.assert_allclose(centre, quad[0] + s * d1, atol=1e-9)
        reference = cv2.getPerspectiveTransform(square.astype(np.float32), quad.astype(np.float32))
        np.testing.assert_allclose(h, reference, rtol=1e-4, atol=1e-4)  # float32 corners there


def test_a_parallelogram_is_affine_and_collinear_points_have_none() -> None:
    quad = [[10.0, 20.0], [110.0, 30.0], [120.0, 130.0], [20.0, 120.0]]
    h = square_to_quad_floats(25.0, quad)
    assert h is not None and h[6] == 0.0 and h[7] == 0.0
    np.testing.assert_allclose(h[:6], [4.0, 0.4, 10.0, 0.4, 4.0, 20.0])
    assert square_to_quad_floats(25.0, [[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [30.0, 0.0]]) is None


def test_the_shift_moves_the_mapped_pixels_into_the_crop() -> None:
    rng = np.random.default_rng(3)
    quad = _random_quad(rng)
    h = square_to_quad_floats(25.0, quad.tolist())
    assert h is not None
    uv = rng.uniform(-4, 29, (1, 50, 2))
    full = cv2.perspectiveTransform(uv, np.array(h).reshape(3, 3))
    crop = cv2.perspectiveTransform(uv, np.array(_shifted(h, 37.0, 81.0)).reshape(3, 3))
    np.testing.assert_allclose(crop, full - [37.0, 81.0], atol=1e-9)


def test_the_box_test_agrees_with_every_point_inside() -> None:
    """When the box test says inside, every point of the box maps inside (checked on a dense grid);
    a box whose points leave the region is never called inside."""
    rng = np.random.default_rng(7)
    grid = np.stack(np.meshgrid(np.linspace(-4, 29, 34), np.linspace(-4, 29, 34)), axis=-1).reshape(1, -1, 2)
    said_inside = said_outside = 0
    for _ in range(400):
        quad = _random_quad(rng)
        h = square_to_quad_floats(25.0, quad.tolist())
        assert h is not None
        width, height = rng.uniform(150, 640), rng.uniform(150, 480)
        shifted = _shifted(h, *rng.uniform(0, 200, 2))
        px = cv2.perspectiveTransform(grid, np.array(shifted).reshape(3, 3)).reshape(-1, 2)
        every = bool(((px >= 0) & (px <= (width, height))).all())
        if _maps_inside(shifted, (-4.0, -4.0, 29.0, 29.0), width, height):
            said_inside += 1
            assert every
        else:
            said_outside += 1
            corners_in = cv2.perspectiveTransform(
                np.array([[[-4.0, -4.0], [29.0, -4.0], [29.0, 29.0], [-4.0, 29.0]]]),
                np.array(shifted).reshape(3, 3),
            ).reshape(-1, 2)
            assert not ((corners_in >= 0) & (corners_in <= (width, height))).all()
    assert said_inside > 30 and said_outside > 30  # both branches were exercised
