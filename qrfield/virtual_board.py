"""The virtual chessboard: the simulated twin of a person showing a calibration board to the camera.

:class:`VirtualChessboard` draws seeded board poses that a careful person would present: the
board's centre aimed at each cell of a 3x3 grid of the image in turn (so the coverage grid fills),
tilted up to ``max_tilt_deg`` in a random direction, at a distance where the board spans about
``span`` of the image width, the whole board (with its white border) inside the image. Each view is
rendered by :func:`qrfield.chessboard.render_chessboard` through the given camera model (distortion
included), so a calibration from these views must give that camera back: the independent truth of
the app's calibration dialog tests. Poses are in mm and degrees, board frame as in
:mod:`qrfield.chessboard`.
"""

from __future__ import annotations

import numpy as np

from qrfield.camera import CameraModel
from qrfield.chessboard import BORDER_SQUARES, Board, ChessboardView, render_chessboard
from qrfield.geometry import Pose, project_points, transform_points
from qrfield.sampling import random_tilted_rotation

#: Cells the board's centre is aimed at, in turn: (column, row) of a 3x3 grid, the centre first.
AIM_CELLS = ((1, 1), (0, 0), (2, 0), (2, 2), (0, 2), (1, 0), (2, 1), (1, 2), (0, 1))


class VirtualChessboard:
    """Seeded board poses and rendered views for calibrating ``camera`` without hardware.

    Args:
        camera: the camera model to render through (its intrinsics are the truth).
        board: the board (inner corners, square side in mm).
        seed: the random seed; the same seed gives the same sequence of views.
        max_tilt_deg: largest angle between the board's normal and the optical axis.
        span: board width (with border) as a share of the image width, at the aimed distance.
        margin_px: every outline point of the board stays this far inside the image.
        noise_sigma: Gaussian pixel noise of the rendered images, grey levels.

    Raises:
        ValueError: a setting out of range.
    """

    MAX_ATTEMPTS = 400

    def __init__(
        self,
        camera: CameraModel,
        board: Board,
        seed: int = 0,
        *,
        max_tilt_deg: float = 40.0,
        span: float = 0.45,
        margin_px: float = 6.0,
        noise_sigma: float = 1.0,
    ) -> None:
        if not 0.0 <= max_tilt_deg < 80.0:
            raise ValueError(f"max_tilt_deg must be in [0, 80), got {max_tilt_deg!r}")
        if not 0.05 <= span <= 1.0:
            raise ValueError(f"span must be in [0.05, 1], got {span!r}")
        if margin_px < 0 or noise_sigma < 0:
            raise ValueError(f"margin_px and noise_sigma must be >= 0, got {margin_px!r}, {noise_sigma!r}")
        self.camera = camera
        self.board = board
        self.seed = int(seed)
        self.max_tilt_deg = float(max_tilt_deg)
        self.span = float(span)
        self.margin_px = float(margin_px)
        self.noise_sigma = float(noise_sigma)
        self._rng = np.random.default_rng(self.seed)
        self.count = 0  # views made so far

    def outline_mm(self) -> np.ndarray:
        """(4, 3) corners of the board with its white border, board frame, mm."""
        s = self.board.square_mm
        half_w = ((self.board.cols + 1) / 2.0 + BORDER_SQUARES) * s
        half_h = ((self.board.rows + 1) / 2.0 + BORDER_SQUARES) * s
        return np.array(
            [[-half_w, -half_h, 0.0], [half_w, -half_h, 0.0], [half_w, half_h, 0.0], [-half_w, half_h, 0.0]]
        )

    def _fits(self, pose: Pose) -> bool:
        if float(pose.rotation[:, 2] @ pose.position_mm) <= 0.0:
            return False  # faces away
        points = transform_points(pose.rotation, pose.position_mm, self.outline_mm())
        if np.any(points[:, 2] <= 1.0):
            return False
        px = project_points(points, self.camera)
        m = self.margin_px
        return bool(
            np.all(np.isfinite(px))
            and np.all(px[:, 0] >= m)
            and np.all(px[:, 0] <= self.camera.width - 1 - m)
            and np.all(px[:, 1] >= m)
            and np.all(px[:, 1] <= self.camera.height - 1 - m)
        )

    def next_pose(self) -> Pose:
        """The next seeded pose (board to camera, mm and degrees) aimed at the next 3x3 cell.

        Where the aimed cell cannot hold the whole board, the aim slides towards the image centre.
        Raises ValueError when the board cannot be placed at all (e.g. a board too large for the view).
        """
        cam = self.camera
        col, row = AIM_CELLS[self.count % len(AIM_CELLS)]
        width_mm = 2 * self.outline_mm()[1, 0]
        z0 = cam.fx * width_mm / (self.span * cam.width)
        centre = np.array([(cam.width - 1) / 2.0, (cam.height - 1) / 2.0])
        aim = np.array([(col + 0.5) * cam.width / 3.0 - 0.5, (row + 0.5) * cam.height / 3.0 - 0.5])
        for attempt in range(self.MAX_ATTEMPTS):
            pull = min(1.0, attempt / (0.75 * self.MAX_ATTEMPTS))  # slide the aim towards the centre
            u, v = aim + pull * (centre - aim) + self._rng.normal(0.0, 0.04, 2) * (cam.width, cam.height)
            z = z0 * self._rng.uniform(0.85, 1.25)
            x = (u - cam.cx) * z / cam.fx
            y = (v - cam.cy) * z / cam.fy
            rotation = random_tilted_rotation(self._rng, self.max_tilt_deg)
            pose = Pose.from_rotation(rotation, np.array([x, y, z]))
            if self._fits(pose):
                self.count += 1
                return pose
        raise ValueError(
            f"cannot place the {self.board.label} board ({width_mm:g} mm wide with its border) inside the "
            f"{cam.width}x{cam.height} image of camera {cam.name} at span {self.span:g}"
        )

    def next_view(self) -> ChessboardView:
        """Render the board at :meth:`next_pose` (grey image and the exact corner pixels)."""
        pose = self.next_pose()
        seed = None if self.noise_sigma == 0 else self.seed * 100_003 + self.count
        return render_chessboard(self.camera, self.board, pose, noise_sigma=self.noise_sigma, seed=seed)
