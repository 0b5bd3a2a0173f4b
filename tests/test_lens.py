"""The lens model against OpenCV: cv2.projectPoints for the forward model, finite differences for its
Jacobian, and a round trip through OpenCV's own projection for the undistortion."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from qrfield.camera import CameraModel
from qrfield.lens import (
    distort_normalised,
    distortion_jacobian_terms,
    has_distortion,
    undistort_points,
)

LENSES = {
    "barrel": (-0.28, 0.09, 0.0006, -0.0004, -0.012),
    "pincushion": (0.12, -0.03, -0.001, 0.0008, 0.004),
    "tangential only": (0.0, 0.0, 0.002, -0.0015, 0.0),
}


def _camera(dist) -> CameraModel:
    return CameraModel(fx=610.0, fy=605.0, cx=318.7, cy=242.1, width=640, height=480, dist=np.array(dist))


@pytest.mark.parametrize("name", sorted(LENSES))
def test_the_forward_model_is_opencvs(name: str) -> None:
    camera = _camera(LENSES[name])
    rng = np.random.default_rng(7)
    x, y = rng.uniform(-0.5, 0.5, 200), rng.uniform(-0.4, 0.4, 200)
    expected, _ = cv2.projectPoints(
        np.column_stack([x, y, np.ones_like(x)]), np.zeros(3), np.zeros(3), camera.K, camera.dist
    )
    xd, yd = distort_normalised(camera.dist, x, y)
    got = np.column_stack([camera.fx * xd + camera.cx, camera.fy * yd + camera.cy])
    np.testing.assert_allclose(got, expected.reshape(-1, 2), atol=1e-9)


def test_floats_and_arrays_give_the_same_numbers() -> None:
    dist = LENSES["barrel"]
    xs, ys = np.array([0.31, -0.2]), np.array([-0.12, 0.27])
    xd, yd = distort_normalised(dist, xs, ys)
    for i in range(2):
        assert distort_normalised(list(dist), float(xs[i]), float(ys[i])) == (xd[i], yd[i])


@pytest.mark.parametrize("name", sorted(LENSES))
def test_the_jacobian_is_the_derivative_of_the_model(name: str) -> None:
    dist = LENSES[name]
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.4, 0.4, 50)
    h = 1e-6
    dxd_dx, dyd_dx = (
        np.subtract(*pair) / (2 * h)
        for pair in zip(distort_normalised(dist, x + h, y), distort_normalised(dist, x - h, y), strict=True)
    )
    dxd_dy, dyd_dy = (
        np.subtract(*pair) / (2 * h)
        for pair in zip(distort_normalised(dist, x, y + h), distort_normalised(dist, x, y - h), strict=True)
    )
    d00, d01, d11 = distortion_jacobian_terms(dist, x, y)
    np.testing.assert_allclose(d00, dxd_dx, atol=1e-7)
    np.testing.assert_allclose(d01, dxd_dy, atol=1e-7)
    np.testing.assert_allclose(d01, dyd_dx, atol=1e-7)  # the matrix is symmetric for this model
    np.testing.assert_allclose(d11, dyd_dy, atol=1e-7)


@pytest.mark.parametrize("name", sorted(LENSES))
def test_undistortion_inverts_opencvs_projection(name: str) -> None:
    camera = _camera(LENSES[name])
    rng = np.random.default_rng(11)
    rays = np.column_stack([rng.uniform(-0.45, 0.45, 300), rng.uniform(-0.35, 0.35, 300), np.ones(300)])
    pixels, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), camera.K, camera.dist)
    pixels = pixels.reshape(-1, 2)
    normalised = undistort_points(pixels, camera.K, camera.dist)
    assert normalised.shape == (300, 2)
    np.testing.assert_allclose(normalised, rays[:, :2], atol=1e-10)
    ideal = undistort_points(pixels.reshape(-1, 1, 2), camera.K, camera.dist, pixels=True)
    assert ideal.shape == (300, 1, 2)
    expected = rays[:, :2] * [camera.fx, camera.fy] + [camera.cx, camera.cy]
    np.testing.assert_allclose(ideal.reshape(-1, 2), expected, atol=1e-7)


def test_undistortion_names_a_wrong_shape() -> None:
    camera = _camera(LENSES["barrel"])
    with pytest.raises(ValueError, match=r"\(\.\.\., 2\)"):
        undistort_points(np.zeros((4, 3)), camera.K, camera.dist)


def test_has_distortion() -> None:
    assert not has_distortion(_camera((0.0, 0.0, 0.0, 0.0, 0.0)))
    assert has_distortion(_camera((0.0, 0.0, 0.0, 0.0, 1e-9)))
    assert _camera(LENSES["barrel"]).has_distortion
