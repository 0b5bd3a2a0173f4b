"""Chessboard calibration targets: the board's description, and rendered views of it at a known pose.

A board is named ``COLSxROWS`` counting *inner* corners (OpenCV's pattern size): a 4x6 board has
5 x 7 squares. Its corners, in the order OpenCV's detectors return them (row by row, COLS per row),
sit on the board plane at (i * S, j * S, 0) mm for column i and row j, S the square side.

The renderer is the simulated twin of a person holding a printed board in front of the camera:
it draws the board at a :class:`~qrfield.geometry.Pose` through a :class:`~qrfield.camera.CameraModel`
(distortion included) and returns the exact corner pixels, the truth calibration is tested against.
Board frame for rendering (as the marker frame of docs/conventions.md): origin at the centre of
the inner-corner grid, +X along a row (towards higher columns), +Y down the rows, +Z = X x Y (into the board).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, project_points, transform_points

#: OpenCV's detectors need at least 3 inner corners along each side.
MIN_CORNERS_PER_SIDE = 3
#: White border around the outer squares of a rendered board, in squares.
BORDER_SQUARES = 1.0


@dataclass(frozen=True)
class Board:
    """A chessboard target.

    Attributes:
        cols: inner corners per row (OpenCV pattern width).
        rows: inner corners per column (OpenCV pattern height).
        square_mm: side of one square, mm (> 0).
    """

    cols: int
    rows: int
    square_mm: float = 1.0

    def __post_init__(self) -> None:
        for name in ("cols", "rows"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, np.integer))
                or value < MIN_CORNERS_PER_SIDE
            ):
                raise ValueError(
                    f"board {name} must be a whole number of inner corners "
                    f">= {MIN_CORNERS_PER_SIDE}, got {value!r}"
                )
        if isinstance(self.square_mm, bool) or not math.isfinite(self.square_mm) or self.square_mm <= 0:
            raise ValueError(f"board square side must be a positive length in mm, got {self.square_mm!r}")
        object.__setattr__(self, "cols", int(self.cols))
        object.__setattr__(self, "rows", int(self.rows))
        object.__setattr__(self, "square_mm", float(self.square_mm))

    @classmethod
    def parse(cls, text: str, square_mm: float = 1.0) -> Board:
        """``COLSxROWS`` (inner corners, e.g. ``9x6``) and a square side in mm; ValueError if malformed."""
        parts = str(text).strip().lower().split("x")
        if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
            raise ValueError(
                f"board {text!r} is not of the form COLSxROWS counting inner corners, e.g. 9x6 "
                "(a board of 10 x 7 squares)"
            )
        return cls(int(parts[0]), int(parts[1]), square_mm)

    @property
    def pattern_size(self) -> tuple[int, int]:
        """(cols, rows): OpenCV's ``patternSize``."""
        return (self.cols, self.rows)

    @property
    def corner_count(self) -> int:
        return self.cols * self.rows

    @property
    def label(self) -> str:
        """``COLSxROWS`` as given on the command line."""
        return f"{self.cols}x{self.rows}"

    def object_points(self) -> np.ndarray:
        """(cols*rows, 3) float32 corner positions on the board plane, mm, OpenCV's order.

        Corner k = j * cols + i (row j, column i) is at (i * S, j * S, 0).
        """
        grid = np.mgrid[0 : self.cols, 0 : self.rows].T.reshape(-1, 2)
        points = np.zeros((self.corner_count, 3), np.float32)
        points[:, :2] = grid * self.square_mm
        return points

    def centred_points(self) -> np.ndarray:
        """(cols*rows, 3) corners in the rendering frame (origin at the grid's centre), mm, float64."""
        points = self.object_points().astype(np.float64)
        points[:, 0] -= (self.cols - 1) * self.square_mm / 2.0
        points[:, 1] -= (self.rows - 1) * self.square_mm / 2.0
        return points


@dataclass(frozen=True)
class ChessboardView:
    """A rendered view of a board and its truth.

    Attributes:
        image: (H, W) uint8 grey image.
        corners_px: (cols*rows, 2) exact pixels of the inner corners, OpenCV's order
            (row by row from the board's -X,-Y corner), distortion included.
        pose: board-to-camera pose (mm, degrees), board frame as in the module docstring.
    """

    image: np.ndarray
    corners_px: np.ndarray
    pose: Pose
    camera: CameraModel
    board: Board


def render_chessboard(
    camera: CameraModel,
    board: Board,
    pose: Pose,
    *,
    background: int = 110,
    supersample: int = 4,
    noise_sigma: float = 0.0,
    seed: int | None = None,
) -> ChessboardView:
    """Render ``board`` (with a white border of one square) at ``pose`` through ``camera``.

    Each camera pixel averages ``supersample``^2 point samples of the ideal pinhole picture, each
    traced to the board plane and coloured by its square (top-left square dark); with lens distortion
    the ideal picture is remapped through the exact undistortion of every pixel, as in
    :func:`qrfield.render.render_view`.

    Raises:
        ValueError: a corner is behind the camera or outside the image, or the board faces away.
    """
    from qrfield.render import ideal_canvas  # the same distortion remap the QR renderer uses

    if supersample < 1 or int(supersample) != supersample:
        raise ValueError(f"supersample must be a whole number >= 1, got {supersample!r}")
    corners_cam = transform_points(pose.rotation, pose.position_mm, board.centred_points())
    if np.any(corners_cam[:, 2] <= 1e-6):
        raise ValueError("the board is (partly) behind the camera: every corner needs z > 0 mm")
    if float(pose.rotation[:, 2] @ pose.position_mm) <= 0.0:
        raise ValueError("the board faces away from the camera")
    corners_px = project_points(corners_cam, camera)
    inside = (
        (corners_px[:, 0] >= 0)
        & (corners_px[:, 0] <= camera.width - 1)
        & (corners_px[:, 1] >= 0)
        & (corners_px[:, 1] <= camera.height - 1)
    )
    if not np.all(inside):
        raise ValueError(
            f"{int(np.sum(~inside))} board corners fall outside the {camera.width}x{camera.height} image"
        )

    ideal = ideal_canvas(camera)
    canvas = ideal.to_camera(
        _ideal_picture(camera, board, pose, ideal.offset, ideal.size, int(supersample), background)
    )
    if noise_sigma < 0 or not math.isfinite(noise_sigma):
        raise ValueError(f"noise_sigma must be a finite number >= 0, got {noise_sigma!r}")
    if noise_sigma > 0:
        rng = np.random.default_rng(seed)
        noisy = canvas.astype(np.float32) + rng.standard_normal(canvas.shape, dtype=np.float32) * noise_sigma
        canvas = np.clip(noisy + 0.5, 0, 255).astype(np.uint8)
    return ChessboardView(canvas, corners_px, pose, camera, board)


def _ideal_picture(
    camera: CameraModel,
    board: Board,
    pose: Pose,
    offset: tuple[float, float],
    size: tuple[int, int],
    ss: int,
    background: int,
) -> np.ndarray:
    """uint8 pinhole picture of the board on a canvas whose pixel (0, 0) is camera pixel ``offset``."""
    width, height = size
    s = board.square_mm
    # Board-plane mm -> canvas pixel, then inverted: canvas sample -> board-plane mm.
    r = pose.rotation
    k_canvas = camera.K.copy()
    k_canvas[0, 2] -= offset[0]
    k_canvas[1, 2] -= offset[1]
    plane_to_px = k_canvas @ np.column_stack([r[:, 0], r[:, 1], pose.position_mm])
    px_to_plane = np.linalg.inv(plane_to_px)
    # Extent of the board with its border, on the plane (mm), and its bounding box on the canvas.
    half_w = ((board.cols + 1) / 2.0 + BORDER_SQUARES) * s
    half_h = ((board.rows + 1) / 2.0 + BORDER_SQUARES) * s
    outline = np.array(
        [[-half_w, -half_h, 1.0], [half_w, -half_h, 1.0], [half_w, half_h, 1.0], [-half_w, half_h, 1.0]]
    )
    proj = outline @ plane_to_px.T
    if np.any(proj[:, 2] <= 0):
        raise ValueError("the board's border reaches behind the camera; move the board further away")
    box = proj[:, :2] / proj[:, 2:3]
    x0 = max(0, math.floor(box[:, 0].min()) - 1)
    y0 = max(0, math.floor(box[:, 1].min()) - 1)
    x1 = min(width, math.ceil(box[:, 0].max()) + 2)
    y1 = min(height, math.ceil(box[:, 1].max()) + 2)
    canvas = np.full((height, width), int(background), np.uint8)
    if x1 <= x0 or y1 <= y0:
        return canvas
    # Sample centres of the supersampled grid in canvas pixels (pixel centres at integers).
    su = x0 - 0.5 + (np.arange((x1 - x0) * ss) + 0.5) / ss
    sv = y0 - 0.5 + (np.arange((y1 - y0) * ss) + 0.5) / ss
    uu, vv = np.meshgrid(su, sv)
    w = px_to_plane[2, 0] * uu + px_to_plane[2, 1] * vv + px_to_plane[2, 2]
    bx = (px_to_plane[0, 0] * uu + px_to_plane[0, 1] * vv + px_to_plane[0, 2]) / w
    by = (px_to_plane[1, 0] * uu + px_to_plane[1, 1] * vv + px_to_plane[1, 2]) / w
    # Square indices counted from the top-left outer square (dark); corners lie on integer lines.
    qx = np.floor(bx / s + (board.cols + 1) / 2.0)
    qy = np.floor(by / s + (board.rows + 1) / 2.0)
    on_squares = (qx >= 0) & (qx <= board.cols) & (qy >= 0) & (qy <= board.rows)
    on_board = (np.abs(bx) <= half_w) & (np.abs(by) <= half_h) & (w > 0)
    dark = on_squares & ((qx + qy) % 2 == 0)
    samples = np.where(on_board, np.where(dark, 0.0, 255.0), float(background)).astype(np.float32)
    if ss > 1:
        samples = cv2.resize(samples, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
    canvas[y0:y1, x0:x1] = np.clip(samples + 0.5, 0, 255).astype(np.uint8)
    return canvas
