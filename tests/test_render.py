"""The virtual bench renderer against independent truth: edge positions measured in the image,
OpenCV's and zxing-cpp's detectors, and the decoded text."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, project_points
from qrfield.render import RenderError, qr_symbol, render_view
from qrfield.sampling import random_visible_poses


def _crossings(image, camera, pose, side, modules):
    """Signed offsets (px) of the measured 50 % grey crossing from the projected outer symbol edge,
    sampled along the finder patterns' outer edges (dark inside, white quiet zone outside)."""
    r, t = pose.rotation, pose.position_mm
    h, m = side / 2, side / modules
    img = image.astype(np.float32)
    offsets = []
    steps = np.linspace(-3, 3, 61)
    for edge in range(4):
        for s in [*np.linspace(0.5, 6.5, 7), *np.linspace(modules - 6.5, modules - 0.5, 7)]:
            if (edge == 1 and s > 7) or (edge == 2 and s < modules - 7):
                continue  # the corner V3 has no finder pattern
            a = -h + s * m
            q, out = [
                (np.array([a, -h, 0]), np.array([0, -1, 0])),
                (np.array([h, a, 0]), np.array([1, 0, 0])),
                (np.array([-a, h, 0]), np.array([0, 1, 0])),
                (np.array([-h, -a, 0]), np.array([-1, 0, 0])),
            ][edge]
            p0 = project_points(r @ q + t, camera)
            d = project_points(r @ (q + out * m / 2) + t, camera) - p0
            d /= np.linalg.norm(d)
            line = p0[None, :] + steps[:, None] * d[None, :]
            prof = cv2.remap(
                img,
                line[:, 0].astype(np.float32)[None],
                line[:, 1].astype(np.float32)[None],
                cv2.INTER_LINEAR,
            ).ravel()
            k = np.nonzero((prof[:-1] < 127.5) & (prof[1:] >= 127.5))[0]
            assert len(k) == 1, "one dark-to-white transition expected across the symbol's outer edge"
            k = k[0]
            offsets.append(steps[k] + (127.5 - prof[k]) / (prof[k + 1] - prof[k]) * (steps[1] - steps[0]))
    return np.array(offsets)


@pytest.mark.slow
@pytest.mark.parametrize(
    "camera",
    [
        CameraModel.from_focal(529.6, 640, 480),
        CameraModel(
            fx=560, fy=555, cx=322, cy=236, width=640, height=480, dist=[-0.25, 0.08, 0.001, -0.001, 0.0]
        ),
    ],
    ids=["pinhole", "distorted"],
)
def test_edges_in_the_image_lie_on_the_projected_symbol_outline(camera):
    # The 50 % crossing of the anti-aliased edge is where the true edge is: measured in the image
    # itself, independent of how the renderer warps. A half-pixel convention error would show a
    # 0.5 px bias, a scale error a growing one.
    side = 80.0
    modules = qr_symbol("qrfield").shape[0]
    poses = random_visible_poses(camera, side, 12, seed=3, max_tilt_deg=50)
    for pose in poses:
        view = render_view(camera, side, pose)
        offsets = _crossings(view.image, camera, pose, side, modules)
        assert abs(offsets.mean()) < 0.03, offsets.mean()
        assert np.abs(offsets).max() < 0.2, np.abs(offsets).max()


@pytest.mark.slow
def test_opencv_and_zxing_read_rendered_codes_at_their_corners():
    # 50 seeded poses: z 150-800 mm, tilt up to 50 degrees from the line of sight, 640x480.
    # OpenCV 5.0's plain QRCodeDetector is itself only good to about a pixel (measured here:
    # median 0.4 px, 84 % of corners within 1.5 px, single corners up to 23 px off), so its answer
    # bounds the renderer loosely; the edge test above bounds it tightly.
    zxingcpp = pytest.importorskip("zxingcpp")
    camera = CameraModel.from_focal(529.6, 640, 480)
    poses = random_visible_poses(camera, 100.0, 50, seed=7, max_tilt_deg=50, tilt_from="line_of_sight")
    detector = cv2.QRCodeDetector()
    found, errors, decoded = 0, [], 0
    for i, pose in enumerate(poses):
        view = render_view(camera, 100.0, pose, text="qrfield-bench", seed=i)
        ok, points = detector.detect(view.image)
        if ok:
            found += 1
            errors.extend(np.linalg.norm(points.reshape(4, 2) - view.corners_px, axis=1))
        for result in zxingcpp.read_barcodes(view.image):
            assert result.text == "qrfield-bench"
            decoded += 1
    errors = np.array(errors)
    assert found >= 48, f"OpenCV found {found} of 50"
    assert decoded >= 44, f"zxing-cpp decoded {decoded} of 50"
    assert np.median(errors) < 0.8
    assert np.mean(errors <= 1.5) >= 0.8


def test_noise_blur_gradient_and_colour():
    camera = CameraModel.from_focal(529.6, 640, 480)
    pose = Pose([0, 0, 300], [10, -15, 20])
    clean = render_view(camera, 50, pose)
    noisy = render_view(camera, 50, pose, noise_sigma=4.0, seed=1)
    residual = noisy.image.astype(float) - clean.image.astype(float)
    flat = (clean.image > 20) & (clean.image < 235)  # away from clipping
    assert np.std(residual[flat]) == pytest.approx(4.0, rel=0.1)
    again = render_view(camera, 50, pose, noise_sigma=4.0, seed=1)
    np.testing.assert_array_equal(noisy.image, again.image)  # seeded
    blurred = render_view(camera, 50, pose, blur_px=2.0)
    assert (
        np.abs(np.diff(blurred.image.astype(float), axis=1)).max()
        < np.abs(np.diff(clean.image.astype(float), axis=1)).max()
    )
    lit = render_view(camera, 50, pose, gradient=0.3)
    assert lit.image[5, 600] > clean.image[5, 600] > lit.image[5, 20]
    colour = render_view(camera, 50, pose, color=True)
    assert colour.image.shape == (480, 640, 3)


def test_card_out_of_view_or_facing_away_is_a_clear_error():
    camera = CameraModel.from_focal(529.6, 640, 480)
    with pytest.raises(RenderError, match="out of view"):
        render_view(camera, 50, Pose([400, 0, 300], [0, 0, 0]))
    with pytest.raises(RenderError, match="faces away"):
        render_view(camera, 50, Pose([0, 0, 300], [0, 150, 0]))
    with pytest.raises(RenderError, match="behind the camera"):
        render_view(camera, 50, Pose([0, 0, -300], [0, 0, 0]))
    cut = render_view(camera, 50, Pose([170, 0, 300], [0, 0, 0]), allow_partial=True)
    assert cut.corners_px[:, 0].max() > 639


def test_qr_symbol_is_a_valid_code():
    symbol = qr_symbol("hello")
    assert symbol.shape == (21, 21)
    # Finder patterns: 7x7 dark ring at three corners, light at the fourth.
    assert symbol[0, :7].all() and symbol[:7, 0].all() and symbol[0, -7:].all() and symbol[-7:, 0].all()
    assert not symbol[-1, -1] or not symbol[-7:, -7:].all()


@pytest.mark.slow
@pytest.mark.parametrize("k1", [-0.25, 0.3], ids=["barrel", "pincushion"])
def test_background_image_through_a_lens_is_not_distorted_again(k1):
    # A background image is a camera image: only the new card passes through the lens model.
    camera = CameraModel(fx=560, fy=556, cx=321, cy=238, width=640, height=480, dist=[k1, 0.05, 0, 0, 0])
    far = render_view(camera, 60.0, Pose([-90.0, 0.0, 500.0], [0.0, 10.0, 5.0]), text="alpha")
    near = render_view(camera, 60.0, Pose([60.0, 10.0, 330.0], [-10.0, 0.0, -20.0]), text="bravo",
                       background=far.image)  # fmt: skip
    alone = render_view(camera, 60.0, near.pose, text="bravo")

    def box(corners, grow):
        (u0, v0), (u1, v1) = (
            np.floor(corners.min(0) - grow).astype(int),
            np.ceil(corners.max(0) + grow).astype(int),
        )
        return slice(v0, v1), slice(u0, u1)

    behind = box(far.corners_px, 10)  # the far code and its quiet zone, clear of the near card
    assert np.abs(near.image[behind].astype(int) - far.image[behind]).max() <= 1
    card = box(near.corners_px, -2)  # inside the near symbol: the card covers the background
    assert np.abs(near.image[card].astype(int) - alone.image[card]).max() <= 1
