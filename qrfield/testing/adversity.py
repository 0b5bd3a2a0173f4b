"""The adversity set: seeded views of what a real bench adds to the hard set, one condition a view.

Used by ``qrfield benchmark adversity`` and tests/test_detect_adversity.py (docs/detection.md,
"Adversity"). The hard set (:mod:`qrfield.testing.hardset`) varies the version (1-10), the error
correction, blur, lighting, noise and the lens; a bench adds more. Each view here is drawn by the
hard set's rasteriser (:func:`qrfield.testing.hardset.rasterise`: segno symbols, the exact area
average over each pixel through the pose and the lens, the truth by ``cv2.projectPoints``) with a
base drawn like the hard set's but milder (modules 1.5-6 px, tilt up to 45 degrees from the line
of sight, Gaussian blur 0.3-0.8 px, a lighting ramp up to +-15 %, noise 0-3 grey levels; even
views the pinhole ``picam-v2@640x480``, odd :data:`~qrfield.testing.hardset.DISTORTED_CAMERA`; the
symbol with its quiet zone in view) plus one condition (:data:`CONDITIONS`):

- ``motion``: linear motion blur of 1-6 px in any direction (``cv2.filter2D`` with a line kernel
  symmetric about its centre, after the optics' blur); truth: the corners at mid-exposure;
- ``jpeg``: JPEG compression at quality 25-90 (``cv2.imencode``/``imdecode``, grey), as video
  streams and webcams deliver frames;
- ``version``: QR versions 11-25 (payloads that fill the version at the error level), modules
  1.5-4 px;
- ``inverted``: light modules on a dark card (ISO/IEC 18004 allows reflectance reversal);
- ``mirrored``: the symbol printed mirror-image (its matrix transposed: the finder patterns stay
  where they are, the data is mirrored; any mirror image is a transpose and a turn, and the turn
  is in the pose). The truth is the card's corners, V1 at the finder between the other two,
  clockwise on screen: a mirrored code seen face on;
- ``occluded``: a finger-like dark capsule or a clip-like light one covering 5-20 % of the
  symbol's area, over a finder pattern, over one of the symbol's corners, or anywhere on it;
- ``glare``: a specular spot, a saturated ellipse (the grey levels clipped at 255) on the code;
- ``twins``: two codes of the same size and text side by side (1-3 modules of card between them);
- ``neighbour``: a second, unrelated code printed on the same sheet, its symbol 1-3 modules from
  the first's (inside the first's quiet zone), on a sheet that fills the view.

Each view is a pure function of (condition, seed, index); nothing is stored. Layer 2 (testing):
no import of the pipeline or the stream.
"""

from __future__ import annotations

import math
import string
from dataclasses import dataclass

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, angles_from_rotation, project_points, rotation_matrix, shortest_module_px
from qrfield.testing.hardset import (
    CARD_MARGIN_MODULES,
    DISTORTED_CAMERA,
    QUIET_MODULES,
    _pinhole,
    rasterise,
    symbol_matrix,
    true_corners,
)

#: The conditions, in the order of the report.
CONDITIONS = ("motion", "jpeg", "version", "inverted", "mirrored", "occluded", "glare", "twins", "neighbour")
#: Module sizes of the base (px, facing the camera), drawn log-uniformly; the ``version`` condition's.
MODULE_PX_RANGE = (1.5, 6.0)
VERSION_MODULE_PX_RANGE = (1.5, 4.0)
MAX_TILT_DEG = 45.0
SIDES_MM = (30.0, 50.0, 100.0)
MOTION_PX = (1.0, 6.0)
JPEG_QUALITY = (25, 90)
VERSIONS = (11, 25)
OCCLUDED_SHARE = (0.05, 0.20)


@dataclass(frozen=True)
class Code:
    """One code in a view: true corners V1..V4 (4, 2) px (cv2.projectPoints, distortion included,
    in the code's own vertex order), its pose (marker to camera, mm and degrees), side L (mm),
    text, modules per side, smallest module side (px) and module matrix (n, n) bool as drawn
    (True = dark, row 0 and column 0 at V1; ``mirrored``: transposed)."""

    corners_px: np.ndarray
    pose: Pose
    side_mm: float
    text: str
    modules: int
    module_px: float
    matrix: np.ndarray


@dataclass(frozen=True)
class AdversityView:
    """One view of the adversity set.

    Attributes:
        condition: one of :data:`CONDITIONS`; index: the view's number (with the seed, it makes it).
        image: (H, W) uint8 grey. camera: the camera model (its size is the image's).
        codes: the codes in view, the one the condition is about first (``twins``: both alike).
        detail: the condition's drawn parameters, for the report ("motion 3.2 px at 40 deg").
    """

    condition: str
    index: int
    image: np.ndarray
    camera: CameraModel
    codes: tuple[Code, ...]
    detail: str

    @property
    def code(self) -> Code:
        return self.codes[0]

    @property
    def distorted(self) -> bool:
        return self.camera.has_distortion


def _payload(rng: np.random.Generator, length: int) -> str:
    alphabet = list(string.ascii_letters + string.digits + " -_.:/?=&%+*#")
    return "".join(rng.choice(alphabet, size=length))


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    import cv2

    axis = np.asarray(axis, dtype=np.float64)
    return cv2.Rodrigues(axis / np.linalg.norm(axis) * angle)[0]


def _tilted(rng: np.random.Generator, position: np.ndarray, max_tilt_deg: float) -> np.ndarray:
    """A rotation (marker to camera) whose card normal is within ``max_tilt_deg`` of the line of
    sight to ``position``, any turn about it."""
    gamma = rng.uniform(-180.0, 180.0)
    tilt = math.radians(rng.uniform(0.0, max_tilt_deg))
    phi = rng.uniform(0.0, 2 * math.pi)
    d = position / np.linalg.norm(position)
    axis = np.cross([0.0, 0.0, 1.0], d)
    align = (
        np.eye(3) if np.linalg.norm(axis) < 1e-12 else _rotation(axis, math.acos(float(np.clip(d[2], -1, 1))))
    )
    tilt_r = _rotation(np.array([math.cos(phi), math.sin(phi), 0.0]), tilt)
    return align @ tilt_r @ rotation_matrix([0.0, 0.0, gamma])


def _outline(side_mm: float, modules: int, pad_modules: float) -> np.ndarray:
    """(4, 3) marker-frame corners (mm) of the symbol grown by ``pad_modules`` modules each side."""
    half = side_mm / 2 + pad_modules * side_mm / modules
    return np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])


def _in_view(camera: CameraModel, pose: Pose, points_mm: np.ndarray, margin_px: float = 2.0) -> bool:
    """True when marker-frame ``points_mm`` (k, 3) lie in front of the camera, ``margin_px`` inside
    the image, and the card faces the camera."""
    rot, t = pose.rotation, pose.position_mm
    cam = points_mm @ rot.T + t
    if np.any(cam[:, 2] <= 1.0) or float(rot[:, 2] @ t) <= 0.0:
        return False
    px = project_points(cam, camera)
    w, h = camera.size
    return bool(
        np.all(np.isfinite(px))
        and px[:, 0].min() >= margin_px
        and px[:, 1].min() >= margin_px
        and px[:, 0].max() <= w - 1 - margin_px
        and px[:, 1].max() <= h - 1 - margin_px
    )


def _pose(
    rng: np.random.Generator,
    camera: CameraModel,
    side_mm: float,
    modules: int,
    module_px: tuple[float, float],
    extent_mm: np.ndarray,
    min_module_px: float = 0.0,
) -> Pose:
    """A pose whose facing module is drawn log-uniformly in ``module_px``, anywhere in view with
    ``extent_mm`` (k, 3, marker frame) inside the image, tilted up to MAX_TILT_DEG, its shortest
    foreshortened module at least ``min_module_px``."""
    w, h = camera.size
    for attempt in range(2000):
        low, high = module_px
        if attempt > 500:  # a big code: smaller modules until it fits
            high = max(low, high * 0.5)
        target = math.exp(rng.uniform(math.log(low), math.log(high)))
        z = camera.fx * side_mm / (modules * target)
        x = (rng.uniform(0.0, w) - camera.cx) * z / camera.fx
        y = (rng.uniform(0.0, h) - camera.cy) * z / camera.fy
        position = np.array([x, y, z])
        pose = Pose(position, angles_from_rotation(_tilted(rng, position, MAX_TILT_DEG)))
        if _in_view(camera, pose, extent_mm) and (
            not min_module_px
            or shortest_module_px(true_corners(camera, pose, side_mm), modules) >= min_module_px
        ):
            return pose
    raise ValueError(f"could not place a {side_mm} mm code of {modules} modules in view")


def _finish(
    rng: np.random.Generator, camera: CameraModel, image: np.ndarray, centre: np.ndarray, extent: float
) -> np.ndarray:
    """The base's optics and sensor on a float scene: Gaussian blur 0.3-0.8 px, a lighting ramp up
    to +-15 % across ``extent`` px about ``centre``, noise 0-3 grey levels (not rounded)."""
    import cv2

    blur = float(rng.uniform(0.3, 0.8))
    gradient = float(rng.uniform(0.0, 0.15))
    phi = rng.uniform(0.0, 2 * math.pi)
    noise = float(rng.uniform(0.0, 3.0))
    image = cv2.GaussianBlur(image, (0, 0), sigmaX=blur, borderType=cv2.BORDER_REPLICATE)
    w, h = camera.size
    yy, xx = np.mgrid[0:h, 0:w]
    ramp = ((xx - centre[0]) * math.cos(phi) + (yy - centre[1]) * math.sin(phi)) / max(extent, 1.0)
    image = image * (1.0 + gradient * np.clip(ramp, -1.5, 1.5))
    return image + rng.normal(0.0, noise, image.shape)


def line_kernel(length_px: float, angle_rad: float) -> np.ndarray:
    """(k, k) float32 kernel summing to 1 of a uniform motion over ``length_px`` px along
    ``angle_rad`` (image x towards y), symmetric about its centre pixel (so the image is blurred
    about the mid-exposure position: no shift)."""
    k = 2 * math.ceil(length_px / 2 + 1) + 1
    kernel = np.zeros((k, k), np.float64)
    c = (k - 1) / 2
    steps = max(int(length_px * 40), 1)
    s = (np.arange(steps) + 0.5) / steps - 0.5
    for sign in (1.0, -1.0):  # both halves alike: exactly symmetric
        x = c + sign * s * length_px * math.cos(angle_rad)
        y = c + sign * s * length_px * math.sin(angle_rad)
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = x - x0, y - y0
        for dx, dy, weight in (
            (0, 0, (1 - fx) * (1 - fy)),
            (1, 0, fx * (1 - fy)),
            (0, 1, (1 - fx) * fy),
            (1, 1, fx * fy),
        ):
            np.add.at(kernel, (y0 + dy, x0 + dx), weight)
    return (kernel / kernel.sum()).astype(np.float32)


def _module_to_px(code: Code, camera: CameraModel, uv: np.ndarray) -> np.ndarray:
    """Pixels of module coordinates ``uv`` (k, 2) of ``code`` (V1 = (0, 0), V3 = (n, n))."""
    pitch = code.side_mm / code.modules
    plane = np.column_stack([uv * pitch - code.side_mm / 2, np.zeros(len(uv))])
    return project_points(plane @ code.pose.rotation.T + code.pose.position_mm, camera)


def _capsule_mask(shape: tuple[int, int], a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """(H, W) float coverage in [0, 1] of a capsule (the points within ``radius`` px of segment
    a-b), anti-aliased over a 1 px ramp."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    d = b - a
    t = np.clip(((xx - a[0]) * d[0] + (yy - a[1]) * d[1]) / max(float(d @ d), 1e-9), 0.0, 1.0)
    dist = np.hypot(xx - (a[0] + t * d[0]), yy - (a[1] + t * d[1]))
    return np.clip(radius + 0.5 - dist, 0.0, 1.0)


def _symbol_area_px(corners: np.ndarray) -> float:
    x, y = corners[:, 0], corners[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


def adversity_view(condition: str, index: int, seed: int = 3031) -> AdversityView:
    """View ``index`` of ``condition`` (one of :data:`CONDITIONS`) with ``seed``: the same view every time."""
    import cv2

    if condition not in CONDITIONS:
        raise ValueError(f"unknown condition {condition!r}; choose from {', '.join(CONDITIONS)}")
    rng = np.random.default_rng([seed, 5_003_011, CONDITIONS.index(condition), index])
    camera = DISTORTED_CAMERA if index % 2 else _pinhole()
    side = float(SIDES_MM[int(rng.integers(len(SIDES_MM)))])
    level = "LMQH"[int(rng.integers(4))]
    if condition == "version":
        matrix, text = _long_symbol(rng, level)
        module_range = VERSION_MODULE_PX_RANGE
    else:
        text = _payload(rng, round(math.exp(rng.uniform(math.log(5), math.log(120)))))
        matrix, _ = symbol_matrix(text, level)
        module_range = MODULE_PX_RANGE
    n = matrix.shape[0]
    light = float(rng.uniform(170.0, 240.0))
    dark = float(rng.uniform(10.0, 70.0))
    background = float(rng.uniform(40.0, 200.0))
    detail = ""
    extent = _outline(side, n, QUIET_MODULES)
    if condition == "twins":
        gap = float(rng.uniform(1.0, 3.0))  # modules of card between the two cards
        step = side + (2 * (QUIET_MODULES + CARD_MARGIN_MODULES) + gap) * side / n
        extent = np.concatenate([extent, extent + np.array([step, 0.0, 0.0])])
        detail = f"gap {gap:.1f} modules"
    second = None
    if condition == "neighbour":
        text2 = _payload(rng, int(rng.integers(5, 60)))
        matrix2, _ = symbol_matrix(text2, "LMQH"[int(rng.integers(4))])
        n2 = matrix2.shape[0]
        side2 = side * float(rng.uniform(0.5, 1.0))
        gap = float(rng.uniform(1.0, 3.0))  # modules of the first code between the two symbols
        offset = np.array([side / 2 + gap * side / n + side2 / 2, rng.uniform(-0.5, 0.5) * side, 0.0])
        turn = 90.0 * int(rng.integers(4))
        second = (text2, matrix2, n2, side2, offset, turn)
        extent = np.concatenate([extent, _outline(side2, n2, 1.0) + offset])
        background = light  # one sheet of paper filling the view
        detail = f"gap {gap:.1f} modules, side {side2 / side:.2f} of the first"
    least = VERSION_MODULE_PX_RANGE[0] if condition == "version" else 0.0
    pose = _pose(rng, camera, side, n, module_range, extent, least)
    if condition == "mirrored":
        matrix = matrix.T
    if condition == "inverted":
        light, dark = dark, light
    scene = rasterise(camera, pose, side, matrix, background, light, dark)
    corners = true_corners(camera, pose, side)
    codes = [Code(corners, pose, side, text, n, shortest_module_px(corners, n), matrix)]
    if condition == "twins":
        rot = pose.rotation
        pose2 = Pose(pose.position_mm + rot[:, 0] * step, pose.angles_deg)
        card = rasterise(camera, pose2, side, matrix, background, light, dark)
        # (the rasteriser's grey levels are float32: outside the card it is the background to
        # 1e-5, not exactly; an exact test drew the second card's bounding box over the first)
        drawn = np.abs(card - background) > 1e-3
        scene[drawn] = card[drawn]
        corners2 = true_corners(camera, pose2, side)
        codes.append(Code(corners2, pose2, side, text, n, shortest_module_px(corners2, n), matrix))
    if second is not None:
        text2, matrix2, n2, side2, offset, turn = second
        rot = pose.rotation
        rot2 = rot @ rotation_matrix([0.0, 0.0, turn])
        pose2 = Pose(pose.position_mm + rot @ offset, angles_from_rotation(rot2))
        ink = rasterise(camera, pose2, side2, matrix2, light, light, dark)
        scene = scene * (ink / light)  # printed on the same sheet: its ink darkens what is under
        corners2 = true_corners(camera, pose2, side2)
        codes.append(Code(corners2, pose2, side2, text2, n2, shortest_module_px(corners2, n2), matrix2))
    h, w = scene.shape
    code = codes[0]
    if condition == "occluded":
        scene, detail = _occlude(rng, scene, code, camera)
    glare = None
    if condition == "glare":
        glare, detail = _glare(rng, (h, w), code)
    if condition == "motion":
        length = float(rng.uniform(*MOTION_PX))
        angle = float(rng.uniform(0.0, math.pi))
        scene = cv2.filter2D(scene, -1, line_kernel(length, angle), borderType=cv2.BORDER_REPLICATE)
        detail = f"motion {length:.1f} px at {math.degrees(angle):.0f} deg"
    all_corners = np.concatenate([c.corners_px for c in codes])
    extent_px = max(float(np.ptp(all_corners, axis=0).max()), 1.0)
    image = _finish(rng, camera, scene, all_corners.mean(axis=0), extent_px)
    if glare is not None:
        image = image + glare
    image = np.clip(np.round(image), 0, 255).astype(np.uint8)
    if condition == "jpeg":
        quality = int(rng.integers(JPEG_QUALITY[0], JPEG_QUALITY[1] + 1))
        ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if not ok:
            raise RuntimeError("cv2.imencode failed")
        image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
        detail = f"quality {quality}"
    if condition == "version":
        detail = f"version {(n - 17) // 4}, {len(text)} bytes"
    if condition == "inverted":
        detail = "light modules on dark"
    if condition == "mirrored":
        detail = "mirror image (transposed)"
    image.setflags(write=False)
    for c in codes:
        c.corners_px.setflags(write=False)
    return AdversityView(condition, index, image, camera, tuple(codes), detail)


def _long_symbol(rng: np.random.Generator, level: str) -> tuple[np.ndarray, str]:
    """A symbol of a version drawn uniformly in VERSIONS at error level ``level`` (lowered until
    the version holds the payload), its payload 60-100 % of the version's byte capacity."""
    import segno

    version = int(rng.integers(VERSIONS[0], VERSIONS[1] + 1))
    low, high = 1, 3000  # the longest payload (bytes) the version holds at this level: bisection
    probe = _payload(rng, high)
    while high - low > 1:
        mid = (low + high) // 2
        try:
            segno.make(probe[:mid], error=level, version=version, micro=False, boost_error=False)
            low = mid
        except segno.DataOverflowError:
            high = mid
    length = int(rng.integers(max(int(0.6 * low), 1), low + 1))
    text = _payload(rng, length)
    qr = segno.make(text, error=level, version=version, micro=False, boost_error=False)
    return np.array(qr.matrix, dtype=bool), text


def _occlude(
    rng: np.random.Generator, scene: np.ndarray, code: Code, camera: CameraModel
) -> tuple[np.ndarray, str]:
    """A finger (a dark capsule, grey 30-110) or a clip (a light one, 215-250) over 5-20 % of the
    symbol: over a finder pattern, over one of the symbol's corners (V1..V4), or anywhere on it."""
    n = code.modules
    share = float(rng.uniform(*OCCLUDED_SHARE))
    where = ("finder", "corner", "anywhere")[int(rng.integers(3))]
    finger = bool(rng.random() < 0.6)
    aspect = float(rng.uniform(2.0, 4.0)) if finger else float(rng.uniform(1.0, 2.0))
    if where == "finder":
        centre_uv = np.array([[3.5, 3.5], [n - 3.5, 3.5], [3.5, n - 3.5]])[int(rng.integers(3))]
    elif where == "corner":
        centre_uv = np.array([[0.0, 0.0], [n, 0.0], [n, n], [0.0, n]])[int(rng.integers(4))]
    else:
        centre_uv = rng.uniform(0.2 * n, 0.8 * n, 2)
    centre = _module_to_px(code, camera, centre_uv[None])[0]
    area = share * _symbol_area_px(code.corners_px)
    if where == "corner":
        area *= 4.0  # a quarter of a blob centred on the corner lies on the symbol (about)
    # A capsule of radius r and straight length l = 2 r (aspect - 1): area pi r^2 + 2 r l.
    radius = math.sqrt(area / (math.pi + 4.0 * (aspect - 1.0)))
    half = radius * (aspect - 1.0)
    phi = rng.uniform(0.0, math.pi)
    direction = np.array([math.cos(phi), math.sin(phi)])
    mask = _capsule_mask(scene.shape, centre - half * direction, centre + half * direction, radius)
    grey = float(rng.uniform(30.0, 110.0)) if finger else float(rng.uniform(215.0, 250.0))
    kind = "finger" if finger else "clip"
    return scene * (1.0 - mask) + grey * mask, f"{kind} over {where}, {100 * share:.0f} %"


def _glare(rng: np.random.Generator, shape: tuple[int, int], code: Code) -> tuple[np.ndarray, str]:
    """(H, W) grey levels to add: an elliptical specular spot on the symbol, a Gaussian profile of
    peak 300-600 (the core saturates at 255), radii 8-25 % of the symbol's side."""
    h, w = shape
    corners = code.corners_px
    side_px = math.sqrt(_symbol_area_px(corners))
    weights = rng.dirichlet(np.ones(4))
    centre = weights @ corners
    a = side_px * float(rng.uniform(0.08, 0.25))
    b = a * float(rng.uniform(0.4, 1.0))
    phi = rng.uniform(0.0, math.pi)
    peak = float(rng.uniform(300.0, 600.0))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    dx, dy = xx - centre[0], yy - centre[1]
    u = (dx * math.cos(phi) + dy * math.sin(phi)) / a
    v = (-dx * math.sin(phi) + dy * math.cos(phi)) / b
    return peak * np.exp(-0.5 * (u * u + v * v)), f"spot {a:.0f}x{b:.0f} px, peak {peak:.0f}"


def adversity_views(condition: str, count: int, seed: int = 3031, start: int = 0):
    """Views ``start`` .. ``start + count - 1`` of ``condition`` (see :func:`adversity_view`)."""
    for index in range(start, start + count):
        yield adversity_view(condition, index, seed)
