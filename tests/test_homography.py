"""Homographies against OpenCV: cv2.getPerspectiveTransform for the four-point map (in float64 here,
float32 there), cv2.perspectiveTransform for applying one, and hand-checked compositions."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qrfield.homography import (
    Homography,
    apply_floats,
    square_to_quad,
    square_to_quad_floats,
    usable_floats,
)


def _quad(rng: np.random.Generator) -> np.ndarray:
    """A convex-ish quadrilateral V1..V4 (clockwise on screen), pixels."""
    base = np.array([[100.0, 80.0], [420.0, 95.0], [400.0, 390.0], [90.0, 360.0]])
    return base + rng.uniform(-40, 40, (4, 2))


def _opencv(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    return cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32)).astype(np.float64)


@pytest.mark.parametrize("seed", range(5))
def test_four_points_give_opencvs_homography(seed: int) -> None:
    rng = np.random.default_rng(seed)
    src, dst = _quad(rng), _quad(rng)
    h = Homography.from_points(src, dst)
    expected = _opencv(src, dst)
    # OpenCV solves in float32: agree to its precision on the mapped points, not the entries.
    pts = rng.uniform(50, 450, (30, 2))
    ocv = cv2.perspectiveTransform(pts.reshape(1, -1, 2), expected).reshape(-1, 2)
    np.testing.assert_allclose(h.apply(pts), ocv, atol=2e-3)
    np.testing.assert_allclose(h.apply(src), dst, atol=1e-9)


@pytest.mark.parametrize("n", [1.0, 21.0, 37.0])
def test_the_closed_form_square_map_equals_the_general_one(n: float) -> None:
    rng = np.random.default_rng(int(n))
    quad = _quad(rng)
    square = np.array([[0.0, 0.0], [n, 0.0], [n, n], [0.0, n]])
    closed = square_to_quad(quad[:, 0], quad[:, 1], n)
    general = Homography.from_points(square, quad).matrix
    np.testing.assert_allclose(closed, general, rtol=1e-9, atol=1e-9)
    floats = square_to_quad_floats(n, quad.tolist())
    np.testing.assert_allclose(np.array(floats).reshape(3, 3), closed, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Homography.square(n, quad).square_corners(n), quad, atol=1e-9)


def test_a_batch_of_squares_keeps_its_rows_and_marks_degenerate_ones() -> None:
    rng = np.random.default_rng(3)
    quads = np.stack([_quad(rng) for _ in range(6)])
    quads[2] = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]  # all on one line
    h = square_to_quad(quads[..., 0], quads[..., 1])
    assert h.shape == (6, 3, 3)
    assert not np.all(np.isfinite(h[2]))
    for i in (0, 1, 3, 4, 5):
        np.testing.assert_allclose(Homography(h[i]).square_corners(1.0), quads[i], atol=1e-9)
    assert square_to_quad_floats(1.0, quads[2].tolist()) is None


def test_a_parallelogram_is_an_affine_map() -> None:
    quad = [[10.0, 20.0], [110.0, 30.0], [130.0, 130.0], [30.0, 120.0]]
    h = square_to_quad_floats(10.0, quad)
    assert h[6] == 0.0 and h[7] == 0.0
    assert apply_floats(h, 10.0, 10.0) == pytest.approx((130.0, 130.0))


def test_apply_in_floats_and_arrays_agree_with_opencv() -> None:
    rng = np.random.default_rng(8)
    h = Homography.from_points(_quad(rng), _quad(rng))
    pts = rng.uniform(0, 500, (20, 2))
    ocv = cv2.perspectiveTransform(pts.reshape(1, -1, 2), h.matrix).reshape(-1, 2)
    np.testing.assert_allclose(h.apply(pts), ocv, atol=1e-9)
    np.testing.assert_allclose([apply_floats(h.floats(), x, y) for x, y in pts], ocv, atol=1e-9)
    assert h.apply(pts.reshape(4, 5, 2)).shape == (4, 5, 2)


def test_compose_and_inverse() -> None:
    rng = np.random.default_rng(9)
    a = Homography.from_points(_quad(rng), _quad(rng))
    b = Homography.from_points(_quad(rng), _quad(rng))
    pts = rng.uniform(50, 450, (10, 2))
    np.testing.assert_allclose(b.compose(a).apply(pts), b.apply(a.apply(pts)), rtol=1e-9)
    np.testing.assert_allclose(a.inverse().apply(a.apply(pts)), pts, atol=1e-7)
    assert usable_floats(a.floats())
    assert not usable_floats([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])  # rank 2


def test_bad_shapes_and_degenerate_points_are_named() -> None:
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        Homography(np.eye(2))
    with pytest.raises(ValueError, match="collinear"):
        Homography.from_points(np.array([[0, 0], [1, 1], [2, 2], [3, 3.0]]), np.eye(4, 2))
    with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
        square_to_quad(np.zeros(3), np.zeros(3))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-30, 30, allow_nan=False), min_size=8, max_size=8))
def test_the_square_map_hits_its_four_corners(offsets: list[float]) -> None:
    quad = np.array([[100.0, 100.0], [300.0, 100.0], [300.0, 300.0], [100.0, 300.0]])
    quad = quad + np.array(offsets).reshape(4, 2)
    h = square_to_quad_floats(25.0, quad.tolist())
    assert h is not None
    for (u, v), corner in zip(((0, 0), (25, 0), (25, 25), (0, 25)), quad, strict=True):
        assert apply_floats(h, u, v) == pytest.approx(tuple(corner), abs=1e-8)
