"""Camera calibration from chessboard views (OpenCV's detectors and calibrateCamera).

Pipeline: :func:`detect_board` finds the board's inner corners in one image (never raises for
what the picture holds: it returns a :class:`BoardDetection` with a reason, so a live dialog can
call it on every frame); :func:`calibrate` turns a list of detections into a
:class:`CalibrationResult`: a :class:`~qrfield.camera.CameraModel` (pixels in OpenCV's
convention, distortion k1, k2, p1, p2, k3), the RMS reprojection error, each view's error, the views
skipped with their reason, a coverage grid of where in the image the board has been, and advice
(:meth:`CalibrationResult.advice`). Degenerate sets (boards all facing one way, absurd focal
lengths) raise :class:`CalibrationError` instead of returning a wrong model.
:func:`calibrate_images` does both steps for image files or arrays.

The square side S only scales the board poses; the intrinsics do not depend on it.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from qrfield.camera import SENSOR_FIELDS, CameraModel, format_crop
from qrfield.chessboard import Board

#: Fewest usable views calibrate() accepts (with zero skew, two views fix the intrinsics in theory;
#: three make a usable minimum, ten or more spread over the image give a good model).
MIN_VIEWS = 3
#: Largest image (megapixels) OpenCV's board detectors see: a larger photo is searched shrunk by a
#: whole factor and its corners refined on the full image (``calibrate`` on a 49 MP photo then
#: peaks under 600 MB: docs/calibration.md, ``qrfield benchmark memory``). 5 MP keeps the 3280 x
#: 2464 photos of a Pi camera v2 at factor 2 and a 640 x 480 frame untouched.
WORKING_MEGAPIXELS = 5.0
#: Coverage grid used by default: (columns, rows) of image cells.
COVERAGE_CELLS = (3, 3)
_ROW_NAMES = ("top", "middle", "bottom")
_COL_NAMES = ("left", "centre", "right")


class CalibrationError(ValueError):
    """No usable calibration: too few usable views, or a degenerate solution (views too alike).

    ``skipped`` lists the views left out and why, for a dialog to show.
    """

    def __init__(self, message: str, skipped: Sequence[SkippedView] = ()) -> None:
        super().__init__(message)
        self.skipped = tuple(skipped)


@dataclass(frozen=True)
class BoardDetection:
    """The board found (or not) in one image.

    Attributes:
        label: the image's name for humans (file path, or e.g. ``view 3``).
        corners_px: (cols*rows, 2) float64 sub-pixel corner pixels in OpenCV's order and pixel
            convention (top-left pixel centre = (0, 0)), or None when not found.
        image_size: (width, height) in pixels, or None when the image could not be read.
        reason: why ``corners_px`` is None ("" when found).
        method: ``classic`` (findChessboardCorners + cornerSubPix) or ``sb`` (findChessboardCornersSB
            + cornerSubPix), "" when not found.
    """

    label: str
    corners_px: np.ndarray | None
    image_size: tuple[int, int] | None
    reason: str = ""
    method: str = ""

    @property
    def found(self) -> bool:
        return self.corners_px is not None


@dataclass(frozen=True)
class ViewError:
    """Reprojection error of one used view, pixels: RMS and largest over its corners."""

    label: str
    rms_px: float
    max_px: float


@dataclass(frozen=True)
class SkippedView:
    """A view left out of the calibration, and why."""

    label: str
    reason: str


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` found.

    Attributes:
        camera: the calibrated model (fx, fy, cx, cy in px; dist k1, k2, p1, p2, k3).
        rms_px: RMS reprojection error over all corners of all used views, px (OpenCV's figure).
        views: per used view, its RMS and largest reprojection error (px), in input order.
        skipped: views left out, with the reason, in input order.
        board: the board (inner corners, square side in mm).
        std_px: one-sigma uncertainty of fx, fy, cx, cy (px) estimated by OpenCV.
        coverage: (rows, cols) int array, number of used views with a corner in each image cell.
        detections: the used views' detections (corners), in input order.
    """

    camera: CameraModel
    rms_px: float
    views: tuple[ViewError, ...]
    skipped: tuple[SkippedView, ...]
    board: Board
    std_px: dict[str, float]
    coverage: np.ndarray
    detections: tuple[BoardDetection, ...] = field(default=(), repr=False)

    @property
    def used(self) -> list[str]:
        """Labels of the views used, in input order."""
        return [v.label for v in self.views]

    def advice(self) -> list[str]:
        """Hints for a better calibration: image cells no view reached, views whose error stands out
        (over 3 times the median and over 0.3 px), focal lengths uncertain by more than 1 %."""
        hints = []
        missing = uncovered_cells(self.coverage)
        if missing:
            hints.append(f"no view reached the {', '.join(missing)} of the image: add views there")
        median = float(np.median([v.rms_px for v in self.views]))
        for v in self.views:
            if v.rms_px > max(3.0 * median, 0.3):
                hints.append(
                    f"{v.label}: error {v.rms_px:.2f} px, {v.rms_px / median:.0f}x the median; "
                    "check its corners (motion blur? a bent board?) or leave it out"
                )
        for key in ("fx", "fy"):
            value, sigma = getattr(self.camera, key), self.std_px[key]
            if sigma > 0.01 * value:
                hints.append(
                    f"{key} is uncertain by +-{sigma:.1f} px ({100 * sigma / value:.1f} %): "
                    "add views with the board tilted in different directions"
                )
        return hints

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary (the shape ``qrfield calibrate --json`` prints; see that command)."""
        cam = self.camera
        return {
            "fx": cam.fx,
            "fy": cam.fy,
            "cx": cam.cx,
            "cy": cam.cy,
            "dist": [float(d) for d in cam.dist],
            "rms_px": self.rms_px,
            "used": self.used,
            "skipped": [{"image": s.label, "reason": s.reason} for s in self.skipped],
            "width": cam.width,
            "height": cam.height,
            "per_image": [{"image": v.label, "rms_px": v.rms_px, "max_px": v.max_px} for v in self.views],
            "std_px": dict(self.std_px),
            "board": self.board.label,
            "square_mm": self.board.square_mm,
            "coverage": self.coverage.tolist(),
            "advice": self.advice(),
        }


# ---------------------------------------------------------------------- detection


def _subpixel_half_window(corners: np.ndarray, board: Board) -> int:
    """cornerSubPix half-window: about a third of the smallest corner spacing, 2..10 px.

    The window must stay within the four squares around a corner, or it locks onto a neighbour.
    """
    grid = corners.reshape(board.rows, board.cols, 2)
    along_rows = np.linalg.norm(np.diff(grid, axis=1), axis=-1).min()
    along_cols = np.linalg.norm(np.diff(grid, axis=0), axis=-1).min()
    return int(np.clip(min(along_rows, along_cols) / 3.0, 2, 10))


def detect_board(
    image: np.ndarray, board: Board, label: str = "image", thorough: bool = True
) -> BoardDetection:
    """Find the inner corners of ``board`` in one grey (H, W) or BGR (H, W, 3) uint8 image.

    Tries OpenCV's classic detector (fast, and closest to hand-labelled corners on real photos),
    then, if ``thorough``, the sector-based one (more robust to blur and uneven light, but some
    0.2-0.3 s on a VGA frame without a board: a live preview passes ``thorough=False``); corners are
    refined with cornerSubPix. Never raises for the picture's content: a missing board, or an array
    that is not an 8-bit image, comes back with ``reason`` set.
    """
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim not in (2, 3):
        what = (
            f"{image.dtype} array of shape {image.shape}"
            if isinstance(image, np.ndarray)
            else type(image).__name__
        )
        return BoardDetection(label, None, None, f"not an 8-bit grey or BGR image ({what})")
    if image.ndim == 3:
        if image.shape[2] == 3:
            grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        elif image.shape[2] == 1:
            grey = image[:, :, 0]
        else:
            return BoardDetection(label, None, None, f"not a grey or BGR image ({image.shape[2]} channels)")
    else:
        grey = image
    size = (int(grey.shape[1]), int(grey.shape[0]))
    if min(size) < 16:
        return BoardDetection(label, None, size, f"image of {size[0]}x{size[1]} px is too small")
    # OpenCV's detectors need tens of bytes per pixel (findChessboardCornersSB took 2.6 GB on a
    # 49 MP photo): they run on a copy shrunk to the working resolution, and only the sub-pixel
    # refinement, which reads a small window around each corner, runs on the full image.
    factor = working_factor(size)
    small = (
        grey
        if factor == 1
        else cv2.resize(grey, (size[0] // factor, size[1] // factor), interpolation=cv2.INTER_AREA)
    )
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(small, board.pattern_size, flags=flags)
    method = "classic"
    if not found and thorough:
        found, corners = cv2.findChessboardCornersSB(small, board.pattern_size, flags=cv2.CALIB_CB_EXHAUSTIVE)
        method = "sb"
    del small
    if not found or corners is None or len(corners) != board.corner_count:
        return BoardDetection(
            label,
            None,
            size,
            f"board {board.label} (inner corners) not found; "
            "check --board and that the whole board is in view",
        )
    # A shrunk pixel i covers full pixels factor*i .. factor*i + factor-1 (centre conventions of
    # docs/conventions.md: a pixel's centre is its integer coordinate).
    corners = (corners.reshape(-1, 1, 2).astype(np.float32) * factor + (factor - 1) / 2.0).astype(np.float32)
    half = max(_subpixel_half_window(corners.reshape(-1, 2), board), min(2 * factor, 10))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-3)
    corners = cv2.cornerSubPix(grey, corners, (half, half), (-1, -1), criteria)
    return BoardDetection(label, corners.reshape(-1, 2).astype(np.float64), size, "", method)


def working_factor(size: tuple[int, int], megapixels: float | None = None) -> int:
    """The whole number an image of ``size`` (width, height) is shrunk by for the board search, so
    that the search sees at most ``megapixels`` (default :data:`WORKING_MEGAPIXELS`; 1 for an
    image that is small enough)."""
    limit = WORKING_MEGAPIXELS if megapixels is None else megapixels
    pixels = float(size[0]) * float(size[1])
    return max(1, math.ceil(math.sqrt(pixels / (limit * 1e6))))


def read_image(path: str | os.PathLike[str]) -> np.ndarray | None:
    """The image file as a grey uint8 array, or None when it cannot be read or decoded (or is above
    the pixel limit, refused before decoding: qrfield.images)."""
    from qrfield.images import ImageError
    from qrfield.images import read_image as read_checked

    try:
        return read_checked(path, mode="grey")
    except ImageError:
        return None


def detect_board_file(path: str | os.PathLike[str], board: Board) -> BoardDetection:
    """:func:`detect_board` on an image file; an unreadable file comes back with its reason."""
    from qrfield.images import ImageError
    from qrfield.images import read_image as read_checked

    label = str(path)
    try:
        image = read_checked(path, mode="grey")
    except ImageError as exc:  # the reason: no such file, a FIFO, over the pixel limit, not an image
        return BoardDetection(label, None, None, str(exc).removeprefix(f"{label}: "))
    return detect_board(image, board, label)


def detection_from_corners(
    corners_px: np.ndarray, image_size: tuple[int, int], board: Board, label: str
) -> BoardDetection:
    """A detection from corners found elsewhere (e.g. by a live dialog); a wrong shape gives a reason."""
    c = np.asarray(corners_px, dtype=float)
    if c.size != board.corner_count * 2:
        return BoardDetection(
            label,
            None,
            image_size,
            f"has {c.size // 2} corners, the {board.label} board has {board.corner_count}",
        )
    c = c.reshape(-1, 2)
    if not np.all(np.isfinite(c)):
        return BoardDetection(label, None, image_size, "corners contain NaN or inf")
    return BoardDetection(label, c, (int(image_size[0]), int(image_size[1])), "", "given")


# ---------------------------------------------------------------------- coverage


def coverage_grid(
    corner_sets: Sequence[np.ndarray], image_size: tuple[int, int], cells: tuple[int, int] = COVERAGE_CELLS
) -> np.ndarray:
    """(rows, cols) int array: for each cell of the image split into ``cells`` = (cols, rows) equal
    parts, the number of views with at least one corner in it.

    ``corner_sets`` holds (N, 2) pixel arrays (OpenCV convention); a cell is [k*W/cols - 0.5,
    (k+1)*W/cols - 0.5) in u, likewise in v. Corners outside the image are ignored.
    """
    n_cols, n_rows = int(cells[0]), int(cells[1])
    if n_cols < 1 or n_rows < 1:
        raise ValueError(f"coverage cells must be at least 1x1, got {cells!r}")
    width, height = image_size
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {image_size!r}")
    grid = np.zeros((n_rows, n_cols), dtype=int)
    for corners in corner_sets:
        c = np.asarray(corners, dtype=float).reshape(-1, 2)
        col = np.floor((c[:, 0] + 0.5) * n_cols / width).astype(int)
        row = np.floor((c[:, 1] + 0.5) * n_rows / height).astype(int)
        keep = (col >= 0) & (col < n_cols) & (row >= 0) & (row < n_rows)
        hit = np.zeros_like(grid, dtype=bool)
        hit[row[keep], col[keep]] = True
        grid += hit
    return grid


def cell_name(row: int, col: int, cells: tuple[int, int] = COVERAGE_CELLS) -> str:
    """Human name of a coverage cell: ``top-left`` .. ``bottom-right`` on a 3x3 grid, else ``row R col C``."""
    if tuple(cells) == (3, 3):
        return "centre" if (row, col) == (1, 1) else f"{_ROW_NAMES[row]}-{_COL_NAMES[col]}"
    return f"row {row + 1} col {col + 1}"


def uncovered_cells(grid: np.ndarray) -> list[str]:
    """Names of the cells no view has reached yet (the hint a calibration dialog shows)."""
    rows, cols = grid.shape
    return [cell_name(r, c, (cols, rows)) for r in range(rows) for c in range(cols) if grid[r, c] == 0]


# ---------------------------------------------------------------------- calibration


def _split_usable(
    detections: Sequence[BoardDetection], board: Board
) -> tuple[list[BoardDetection], list[SkippedView], tuple[int, int] | None]:
    """Views usable together (found, right corner count, the common image size) and the rest."""
    found = [d for d in detections if d.found]
    sizes = Counter(d.image_size for d in found)
    size = None
    if sizes:
        best = max(sizes.values())
        size = next(d.image_size for d in found if sizes[d.image_size] == best)  # ties: the first seen
    used: list[BoardDetection] = []
    skipped: list[SkippedView] = []
    for d in detections:
        if not d.found:
            skipped.append(SkippedView(d.label, d.reason or "board not found"))
        elif d.corners_px.shape != (board.corner_count, 2):
            skipped.append(
                SkippedView(
                    d.label,
                    f"has {d.corners_px.shape[0]} corners, the {board.label} board has {board.corner_count}",
                )
            )
        elif d.image_size != size:
            skipped.append(
                SkippedView(
                    d.label,
                    f"wrong size: image is {d.image_size[0]}x{d.image_size[1]}, "
                    f"most views are {size[0]}x{size[1]}",
                )
            )
        else:
            used.append(d)
    return used, skipped, size


_VARY_HINT = (
    "take views with the board tilted 20-45 degrees in different directions and spread over the image"
)
#: Views whose board normals all lie within this angle of each other cannot fix the focal length.
MIN_TILT_SPREAD_DEG = 5.0
#: Plausible focal lengths, in image widths (a field of view from about 160 to 1 degrees).
FOCAL_RANGE_WIDTHS = (0.09, 60.0)


def _check_plausible(
    K: np.ndarray,
    rvecs: Sequence[np.ndarray],
    size: tuple[int, int],
    count: int,
    skipped: Sequence[SkippedView],
) -> None:
    """Raise CalibrationError for a degenerate solution (views too alike, absurd focal lengths)."""
    normals = np.array([cv2.Rodrigues(np.asarray(r, dtype=float))[0][:, 2] for r in rvecs])
    cosines = np.clip(normals @ normals.T, -1.0, 1.0)
    spread = float(np.degrees(np.arccos(cosines.min())))
    if spread < MIN_TILT_SPREAD_DEG:
        raise CalibrationError(
            f"the {count} views are too alike: the board faces the same way in all of them (its normal "
            f"turns by at most {spread:.1f} deg, at least {MIN_TILT_SPREAD_DEG:g} needed); {_VARY_HINT}",
            skipped,
        )
    fx, fy = float(K[0, 0]), float(K[1, 1])
    lo, hi = (f * size[0] for f in FOCAL_RANGE_WIDTHS)
    if not (lo <= fx <= hi and lo <= fy <= hi and 0.5 <= fx / fy <= 2.0):
        raise CalibrationError(
            f"the calibration is implausible (fx = {fx:.4g} px, fy = {fy:.4g} px for a {size[0]} px wide "
            f"image); {_VARY_HINT}",
            skipped,
        )


def calibrate(
    detections: Sequence[BoardDetection],
    board: Board,
    *,
    fix_k3: bool = False,
    name: str = "calibrated",
    min_views: int = MIN_VIEWS,
    cells: tuple[int, int] = COVERAGE_CELLS,
    stream: CameraModel | None = None,
) -> CalibrationResult:
    """Calibrate from board detections with cv2.calibrateCamera (pinhole, k1, k2, p1, p2, k3).

    Views whose board was not found, whose corner count is wrong, or whose image size differs
    from most views' are skipped with the reason.

    Args:
        detections: from :func:`detect_board`, :func:`detect_board_file` or :func:`detection_from_corners`.
        board: the board (inner corners COLSxROWS, square side in mm).
        fix_k3: keep k3 = 0 (advisable with few views or a mild lens).
        name: the camera model's name.
        min_views: fewest usable views accepted.
        cells: (cols, rows) of the coverage grid.
        stream: the camera model of the stream the views came from (a picamera2 stream's, derived
            from its sensor mode and crop); its sensor geometry (sensor_resolution, sensor_crop,
            sensor_mode, lens_position, focal_length_mm) is saved in the result when it has the
            views' size, so the profile can be mapped to other modes and warns at another focus.

    Raises:
        CalibrationError: fewer than ``min_views`` usable views (the message lists why views were skipped).
    """
    if min_views < 2:
        raise ValueError(f"min_views must be at least 2, got {min_views}")
    used, skipped, size = _split_usable(detections, board)
    if len(used) < min_views:
        reasons = "; ".join(f"{Path(s.label).name}: {s.reason}" for s in skipped[:3])
        more = f"; and {len(skipped) - 3} more" if len(skipped) > 3 else ""
        if used:
            head = f"only {len(used)} of {len(detections)} images usable, at least {min_views} needed"
        else:
            head = f"no usable images among {len(detections)}"
        detail = f" ({len(skipped)} skipped: {reasons}{more})" if skipped else ""
        raise CalibrationError(f"{head}{detail}", skipped)
    object_points = [board.object_points() for _ in used]
    image_points = [d.corners_px.reshape(-1, 1, 2).astype(np.float32) for d in used]
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        rms, K, dist, rvecs, tvecs, std_intrinsics, _std_extr, _per_view = cv2.calibrateCameraExtended(
            object_points, image_points, size, None, None, flags=flags, criteria=criteria
        )
    except cv2.error as exc:
        raise CalibrationError(
            f"OpenCV could not calibrate from these {len(used)} views ({exc.err}); {_VARY_HINT}", skipped
        ) from None
    _check_plausible(K, rvecs, size, len(used), skipped)
    views = []
    for d, obj, rvec, tvec in zip(used, object_points, rvecs, tvecs, strict=True):
        projected, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
        err = np.linalg.norm(projected.reshape(-1, 2) - d.corners_px, axis=1)
        views.append(ViewError(d.label, float(np.sqrt(np.mean(err**2))), float(err.max())))
    std = np.asarray(std_intrinsics, dtype=float).reshape(-1)
    std_px = {key: float(std[i]) for i, key in enumerate(("fx", "fy", "cx", "cy"))}
    images = ", ".join(Path(d.label).name for d in used)
    notes = (
        f"calibrated by qrfield on {_dt.datetime.now(_dt.UTC):%Y-%m-%d %H:%M} UTC from {len(used)} of "
        f"{len(detections)} views ({images}); chessboard {board.label} inner corners, {board.square_mm:g} mm "
        f"squares; RMS reprojection error {rms:.3f} px; OpenCV {cv2.__version__} calibrateCamera, "
        f"distortion {'k1, k2, p1, p2 (k3 fixed at 0)' if fix_k3 else 'k1, k2, p1, p2, k3'}; "
        f"1-sigma fx {std_px['fx']:.2f}, fy {std_px['fy']:.2f}, "
        f"cx {std_px['cx']:.2f}, cy {std_px['cy']:.2f} px"
    )
    geometry: dict[str, Any] = {}
    if stream is not None and stream.size == tuple(size):
        geometry = {key: getattr(stream, key) for key in SENSOR_FIELDS}
        if stream.sensor_crop is not None:
            notes += f"; sensor crop {format_crop(stream.sensor_crop)}" + (
                f" (sensor mode {stream.sensor_mode})" if stream.sensor_mode else ""
            )
        if stream.lens_position is not None:
            notes += f"; lens position {stream.lens_position:g} dioptres"
    try:
        camera = CameraModel(
            fx=K[0, 0],
            fy=K[1, 1],
            cx=K[0, 2],
            cy=K[1, 2],
            width=size[0],
            height=size[1],
            dist=dist.reshape(-1)[:5],
            name=name,
            notes=notes,
            **geometry,
        )
    except ValueError as exc:
        raise CalibrationError(f"the calibration is unusable: {exc}; {_VARY_HINT}", skipped) from None
    coverage = coverage_grid([d.corners_px for d in used], size, cells)
    return CalibrationResult(
        camera, float(rms), tuple(views), tuple(skipped), board, std_px, coverage, tuple(used)
    )


def calibrate_images(
    images: Sequence[str | os.PathLike[str] | np.ndarray],
    board: Board,
    *,
    labels: Sequence[str] | None = None,
    **kwargs: Any,
) -> CalibrationResult:
    """Detect the board in each image (file path or uint8 array) and :func:`calibrate`.

    ``labels`` names array images in messages (default ``view 1``, ``view 2``, ...); paths name
    themselves. Other keyword arguments go to :func:`calibrate`.
    """
    return calibrate(detect_images(images, board, labels=labels), board, **kwargs)


def detect_images(
    images: Sequence[str | os.PathLike[str] | np.ndarray],
    board: Board,
    *,
    labels: Sequence[str] | None = None,
) -> list[BoardDetection]:
    """:func:`detect_board` on each image (file path or uint8 array), in order (see
    :func:`calibrate_images` for ``labels``)."""
    if labels is not None and len(labels) != len(images):
        raise ValueError(f"{len(labels)} labels for {len(images)} images")
    detections = []
    for i, image in enumerate(images):
        label = labels[i] if labels is not None else None
        if isinstance(image, np.ndarray):
            detections.append(detect_board(image, board, label or f"view {i + 1}"))
        else:
            detection = detect_board_file(image, board)
            if label is not None:
                detection = BoardDetection(
                    label, detection.corners_px, detection.image_size, detection.reason, detection.method
                )
            detections.append(detection)
    return detections


# ---------------------------------------------------------------------- one camera?

#: Words of a file or folder name that say which camera of a stereo pair took a view.
SIDE_WORDS = {"left": "left", "right": "right", "l": "left", "r": "right"}
_CAMERA_NUMBER = re.compile(r"(?:^|[^a-z])(?:cam|camera)[-_ ]?(\d+)")
#: A view fits a calibration far worse than the others when its RMS reprojection error is above
#: CLUSTER_FACTOR times the median and above CLUSTER_MIN_PX; CLUSTER_MIN_VIEWS such views, and at
#: least CLUSTER_MIN_SHARE of all, are a cluster: another camera, or another focus or zoom (a
#: single one is a bad view, which :meth:`CalibrationResult.advice` names).
CLUSTER_FACTOR = 3.0
CLUSTER_MIN_PX = 0.3
CLUSTER_MIN_VIEWS = 2
CLUSTER_MIN_SHARE = 0.2
#: When the calibration's RMS is above CLUSTER_MIN_PX, one model may be the compromise of two
#: cameras, which spreads the error over every view instead of leaving a cluster: then models of
#: CLUSTER_SAMPLE_VIEWS views drawn at random (CLUSTER_TRIALS draws, seeded) are tried, and of
#: those that fit their own views within CLUSTER_MIN_PX the one most views agree with (missed by
#: less than CLUSTER_INLIER_PX, or CLUSTER_FACTOR times its own RMS) is refitted on them: when
#: they are at least half the views, fit within CLUSTER_MIN_PX, and miss the others by
#: CLUSTER_FACTOR times that, the others are a cluster.
CLUSTER_SAMPLE_VIEWS = 4
CLUSTER_TRIALS = 40
CLUSTER_INLIER_PX = 0.5


def camera_from_name(label: str) -> str | None:
    """Which camera a view's name says took it: ``left``/``right`` (a word of the file's name, or
    else of its folder's: ``left03.jpg``, ``img_R_03.png``, ``right/03.png``), ``cam1``
    (``cam1_03.png``, ``camera-1/...``), or None when the name says nothing."""
    path = Path(label)
    for part in (path.stem, path.parent.name):
        text = part.lower()
        number = _CAMERA_NUMBER.search(text)
        if number:
            return f"cam{int(number.group(1))}"
        sides = {SIDE_WORDS[word] for word in re.split(r"[^a-z]+", text) if word in SIDE_WORDS}
        if len(sides) == 1:
            return sides.pop()
    return None


def _examples(labels: Sequence[str]) -> str:
    names = [Path(label).name for label in labels]
    return ", ".join(names[:2]) + (", ..." if len(names) > 2 else "")


def mixed_cameras(detections: Sequence[BoardDetection], result: CalibrationResult | None = None) -> list[str]:
    """Why the views seem not all to come from one camera ([] when nothing says so): one model
    from two cameras fits neither. Three signs are looked for:

    - the images have different sizes (a camera delivers one size);
    - their names name two cameras (``left*`` and ``right*``, ``cam0*`` and ``cam1*``: a stereo
      pair, whose two cameras are alike enough to calibrate together with a small error);
    - with ``result``, a cluster of views fits the calibration far worse than the rest
      (:data:`CLUSTER_FACTOR` times the median error and more, at least :data:`CLUSTER_MIN_VIEWS`
      views and :data:`CLUSTER_MIN_SHARE` of them).
    """
    problems = []
    sizes = Counter(d.image_size for d in detections if d.image_size is not None)
    if len(sizes) > 1:
        shown = ", ".join(f"{w}x{h} ({n})" for (w, h), n in sizes.most_common())
        problems.append(f"the images have {len(sizes)} sizes: {shown}")
    groups: dict[str, list[str]] = {}
    for d in detections:
        if d.found:
            name = camera_from_name(d.label)
            if name is not None:
                groups.setdefault(name, []).append(d.label)
    if len(groups) > 1:
        shown = "; ".join(
            f"{name} ({len(labels)}: {_examples(labels)})" for name, labels in sorted(groups.items())
        )
        problems.append(f"their names say {len(groups)} cameras: {shown}")
    if result is not None and result.views:
        median = float(np.median([v.rms_px for v in result.views]))
        far = [v for v in result.views if v.rms_px > max(CLUSTER_FACTOR * median, CLUSTER_MIN_PX)]
        if len(far) >= CLUSTER_MIN_VIEWS and len(far) >= CLUSTER_MIN_SHARE * len(result.views):
            low, high = min(v.rms_px for v in far), max(v.rms_px for v in far)
            problems.append(
                f"{len(far)} of {len(result.views)} views fit the model far worse than the rest "
                f"(RMS {low:.2f}-{high:.2f} px against a median of {median:.2f} px: "
                f"{_examples([v.label for v in far])}): another camera, or another focus or zoom"
            )
        else:
            split = two_camera_split(result)
            if split is not None:
                rms, misses = split
                low, high = min(misses.values()), max(misses.values())
                problems.append(
                    f"{len(misses)} of {len(result.views)} views do not fit the model of the others "
                    f"(which fits them within {rms:.2f} px, against {result.rms_px:.2f} px for all "
                    f"together, and misses these by {low:.2f}-{high:.2f} px: "
                    f"{_examples(list(misses))}): another camera, or another focus or zoom"
                )
    return problems


def _fit(views: Sequence[BoardDetection], board: Board, size: tuple[int, int]) -> tuple[float, Any, Any]:
    """(RMS px, K, dist) of cv2.calibrateCamera on ``views``."""
    objects = [board.object_points() for _ in views]
    images = [d.corners_px.reshape(-1, 1, 2).astype(np.float32) for d in views]
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 50, 1e-9)
    rms, K, dist, _rvecs, _tvecs = cv2.calibrateCamera(objects, images, size, None, None, criteria=criteria)
    return float(rms), K, dist


def _miss(view: BoardDetection, board: Board, K: Any, dist: Any) -> float:
    """RMS px by which the model (K, dist) misses ``view`` at the view's best pose."""
    obj = board.object_points().astype(np.float64)
    corners = view.corners_px.astype(np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, corners, K, dist)
    if not ok:
        return math.inf
    projected, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - corners) ** 2, axis=1))))


def two_camera_split(result: CalibrationResult, seed: int = 0) -> tuple[float, dict[str, float]] | None:
    """The views of ``result`` that another camera seems to have taken (see
    :data:`CLUSTER_SAMPLE_VIEWS`): (the RMS of the others' own model, {label: px it misses it by}),
    or None."""
    views = list(result.detections)
    total = len(views)
    if result.rms_px <= CLUSTER_MIN_PX or total < 2 * CLUSTER_SAMPLE_VIEWS:
        return None
    size, board = result.camera.size, result.board
    rng = np.random.default_rng(seed)
    best: list[int] = []
    for _ in range(CLUSTER_TRIALS):
        sample = sorted(rng.choice(total, CLUSTER_SAMPLE_VIEWS, replace=False).tolist())
        try:
            rms, K, dist = _fit([views[i] for i in sample], board, size)
            if rms > CLUSTER_MIN_PX:  # the draw mixes the cameras too: its model fits nothing well
                continue
            limit = max(CLUSTER_INLIER_PX, CLUSTER_FACTOR * rms)
            agree = [i for i in range(total) if _miss(views[i], board, K, dist) < limit]
        except cv2.error:  # four views too alike to calibrate from: the next draw
            continue
        if len(agree) > len(best):
            best = agree
    try:
        if len(best) < total / 2 or total - len(best) < max(CLUSTER_MIN_VIEWS, CLUSTER_MIN_SHARE * total):
            return None
        rms, K, dist = _fit([views[i] for i in best], board, size)
        if rms > CLUSTER_MIN_PX:
            return None
        misses = {views[i].label: _miss(views[i], board, K, dist) for i in range(total) if i not in best}
    except cv2.error:
        return None
    if float(np.median(list(misses.values()))) < max(CLUSTER_FACTOR * rms, CLUSTER_MIN_PX):
        return None
    return rms, misses
