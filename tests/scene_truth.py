"""The scenes of the detection and hand-eye tests: QR cards at chosen poses, drawn by the hard set's
rasteriser (:func:`qrfield.testing.hardset.rasterise`, not qrfield.render's warped texture).

Each card is a segno symbol (not OpenCV's encoder) with a quiet zone and a white margin, every pixel
the area average of the card over it (point samples through OpenCV's undistortion onto the card
plane, looked up in the module matrix). The truth is cv2.projectPoints of the vertices
(:func:`qrfield.testing.hardset.true_corners`; docs/conventions.md: V1 the outer corner of the
top-left finder pattern, then clockwise; marker X from V1 to V2, Y from V1 to V4). Several cards
can share one frame (they must not overlap); the frame is then blurred (Gaussian) and noised.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, angles_from_rotation, shortest_module_px
from qrfield.testing.hardset import rasterise, true_corners

#: The payload of the hand-eye tests' card (tests/test_handeye_robot.py, tests/test_handeye_cli.py).
HANDEYE_TEXT = "qrfield hand-eye 28"


@dataclass(frozen=True)
class Card:
    """One card to draw: its payload, symbol side L (mm) and pose (marker to camera)."""

    text: str
    side_mm: float
    pose: Pose
    error: str = "M"


@dataclass(frozen=True)
class Drawn:
    """A drawn frame: the (H, W) uint8 image and, per card, its true corners V1..V4 (4, 2) px,
    modules per side and smallest module side (px: the shortest side of V1..V4 over the modules)."""

    image: np.ndarray
    corners: tuple[np.ndarray, ...]
    modules: tuple[int, ...]
    module_px: tuple[float, ...]


def symbol(text: str, error: str = "M") -> np.ndarray:
    """(n, n) bool module matrix (True = dark) of ``text`` by segno (QR, not micro)."""
    import segno

    return np.array(segno.make(text, error=error, micro=False).matrix, dtype=bool)


def draw(
    camera: CameraModel,
    cards: list[Card],
    *,
    background: float = 110.0,
    light: float = 215.0,
    dark: float = 35.0,
    blur_px: float = 0.6,
    noise: float = 2.0,
    seed: int = 0,
) -> Drawn:
    """Draw ``cards`` (not overlapping) into one frame of ``camera``'s size, blur (sigma px) and
    noise (sigma, grey levels) it; the truth of each card."""
    h, w = camera.height, camera.width
    image = np.full((h, w), float(background))
    corners, modules, module_px = [], [], []
    for card in cards:
        matrix = symbol(card.text, card.error)
        drawn = rasterise(camera, card.pose, card.side_mm, matrix, background, light, dark)
        here = drawn != background
        if not here.any():
            raise ValueError(f"the card {card.text!r} is out of view")
        image[here] = drawn[here]
        true = true_corners(camera, card.pose, card.side_mm)
        n = matrix.shape[0]
        corners.append(true)
        modules.append(n)
        module_px.append(shortest_module_px(true, n))
    if blur_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), sigmaX=blur_px, borderType=cv2.BORDER_REPLICATE)
    rng = np.random.default_rng(seed)
    image = np.clip(np.round(image + rng.normal(0.0, noise, image.shape)), 0, 255).astype(np.uint8)
    return Drawn(image, tuple(corners), tuple(modules), tuple(module_px))


def draw_card(
    camera: CameraModel, pose: Pose, side_mm: float, text: str = HANDEYE_TEXT, **kwargs
) -> np.ndarray:
    """(H, W) uint8: the one card of ``text`` (error level M) at ``pose`` (marker to camera, mm,
    degrees) seen by ``camera``; ``kwargs`` as :func:`draw`'s."""
    return draw(camera, [Card(text, side_mm, pose)], **kwargs).image


def facing(position_mm, tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0, turn_deg: float = 0.0) -> Pose:
    """A pose at ``position_mm`` whose card faces the camera's line of sight to it, then is tilted
    about its own X and Y and turned about its normal (degrees)."""
    from qrfield.geometry import rotation_matrix
    from qrfield.sampling import _align_z

    p = np.asarray(position_mm, dtype=np.float64)
    rotation = _align_z(p) @ rotation_matrix([tilt_x_deg, tilt_y_deg, turn_deg])
    return Pose(p, angles_from_rotation(rotation))
