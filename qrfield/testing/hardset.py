"""The hard set: seeded views of QR codes whose truth does not come from qrfield's renderer.

Used by ``qrfield benchmark detect`` and ``pose`` (``qrfield benchmark hardset`` describes it) and
by the detector's and the pipeline's tests.

Why: a bench made with our own renderer and one payload was too kind (docs/detection.md). Here
every piece of the picture is made another way than :mod:`qrfield.render`:

- the symbol: encoded by segno (a different encoder from OpenCV's QRCodeEncoder, so the module
  layouts, masks and versions differ), payloads of 5 to 200 printable ASCII bytes, error correction
  L, M, Q or H, versions 1 to 10;
- the picture: each camera pixel is the area average of the card over the pixel, estimated by
  233 point samples on a Fibonacci lattice (a pixel wholly inside one module is evaluated once):
  every sample is mapped back onto the card plane through the pose (a ray-plane intersection)
  and the lens (OpenCV's iterative undistortion, to 1e-10, at the pixel corners, bilinear within
  the pixel), then looked up in the module matrix. No texture, no warp, no resampling;
- the truth: the corners V1..V4 (docs/conventions.md) projected by ``cv2.projectPoints`` with the
  lens' distortion.

Then a Gaussian blur (sigma 0.3-1.2 px), a linear lighting gradient (up to +-25 % across the code,
any direction), Gaussian noise (0-4 grey levels) and rounding to uint8. Cameras: the pinhole
``picam-v2@640x480`` and :data:`DISTORTED_CAMERA` (the lens of tests/solver_cases.DISTORTED).
Codes of 30, 50 and 100 mm at z 150-1000 mm, tilted up to 60 degrees from the line of sight.

Each view is a pure function of (seed, index): the set is rebuilt the same every time (about 50 ms
a view), so nothing is stored.
"""

from __future__ import annotations

import functools
import math
import string
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, marker_vertices, shortest_module_px

#: A lens with visible barrel distortion (k1, k2, p1, p2, k3), typical of a wide Pi camera; the
#: solver tests use it too (tests/solver_cases.DISTORTED).
DISTORTED_CAMERA = CameraModel(
    fx=530.0,
    fy=528.0,
    cx=322.0,
    cy=236.5,
    width=640,
    height=480,
    dist=np.array([-0.28, 0.09, 0.0012, -0.0008, -0.012]),
    name="test-distorted",
)
#: The pinhole camera of the set.
PINHOLE_CAMERA_SPEC = "picam-v2@640x480"
#: QR symbol sides of the set, mm.
SIDES_MM = (30.0, 50.0, 100.0)
Z_RANGE_MM = (150.0, 1000.0)
MAX_TILT_DEG = 60.0
#: Range of module sizes (px, facing the camera) the views are drawn from, log-uniformly.
MODULE_PX_RANGE = (0.8, 10.0)
PAYLOAD_BYTES = (5, 200)
MAX_VERSION = 10
#: Point samples per pixel (a Fibonacci lattice).
SUPERSAMPLE = 233
#: Quiet zone and white card margin around the symbol, modules.
QUIET_MODULES = 4
CARD_MARGIN_MODULES = 2
#: Module size bands of the report, px (the smallest module side of the view, see HardView.module_px).
BANDS = (("< 2 px", 0.0, 2.0), ("2-3 px", 2.0, 3.0), (">= 3 px", 3.0, math.inf))


@dataclass(frozen=True)
class HardView:
    """One view of the hard set.

    Attributes:
        index: the view's number in the set (with the seed, it makes the view).
        image: (H, W) uint8 grey.
        corners_px: (4, 2) exact pixels of V1..V4 (cv2.projectPoints, distortion included).
        camera, side_mm, pose: the camera model, the symbol's side L (mm), the true pose.
        text: the payload; version: QR version 1..10; modules: modules per side (17 + 4 version).
        module_px: the view's smallest module side in px (the shortest side of V1..V4 over modules).
        noise, blur_px, gradient: grey-level noise sigma, blur sigma (px), lighting gradient (share).
    """

    index: int
    image: np.ndarray
    corners_px: np.ndarray
    camera: CameraModel
    side_mm: float
    pose: Pose
    text: str
    version: int
    modules: int
    module_px: float
    noise: float
    blur_px: float
    gradient: float

    @property
    def distorted(self) -> bool:
        return self.camera.has_distortion

    @property
    def band(self) -> str:
        """The module size band's label (BANDS)."""
        return band_of(self.module_px)


def band_of(module_px: float) -> str:
    """Label of the module size band (BANDS) holding ``module_px``."""
    for label, low, high in BANDS:
        if low <= module_px < high:
            return label
    return BANDS[-1][0]


@functools.lru_cache(maxsize=4)
def _pinhole() -> CameraModel:
    from qrfield.camera import resolve_camera

    return resolve_camera(PINHOLE_CAMERA_SPEC)


def symbol_matrix(text: str, error: str, max_version: int = MAX_VERSION) -> tuple[np.ndarray, int]:
    """(n, n) bool module matrix (True = dark, no quiet zone) and version of ``text`` encoded by segno.

    The error level is lowered (H, Q, M, L) until the symbol fits ``max_version``; ValueError if
    even L does not.
    """
    import segno

    levels = "LMQH"
    for level in reversed(levels[: levels.index(error.upper()) + 1]):
        qr = segno.make(text, error=level, micro=False, boost_error=False)
        if qr.version <= max_version:
            return np.array(qr.matrix, dtype=bool), int(qr.version)
    raise ValueError(f"a {len(text)}-byte text does not fit QR version {max_version}")


def _payload(rng: np.random.Generator) -> str:
    low, high = PAYLOAD_BYTES
    length = round(math.exp(rng.uniform(math.log(low), math.log(high))))
    alphabet = string.ascii_letters + string.digits + " -_.:/?=&%+*#"
    return "".join(rng.choice(list(alphabet), size=length))


def _undistorted_normalised(camera: CameraModel, pts: np.ndarray) -> np.ndarray:
    """Normalised ideal image coordinates (x/z, y/z) of pixels ``pts`` (k, 2), to 1e-10."""
    import cv2

    if not camera.has_distortion:
        return np.column_stack([(pts[:, 0] - camera.cx) / camera.fx, (pts[:, 1] - camera.cy) / camera.fy])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    src = pts.reshape(-1, 1, 2).astype(np.float64)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x
        out = cv2.undistortPointsIter(src, camera.K, camera.dist, None, None, criteria)
    else:  # OpenCV 5
        out = cv2.undistortPoints(src, camera.K, camera.dist, R=None, P=None, criteria=criteria)
    return out.reshape(-1, 2)


def rasterise(
    camera: CameraModel,
    pose: Pose,
    side_mm: float,
    matrix: np.ndarray,
    background: float,
    light: float,
    dark: float,
    supersample: int = SUPERSAMPLE,
) -> np.ndarray:
    """(H, W) float image of the card: the exact area average over each pixel (point-sampled).

    Module (c, r) (column, row of ``matrix``) covers marker x in [-L/2 + c L/n, -L/2 + (c+1) L/n],
    y likewise (docs/conventions.md: +X from V1 to V2, +Y from V1 to V4). The card (quiet zone and
    margin) is ``light``, dark modules ``dark``, the rest of the scene ``background``.
    """
    n = matrix.shape[0]
    pitch = side_mm / n
    pad = QUIET_MODULES + CARD_MARGIN_MODULES
    rot = pose.rotation
    t = pose.position_mm
    # Plane (x, y, 1) -> camera ray; its inverse takes a normalised ray back to the plane.
    plane_to_ray = np.column_stack([rot[:, 0], rot[:, 1], t])
    ray_to_plane = np.linalg.inv(plane_to_ray)
    # Card extent in pixels, for the region to render.
    half = side_mm / 2 + pad * pitch
    edge = np.linspace(-half, half, 33)
    outline = np.concatenate(
        [np.column_stack([edge, np.full_like(edge, s)]) for s in (-half, half)]
        + [np.column_stack([np.full_like(edge, s), edge]) for s in (-half, half)]
    )
    from qrfield.geometry import project_points

    card_px = project_points(outline @ rot[:, :2].T + t, camera)
    w, h = camera.size
    x0 = max(math.floor(card_px[:, 0].min()) - 2, 0)
    y0 = max(math.floor(card_px[:, 1].min()) - 2, 0)
    x1 = min(math.ceil(card_px[:, 0].max()) + 3, w)
    y1 = min(math.ceil(card_px[:, 1].max()) + 3, h)
    image = np.full((h, w), float(background))
    if x1 <= x0 or y1 <= y0:
        return image
    # Module coordinates (u, v) of the pixel corners (the lens is exact here).
    gx, gy = np.meshgrid(np.arange(x0, x1 + 1) - 0.5, np.arange(y0, y1 + 1) - 0.5)
    ray = _undistorted_normalised(camera, np.column_stack([gx.ravel(), gy.ravel()]))
    plane = np.column_stack([ray, np.ones(len(ray))]) @ ray_to_plane.T
    uv = plane[:, :2] / plane[:, 2:3] / pitch + n / 2.0
    uv = uv.reshape(y1 - y0 + 1, x1 - x0 + 1, 2)

    padded = np.pad(matrix, pad + 1, constant_values=False)
    # Grey level of each module cell: dark modules, the card (quiet zone and margin), and the
    # background in the outermost ring (clipping sends everything beyond the card there).
    cell_grey = np.where(padded, dark, light).astype(np.float32)
    cell_grey[0, :] = cell_grey[-1, :] = cell_grey[:, 0] = cell_grey[:, -1] = background
    m = padded.shape[0]
    flat_grey = cell_grey.ravel()

    def level(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        c = np.clip(np.floor(u).astype(np.int32) + (pad + 1), 0, m - 1)
        r = np.clip(np.floor(v).astype(np.int32) + (pad + 1), 0, m - 1)
        return flat_grey[r * m + c]

    corner_cells = np.floor(uv).astype(np.int64)
    cells = [corner_cells[:-1, :-1], corner_cells[:-1, 1:], corner_cells[1:, :-1], corner_cells[1:, 1:]]
    uniform = np.ones(cells[0].shape[:2], dtype=bool)
    for other in cells[1:]:
        uniform &= np.all(other == cells[0], axis=-1)
    centre = 0.25 * (uv[:-1, :-1] + uv[:-1, 1:] + uv[1:, :-1] + uv[1:, 1:])
    region = level(centre[..., 0], centre[..., 1]).astype(np.float64)
    rows, cols = np.nonzero(~uniform)
    sx, sy = _lattice(supersample)
    uv32 = uv.astype(np.float32)
    for chunk in range(0, len(rows), 4096):
        r, c = rows[chunk : chunk + 4096], cols[chunk : chunk + 4096]
        # Bilinear within the pixel between its corners' module coordinates: a homography (and
        # the lens map) differs from it by second-order terms, below 1e-4 px at these scales.
        c00, c10, c01, c11 = uv32[r, c], uv32[r, c + 1], uv32[r + 1, c], uv32[r + 1, c + 1]
        dx, dy, twist = c10 - c00, c01 - c00, c11 - c10 - c01 + c00
        u = c00[:, :1] + sx * dx[:, :1] + sy * dy[:, :1] + (sx * sy) * twist[:, :1]
        v = c00[:, 1:] + sx * dx[:, 1:] + sy * dy[:, 1:] + (sx * sy) * twist[:, 1:]
        region[r, c] = level(u, v).mean(axis=1)
    image[y0:y1, x0:x1] = region
    return image


@functools.lru_cache(maxsize=4)
def _lattice(count: int) -> tuple[np.ndarray, np.ndarray]:
    """(1, count) x and y in [0, 1) of a Fibonacci lattice of ``count`` points (a Fibonacci number).

    Every column and every row of a count x count grid holds exactly one point, so an edge along a
    pixel axis is resolved to 1/count px (a square grid of the same size resolves it to only
    1/sqrt(count) px), and edges at any other angle about as well.
    """
    fib = [1, 1]
    while fib[-1] < count:
        fib.append(fib[-1] + fib[-2])
    if fib[-1] != count:
        raise ValueError(f"the lattice needs a Fibonacci number of points, got {count}")
    k = np.arange(count)
    x = (k + 0.5) / count
    y = ((k * fib[-2]) % count + 0.5) / count
    return x[None, :].astype(np.float32), y[None, :].astype(np.float32)


def true_corners(camera: CameraModel, pose: Pose, side_mm: float) -> np.ndarray:
    """(4, 2) pixels of the corners V1..V4 of a code of ``side_mm`` at ``pose``, by
    ``cv2.projectPoints`` with the lens' distortion: the set's truth."""
    import cv2

    rvec = cv2.Rodrigues(pose.rotation)[0]
    projected, _ = cv2.projectPoints(marker_vertices(side_mm), rvec, pose.position_mm, camera.K, camera.dist)
    return projected.reshape(4, 2)


def _card(rng: np.random.Generator, index: int) -> tuple[CameraModel, float, str, np.ndarray, int]:
    """A view's camera (even ``index`` pinhole, odd :data:`DISTORTED_CAMERA`) and card drawn from
    ``rng`` in this order: the side (SIDES_MM, mm), the payload, the error level; the symbol's
    matrix and version (:func:`symbol_matrix`)."""
    camera = DISTORTED_CAMERA if index % 2 else _pinhole()
    side = float(SIDES_MM[int(rng.integers(len(SIDES_MM)))])
    text = _payload(rng)
    matrix, version = symbol_matrix(text, "LMQH"[int(rng.integers(4))])
    return camera, side, text, matrix, version


def hard_view(index: int, seed: int = 2024) -> HardView:
    """View ``index`` of the hard set with ``seed``: the same view every time."""
    from qrfield.sampling import random_visible_poses

    rng = np.random.default_rng([seed, index])
    camera, side, text, matrix, version = _card(rng, index)
    n = matrix.shape[0]
    # Stratified by module size (log-uniform over MODULE_PX_RANGE) so that every band is well
    # filled; the distance follows from it and must lie in Z_RANGE_MM (else another draw).
    while True:
        target = math.exp(rng.uniform(*np.log(MODULE_PX_RANGE)))
        z = camera.fx * side / (n * target)
        if Z_RANGE_MM[0] <= z <= Z_RANGE_MM[1]:
            break
    pose = random_visible_poses(
        camera,
        side,
        1,
        seed=int(rng.integers(2**31)),
        z_range_mm=(z, z),
        max_tilt_deg=MAX_TILT_DEG,
        tilt_from="line_of_sight",
    )[0]
    image, corners, noise, blur, gradient = _picture(rng, camera, pose, side, matrix)
    return HardView(
        index,
        image,
        corners,
        camera,
        side,
        pose,
        text,
        version,
        n,
        shortest_module_px(corners, n),
        noise,
        blur,
        gradient,
    )


def _picture(
    rng: np.random.Generator, camera: CameraModel, pose: Pose, side: float, matrix: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """The view of one card: (image (H, W) uint8, true corners (4, 2), noise sigma, blur sigma px,
    lighting gradient): grey levels, blur, lighting ramp and noise drawn from ``rng`` in this order."""
    import cv2

    light = float(rng.uniform(170.0, 240.0))
    dark = float(rng.uniform(10.0, 70.0))
    background = float(rng.uniform(40.0, 200.0))
    noise = float(rng.uniform(0.0, 4.0))
    blur = float(rng.uniform(0.3, 1.2))
    gradient = float(rng.uniform(0.0, 0.25))
    phi = rng.uniform(0.0, 2 * math.pi)
    image = rasterise(camera, pose, side, matrix, background, light, dark)
    image = cv2.GaussianBlur(image, (0, 0), sigmaX=blur, borderType=cv2.BORDER_REPLICATE)
    corners = true_corners(camera, pose, side)
    # Lighting: a linear ramp in direction phi, +-gradient across the code's extent.
    w, h = camera.size
    centre = corners.mean(axis=0)
    extent = max(float(np.ptp(corners, axis=0).max()), 1.0)
    yy, xx = np.mgrid[0:h, 0:w]
    ramp = ((xx - centre[0]) * math.cos(phi) + (yy - centre[1]) * math.sin(phi)) / extent
    image = image * (1.0 + gradient * np.clip(ramp, -1.5, 1.5))
    image = image + rng.normal(0.0, noise, image.shape) if noise > 0 else image
    image = np.clip(np.round(image), 0, 255).astype(np.uint8)
    image.setflags(write=False)
    corners.setflags(write=False)
    return image, corners, noise, blur, gradient


#: The steep set (docs/benchmarks.md, "detect"): codes tilted about both X and Y, alpha and beta
#: each up to this (deg), at z in STEEP_Z_RANGE_MM (mm), anywhere in view: foreshortened modules of
#: 1-2 px along the code's short side where the other side's are 2-4 px.
STEEP_TILT_DEG = 55.0
STEEP_Z_RANGE_MM = (150.0, 600.0)


def steep_view(index: int, seed: int = 2026) -> HardView:
    """View ``index`` of the steep set with ``seed`` (the same view every time): a segno symbol as in
    the hard set (30/50/100 mm, versions 1-10), alpha and beta uniform in +-STEEP_TILT_DEG and gamma
    over the full turn (R = Rx Ry Rz, docs/conventions.md), z uniform in STEEP_Z_RANGE_MM, the
    symbol and its quiet zone in view; drawn, blurred, lit and noised like the hard set's views
    (even indices pinhole, odd the distorted lens). ``module_px`` is the foreshortened module along
    the code's shortest side."""
    from qrfield.visibility import view_of

    rng = np.random.default_rng([seed, 7_000_001, index])
    camera, side, text, matrix, version = _card(rng, index)
    n = matrix.shape[0]
    quiet_side = side * (n + 2 * QUIET_MODULES) / n  # the symbol with its quiet zone
    w, h = camera.size
    while True:
        z = float(rng.uniform(*STEEP_Z_RANGE_MM))
        x = (rng.uniform(-0.5, 0.5) * w + w / 2 - 0.5 - camera.cx) * z / camera.fx
        y = (rng.uniform(-0.5, 0.5) * h + h / 2 - 0.5 - camera.cy) * z / camera.fy
        angles = (
            float(rng.uniform(-STEEP_TILT_DEG, STEEP_TILT_DEG)),
            float(rng.uniform(-STEEP_TILT_DEG, STEEP_TILT_DEG)),
            float(rng.uniform(-180.0, 180.0)),
        )
        pose = Pose(np.array([x, y, z]), angles)
        if bool(view_of(camera, quiet_side, pose.rotation, pose.position_mm, margin_px=2.0).in_view):
            break
    image, corners, noise, blur, gradient = _picture(rng, camera, pose, side, matrix)
    small = shortest_module_px(corners, n)
    return HardView(index, image, corners, camera, side, pose, text, version, n, small, noise, blur, gradient)


def steep_views(count: int, seed: int = 2026, start: int = 0) -> Iterator[HardView]:
    """Views ``start`` .. ``start + count - 1`` of the steep set (see :func:`steep_view`)."""
    for index in range(start, start + count):
        yield steep_view(index, seed)


#: The camera of the frames with several codes, its grid of cells (columns, rows) and the codes' side.
MULTI_CAMERA_SPEC = "webcam-60@1280x720"
MULTI_GRID = (4, 2)
MULTI_SIDE_MM = 40.0


@dataclass(frozen=True)
class MultiView:
    """A frame holding several codes (:func:`multi_view`): image (H, W) uint8 grey; per code its
    true corners V1..V4 (4, 2) px, text, modules per side and smallest module side (px)."""

    image: np.ndarray
    camera: CameraModel
    corners_px: tuple[np.ndarray, ...]
    texts: tuple[str, ...]
    modules: tuple[int, ...]
    module_px: tuple[float, ...]


def multi_view(index: int, count: int, seed: int = 2024) -> MultiView:
    """Frame ``index`` with ``count`` codes (1 .. 8, the cells of a MULTI_GRID over the view, in a
    seeded order), each a segno symbol of 5-60 bytes and MULTI_SIDE_MM at z 330-420 mm, tilted up
    to 35 deg from the line of sight, any in-plane turn, drawn by :func:`rasterise` (the cards do
    not overlap) on one background, then one blur (0.4-0.9 px) and noise (0-3 grey levels)."""
    import cv2

    from qrfield.camera import resolve_camera
    from qrfield.geometry import angles_from_rotation
    from qrfield.sampling import _align_z, random_tilted_rotation

    columns, rows = MULTI_GRID
    if not 1 <= count <= columns * rows:
        raise ValueError(f"a frame holds 1 to {columns * rows} codes, got {count}")

    camera = resolve_camera(MULTI_CAMERA_SPEC)
    rng = np.random.default_rng([seed, 9_000_011, index, count])
    light, dark = float(rng.uniform(180.0, 235.0)), float(rng.uniform(15.0, 60.0))
    background = float(rng.uniform(60.0, 160.0))
    image = np.full((camera.height, camera.width), background)
    w, h = camera.size
    corners, texts, modules, module_px = [], [], [], []
    for cell in rng.permutation(columns * rows)[:count]:
        column, row = divmod(int(cell), rows)
        length = int(rng.integers(5, 61))
        text = "".join(rng.choice(list(string.ascii_letters + string.digits), length))
        matrix, _ = symbol_matrix(text, "LMQH"[int(rng.integers(4))])
        z = float(rng.uniform(330.0, 420.0))
        u = (column + 0.5 + rng.uniform(-0.1, 0.1)) * w / columns
        v = (row + 0.5 + rng.uniform(-0.1, 0.1)) * h / rows
        position = np.array([(u - camera.cx) * z / camera.fx, (v - camera.cy) * z / camera.fy, z])
        rotation = _align_z(position) @ random_tilted_rotation(rng, 35.0)
        pose = Pose(position, angles_from_rotation(rotation))
        card = rasterise(camera, pose, MULTI_SIDE_MM, matrix, background, light, dark)
        drawn = card != background
        image[drawn] = card[drawn]
        true = true_corners(camera, pose, MULTI_SIDE_MM)
        corners.append(true)
        texts.append(text)
        modules.append(matrix.shape[0])
        module_px.append(shortest_module_px(true, matrix.shape[0]))
    blur = float(rng.uniform(0.4, 0.9))
    image = cv2.GaussianBlur(image, (0, 0), sigmaX=blur, borderType=cv2.BORDER_REPLICATE)
    image = np.clip(np.round(image + rng.normal(0.0, float(rng.uniform(0.0, 3.0)), image.shape)), 0, 255)
    out = image.astype(np.uint8)
    out.setflags(write=False)
    return MultiView(out, camera, tuple(corners), tuple(texts), tuple(modules), tuple(module_px))


def hard_views(count: int, seed: int = 2024, start: int = 0) -> Iterator[HardView]:
    """Views ``start`` .. ``start + count - 1`` of the hard set (even indices pinhole, odd distorted)."""
    for index in range(start, start + count):
        yield hard_view(index, seed)


def hard_sequence(index: int, frames: int = 60, seed: int = 2024) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """A moving card drawn like the set's views: ``frames`` (image (H, W) uint8, true corners V1..V4
    (4, 2) px) of sequence ``index`` (even pinhole, odd the distorted lens), a pure function of
    (seed, index).

    The card (a payload of 5-80 bytes, a side of 50-100 mm) slides about 100 mm across the view,
    moves 50 mm in depth about z 260-420 mm and turns 90 degrees about its normal while it tilts by
    up to 35 degrees: a few pixels a frame, as a hand-held card at 30 frames a second. Blur 0.6 px,
    noise 2 grey levels. For the tracker, which the independent views do not exercise.
    """
    import cv2

    rng = np.random.default_rng([seed, 1_000_003, index])
    camera = DISTORTED_CAMERA if index % 2 else _pinhole()
    text = "".join(
        rng.choice(list(string.ascii_letters + string.digits + " /:.?="), int(rng.integers(5, 81)))
    )
    matrix, _ = symbol_matrix(text, "LMQH"[int(rng.integers(4))])
    side = float(rng.uniform(50.0, 100.0))
    z0 = float(rng.uniform(300.0, 370.0))
    phase = rng.uniform(0.0, 2 * math.pi, 3)
    turn = 1.0 if rng.random() < 0.5 else -1.0
    light, dark, background = (
        float(rng.uniform(190.0, 230.0)),
        float(rng.uniform(20.0, 50.0)),
        float(rng.uniform(60.0, 160.0)),
    )
    noise = np.random.default_rng([seed, 1_000_033, index])
    for i in range(frames):
        s = i / max(frames - 1, 1)
        position = [
            -50.0 + 100.0 * s,
            -20.0 + 30.0 * s + 10.0 * math.sin(phase[0] + 4 * s),
            z0 + 50.0 * math.sin(3 * s + phase[1]),
        ]
        angles = [15.0 * math.sin(5 * s + phase[2]), -20.0 + 35.0 * s, 30.0 + 90.0 * s * turn]
        pose = Pose(position, angles)
        image = rasterise(camera, pose, side, matrix, background, light, dark)
        image = cv2.GaussianBlur(image, (0, 0), sigmaX=0.6, borderType=cv2.BORDER_REPLICATE)
        image = np.clip(np.round(image + noise.normal(0.0, 2.0, image.shape)), 0, 255).astype(np.uint8)
        yield image, true_corners(camera, pose, side)
