"""Real optics: four chessboard corners as a "QR code", against the whole board (section 4 of
``qrfield benchmark pose``, and tests/test_benchmarks_pose.py).

Data: ../shared/data/calibration/Bumblebee2_Chess, 11 + 11 real 640x480 frames of a chessboard with
4 x 6 inner corners (a PtGrey Bumblebee2 stereo camera, left and right), hand-labelled corners
(``leftNN.txt``), and the intrinsics BoofCV computed (``intrinsicLeft.xml``; the right camera's in
``stereo.xml``: fx, fy, cx, cy and two radial terms, OpenCV's k1, k2). The squares are 30 mm, as
BoofCV's calibration example for this data configures (only the mm figures depend on it).

For each frame the inner corners are found by OpenCV (findChessboardCorners + cornerSubPix, as
``qrfield calibrate`` does) and the board's pose by cv2.solvePnP (iterative LM) on all 24 corners:
the reference. Each square of 4 inner corners (2 or 3 squares a side) is then solved as a QR code of
that side by each method through the calibrated model, and compared with the reference pose of
that square (its centre, and the board's axes). Corner std: the RMS residual of the 24 detected
corners about the whole-board fit, sqrt(RSS / (2 N - 6)) per coordinate (noise and lens model
error together). A second source, the hand labels (minus 0.5 px: they count from the pixel edge),
takes its std from the labels' own residual about a board fit to them.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from qrfield.camera import CameraModel

FOLDER = "calibration/Bumblebee2_Chess"
SQUARE_MM = 30.0
#: Squares of k x k board squares, k in SQUARE_SIZES, with 4 inner corners at their corners.
SQUARE_SIZES = (2, 3)
#: Marker axes in board axes when a square's corners have to be taken transposed to run
#: clockwise on screen: X_m = Y_b, Y_m = X_b, Z_m = -Z_b.
TRANSPOSE = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def boofcv_cameras(folder: Path) -> dict[str, CameraModel]:
    """{"left": ..., "right": ...} from BoofCV's XMLEncoder files (left: intrinsicLeft.xml; right:
    the second IntrinsicParameters of stereo.xml)."""

    def parse(block: str, name: str) -> CameraModel:
        value = {}
        for key in ("cx", "cy", "fx", "fy"):
            match = re.search(rf'property="{key}">\s*<double>([-0-9.eE]+)</double>', block)
            if match is None:
                raise ValueError(f"{name}: no {key}")
            value[key] = float(match.group(1))
        radial = [float(v) for v in re.findall(r"<void index=\"\d\">\s*<double>([-0-9.eE]+)</double>", block)]
        k1, k2 = [*radial, 0.0, 0.0][:2]
        return CameraModel(
            width=640, height=480, dist=[k1, k2, 0.0, 0.0, 0.0], name=f"bumblebee2-{name} (BoofCV)", **value
        )

    left = (folder / "intrinsicLeft.xml").read_text()
    stereo = (folder / "stereo.xml").read_text()
    blocks = stereo.split('class="boofcv.struct.calib.IntrinsicParameters"')
    return {"left": parse(left, "left"), "right": parse(blocks[2], "right")}


@dataclass(frozen=True)
class SquareCase:
    """One square of one frame solved by one method from one corner source.

    errors: (6,) x, y, z (mm) and alpha, beta, gamma (deg) minus the whole-board reference.
    std: (6,) the solver's reported std; ref_std: (6,) the reference's own std (24 corners).
    corner_std_px: the per-coordinate corner std used (px).
    """

    frame: str
    source: str
    size: int
    method: str
    converged: bool
    ambiguous: bool
    errors: np.ndarray
    std: np.ndarray
    ref_std: np.ndarray
    corner_std_px: float
    distance_mm: float


def _board_fit(object_points: np.ndarray, corners: np.ndarray, camera: CameraModel):
    """(R, t, sigma px, covariance of (omega, t)) of the board by cv2.solvePnP (iterative LM)."""
    import cv2

    ok, rvec, tvec = cv2.solvePnP(object_points, corners, camera.K, camera.dist, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise RuntimeError("solvePnP failed on the whole board")
    rotation, position = cv2.Rodrigues(rvec)[0], tvec.reshape(3)

    def project(r: np.ndarray, t: np.ndarray) -> np.ndarray:
        pts = cv2.projectPoints(object_points, cv2.Rodrigues(r)[0], t, camera.K, camera.dist)[0]
        return pts.reshape(-1)

    residual = project(rotation, position) - corners.reshape(-1)
    sigma = math.sqrt(float(residual @ residual) / (residual.size - 6))
    jac = np.zeros((residual.size, 6))
    h = 1e-6
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        # exp([omega]x) R: a small rotation of the camera frame, as in qrfield.solvers.uncertainty.
        plus = project(cv2.Rodrigues(step[:3])[0] @ rotation, position + step[3:])
        minus = project(cv2.Rodrigues(-step[:3])[0] @ rotation, position - step[3:])
        jac[:, k] = (plus - minus) / (2 * h)
    return rotation, position, sigma, sigma**2 * np.linalg.inv(jac.T @ jac)


def _square_reference(rotation, position, cov_p, centre_board, axes):
    """(centre mm, angles deg, (6,) std) of a square's marker frame from the board pose."""
    from qrfield.geometry import angles_from_rotation
    from qrfield.solvers.uncertainty import _skew, euler_jacobian

    marker = rotation @ axes
    arm = rotation @ centre_board
    angles = angles_from_rotation(marker)
    f = np.zeros((6, 6))
    f[:3, :3] = -_skew(arm)
    f[:3, 3:] = np.eye(3)
    f[3:, :3] = euler_jacobian(angles)
    std = np.sqrt(np.diag(f @ cov_p @ f.T))
    return arm + position, angles, std


def _sources(image_path: Path, camera: CameraModel, board) -> list[tuple[str, np.ndarray]]:
    """[("cornerSubPix", corners (24, 2)), ("hand labels", ...)] in OpenCV's board order."""
    import cv2

    from qrfield.calibration import detect_board

    detection = detect_board(cv2.imread(str(image_path), cv2.IMREAD_GRAYSCALE), board, str(image_path))
    if not detection.found:
        return []
    corners = detection.corners_px
    out = [("cornerSubPix", corners)]
    labels = image_path.with_suffix(".txt")
    if labels.is_file():
        hand = np.loadtxt(labels) - 0.5  # pixel-edge origin -> OpenCV's pixel centres
        nearest = np.linalg.norm(corners[:, None, :] - hand[None, :, :], axis=2).argmin(axis=1)
        if len(set(nearest.tolist())) == len(corners):
            out.append(("hand labels", hand[nearest]))
    return out


def square_cases(folder: Path) -> list[SquareCase]:
    """Every (frame, corner source, square, method) of the data set (see the module doc)."""
    from qrfield.chessboard import Board
    from qrfield.geometry import angle_difference
    from qrfield.solvers import METHODS, solve
    from qrfield.solvers.checks import quad_problem
    from qrfield.solvers.uncertainty import isotropic_cov

    board = Board(4, 6, SQUARE_MM)
    cams = boofcv_cameras(folder)
    obj = board.object_points().astype(np.float64)
    out: list[SquareCase] = []
    for image_path in sorted(folder.glob("*[0-9][0-9].jpg")):
        camera = cams["left" if image_path.name.startswith("left") else "right"]
        sources = _sources(image_path, camera, board)
        if not sources:
            continue
        rotation, position, _, cov_p = _board_fit(obj, sources[0][1], camera)  # the reference
        for source, corners in sources:
            sigma = _board_fit(obj, corners, camera)[2]
            for size in SQUARE_SIZES:
                for j0 in range(board.rows - size):
                    for i0 in range(board.cols - size):
                        grid = [(i0, j0), (i0 + size, j0), (i0 + size, j0 + size), (i0, j0 + size)]
                        axes = np.eye(3)
                        quad = np.array([corners[j * board.cols + i] for i, j in grid])
                        if quad_problem(quad.ravel().tolist()):  # counter-clockwise: transpose
                            grid = [grid[0], grid[3], grid[2], grid[1]]
                            axes = TRANSPOSE
                            quad = np.array([corners[j * board.cols + i] for i, j in grid])
                        centre_board = np.array(
                            [(i0 + size / 2) * SQUARE_MM, (j0 + size / 2) * SQUARE_MM, 0.0]
                        )
                        ref_pos, ref_ang, ref_std = _square_reference(
                            rotation, position, cov_p, centre_board, axes
                        )
                        for method in METHODS:
                            r = solve(
                                quad, camera, size * SQUARE_MM, method, corners_cov=isotropic_cov(sigma)
                            )
                            errors = np.concatenate(
                                [r.position_mm - ref_pos, angle_difference(r.angles_deg, ref_ang)]
                            )
                            out.append(
                                SquareCase(
                                    image_path.stem,
                                    source,
                                    size,
                                    method,
                                    r.converged,
                                    r.ambiguous,
                                    errors,
                                    np.concatenate([r.position_std_mm, r.angles_std_deg]),
                                    ref_std,
                                    sigma,
                                    float(np.linalg.norm(ref_pos)),
                                )
                            )
    return out
