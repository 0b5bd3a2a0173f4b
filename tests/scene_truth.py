"""An independent renderer for the detection tests: QR cards drawn by ray casting on a regular grid.

Neither qrfield.render (a warped texture, area-averaged) nor the hard benchmark set's rasteriser
(a Fibonacci lattice of point samples): a pixel that an edge crosses is the mean of
``supersample`` x ``supersample`` stratified random sub-pixel points, each taken back through
OpenCV's undistortion (cv2.undistortPoints, at the pixel corners) and the pose onto the card
plane and looked up in a segno module matrix; any other pixel is the grey its corners see.
The truth is cv2.projectPoints of the vertices (docs/conventions.md: V1 the outer corner of the
top-left finder pattern, then clockwise; marker X from V1 to V2, Y from V1 to V4). Several cards
can share one frame (they must not overlap); the frame is then blurred (Gaussian) and noised.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, angles_from_rotation, marker_vertices

#: Quiet zone and white card margin around each symbol, modules.
QUIET_MODULES = 4
MARGIN_MODULES = 2


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


def truth(camera: CameraModel, pose: Pose, side_mm: float) -> np.ndarray:
    """(4, 2) pixels of V1..V4 by cv2.projectPoints, distortion included."""
    rvec = cv2.Rodrigues(np.asarray(pose.rotation, dtype=np.float64))[0]
    pts, _ = cv2.projectPoints(
        marker_vertices(side_mm), rvec, np.asarray(pose.position_mm), camera.K, camera.dist
    )
    return pts.reshape(4, 2)


def _card_grey(camera: CameraModel, card: Card, shape: tuple[int, int], levels, supersample: int):
    """(the card's grey levels over its bounding box (y0, x0, block), or None when out of view)."""
    matrix = symbol(card.text, card.error)
    n = matrix.shape[0]
    pitch = card.side_mm / n
    pad = QUIET_MODULES + MARGIN_MODULES
    rotation = np.asarray(card.pose.rotation, dtype=np.float64)
    t = np.asarray(card.pose.position_mm, dtype=np.float64)
    half = card.side_mm / 2 + pad * pitch
    outline = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])
    rvec = cv2.Rodrigues(rotation)[0]
    box, _ = cv2.projectPoints(outline, rvec, t, camera.K, camera.dist)
    box = box.reshape(4, 2)
    h, w = shape
    x0, y0 = max(int(np.floor(box[:, 0].min())) - 3, 0), max(int(np.floor(box[:, 1].min())) - 3, 0)
    x1, y1 = min(int(np.ceil(box[:, 0].max())) + 4, w), min(int(np.ceil(box[:, 1].max())) + 4, h)
    if x1 <= x0 or y1 <= y0:
        return None
    # The lens is undistorted at the pixel corners, the rays bilinear within a pixel (the lens is
    # smooth: within 1e-5 px at these scales). Pixel centres at integers (OpenCV's convention).
    cy, cx = np.mgrid[y0 : y1 + 1, x0 : x1 + 1]
    corner_px = np.column_stack([cx.ravel() - 0.5, cy.ravel() - 0.5]).reshape(-1, 1, 2).astype(np.float64)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    if hasattr(cv2, "undistortPointsIter"):
        corner_rays = cv2.undistortPointsIter(corner_px, camera.K, camera.dist, None, None, criteria)
    else:
        corner_rays = cv2.undistortPoints(corner_px, camera.K, camera.dist, R=None, P=None, criteria=criteria)
    corner_rays = corner_rays.reshape(y1 - y0 + 1, x1 - x0 + 1, 2)
    to_plane = np.linalg.inv(np.column_stack([rotation[:, 0], rotation[:, 1], t]))
    background, light, dark = levels
    rng = np.random.default_rng(12345)

    def grey_at(rays: np.ndarray) -> np.ndarray:
        """Grey levels of the scene along normalised rays (..., 2): on the card plane z_marker = 0
        (camera point R (x, y, 0) + t on the ray (rx, ry, 1) s), dark modules, card, background."""
        flat = rays.reshape(-1, 2)
        plane = np.column_stack([flat, np.ones(len(flat))]) @ to_plane.T
        u = plane[:, 0] / plane[:, 2] / pitch + n / 2.0
        v = plane[:, 1] / plane[:, 2] / pitch + n / 2.0
        cu, cv = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        on_symbol = (cu >= 0) & (cu < n) & (cv >= 0) & (cv < n)
        on_card = (u >= -pad) & (u < n + pad) & (v >= -pad) & (v < n + pad) & (plane[:, 2] > 0)
        grey = np.full(len(u), float(background))
        grey[on_card] = light
        dark_here = np.zeros(len(u), dtype=bool)
        dark_here[on_symbol] = matrix[cv[on_symbol], cu[on_symbol]]
        grey[dark_here] = dark
        return grey.reshape(rays.shape[:-1])

    # A pixel whose four corners see one grey lies wholly in one cell (modules of 1 px or more: a
    # cell's corner inside the pixel puts the cell over one of its corners); the others get
    # ``supersample`` x ``supersample`` stratified random points, one in each cell of the pixel
    # (an unbiased estimate of the area average, where a plain grid quantises an edge along a
    # pixel axis to 1 / supersample px).
    at_corners = grey_at(corner_rays)
    block = at_corners[:-1, :-1].copy()
    mixed = (
        (at_corners[:-1, :-1] != at_corners[:-1, 1:])
        | (at_corners[:-1, :-1] != at_corners[1:, :-1])
        | (at_corners[:-1, :-1] != at_corners[1:, 1:])
    )
    rows, cols = np.nonzero(mixed)
    cells = np.arange(supersample, dtype=np.float64)
    fx = ((cells[None, None, :] + rng.random((len(rows), supersample, supersample))) / supersample)[..., None]
    fy = ((cells[None, :, None] + rng.random((len(rows), supersample, supersample))) / supersample)[..., None]
    r00, r10 = corner_rays[rows, cols][:, None, None], corner_rays[rows, cols + 1][:, None, None]
    r01, r11 = corner_rays[rows + 1, cols][:, None, None], corner_rays[rows + 1, cols + 1][:, None, None]
    rays = r00 * (1 - fx) * (1 - fy) + r10 * fx * (1 - fy) + r01 * (1 - fx) * fy + r11 * fx * fy
    block[rows, cols] = grey_at(rays).reshape(len(rows), -1).mean(axis=1)
    return y0, x0, block, n


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
    supersample: int = 16,
) -> Drawn:
    """Draw ``cards`` (not overlapping) into one frame of ``camera``'s size, blur (sigma px) and
    noise (sigma, grey levels) it; the truth of each card."""
    h, w = camera.height, camera.width
    image = np.full((h, w), float(background))
    corners, modules, module_px = [], [], []
    for card in cards:
        drawn = _card_grey(camera, card, (h, w), (background, light, dark), supersample)
        if drawn is None:
            raise ValueError(f"the card {card.text!r} is out of view")
        y0, x0, block, n = drawn
        region = image[y0 : y0 + block.shape[0], x0 : x0 + block.shape[1]]
        here = block != background
        region[here] = block[here]
        true = truth(camera, card.pose, card.side_mm)
        corners.append(true)
        modules.append(n)
        sides = np.linalg.norm(np.roll(true, -1, axis=0) - true, axis=1)
        module_px.append(float(sides.min()) / n)
    if blur_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), sigmaX=blur_px, borderType=cv2.BORDER_REPLICATE)
    rng = np.random.default_rng(seed)
    image = np.clip(np.round(image + rng.normal(0.0, noise, image.shape)), 0, 255).astype(np.uint8)
    return Drawn(image, tuple(corners), tuple(modules), tuple(module_px))


def facing(position_mm, tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0, turn_deg: float = 0.0) -> Pose:
    """A pose at ``position_mm`` whose card faces the camera's line of sight to it, then is tilted
    about its own X and Y and turned about its normal (degrees)."""
    from qrfield.geometry import rotation_matrix
    from qrfield.sampling import _align_z

    p = np.asarray(position_mm, dtype=np.float64)
    rotation = _align_z(p) @ rotation_matrix([tilt_x_deg, tilt_y_deg, turn_deg])
    return Pose(p, angles_from_rotation(rotation))
