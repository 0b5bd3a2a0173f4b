"""View sets for ``qrfield benchmark pose``: seeded views with their truth, and the cameras they use.

A view set is a function ``(count, seed) -> list[BenchView]`` registered in :data:`VIEW_SETS`; the
bench takes its name (``--view-set``), so that another set (a harder one built elsewhere, another
renderer) drops in without touching the bench. Truth is independent of the code under test: the
pose is drawn first, its corners are the exact projections of the vertices (docs/conventions.md),
and the image is rendered by :func:`qrfield.render.render_view` from that pose.
"""

from __future__ import annotations

import math
import string
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from qrfield.camera import CameraModel, resolve_camera
from qrfield.geometry import Pose
from qrfield.testing.hardset import DISTORTED_CAMERA

#: The lens with visible barrel distortion of the hard benchmark set (also the tests' DISTORTED case).
DISTORTED = DISTORTED_CAMERA
#: QR sides (mm), distances (mm) and the largest tilt (deg) the sets draw from.
SIDES_MM = (30.0, 50.0, 100.0)
Z_RANGE_MM = (150.0, 1000.0)
MAX_TILT_DEG = 60.0
#: Payload lengths (bytes): QR versions 1 to about 9 at error correction L.
PAYLOAD_BYTES = (5, 200)
_ALPHABET = string.ascii_letters + string.digits + " -_.:/"


def cameras() -> tuple[CameraModel, CameraModel]:
    """The pinhole camera (Pi camera v2 at 640x480, datasheet model) and :data:`DISTORTED`."""
    return resolve_camera("picam-v2@640x480"), DISTORTED


@dataclass(frozen=True)
class BenchView:
    """One view and its truth.

    Attributes:
        camera: the camera model; side_mm: the QR symbol's side L (mm).
        truth: the true pose (mm, degrees; marker to camera).
        corners_px: (4, 2) exact pixels of V1..V4 (distortion included).
        image: (H, W) uint8 grey, or None for a corner-level set (no picture).
        modules: modules per side (0 when there is no picture); text: the payload.
        module_size_px: the set's own module size (px), NaN to take the mean side's.
    """

    camera: CameraModel
    side_mm: float
    truth: Pose
    corners_px: np.ndarray
    image: np.ndarray | None = None
    modules: int = 0
    text: str = ""
    module_size_px: float = math.nan

    @property
    def module_px(self) -> float:
        """The module size as the set defines it (``module_size_px``: the hard set's shortest side
        over the module count), else the mean side of the corner quadrilateral over the module
        count (px; NaN without modules)."""
        if math.isfinite(self.module_size_px):
            return self.module_size_px
        if not self.modules:
            return math.nan
        sides = np.linalg.norm(np.roll(self.corners_px, -1, axis=0) - self.corners_px, axis=1)
        return float(sides.mean()) / self.modules


def _poses(rng: np.random.Generator, camera: CameraModel, side: float) -> Pose:
    from qrfield.sampling import random_visible_poses

    seed = int(rng.integers(0, 2**31))
    return random_visible_poses(camera, side, 1, seed=seed, z_range_mm=Z_RANGE_MM, max_tilt_deg=MAX_TILT_DEG)[
        0
    ]


def _draw(rng: np.random.Generator, index: int) -> tuple[CameraModel, float, Pose]:
    """The camera (pinhole and DISTORTED alternately), QR side and pose of view ``index``."""
    camera = cameras()[index % 2]
    side = float(rng.choice(SIDES_MM))
    return camera, side, _poses(rng, camera, side)


def corner_set(count: int, seed: int) -> list[BenchView]:
    """Corner-level views (no pictures): pinhole and DISTORTED alternately, sides SIDES_MM, z and
    tilt as in :data:`Z_RANGE_MM`, :data:`MAX_TILT_DEG`."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        camera, side, pose = _draw(rng, i)
        out.append(BenchView(camera, side, pose, pose.corners_px(camera, side)))
    return out


def render_set(count: int, seed: int) -> list[BenchView]:
    """Rendered views by qrfield.render: payloads of PAYLOAD_BYTES (log-uniform), sides SIDES_MM,
    z 150-1000 mm, tilt up to 60 deg, noise 0-4 grey levels, blur 0.3-1.2 px, brightness gradients
    up to 30 %, pinhole and DISTORTED alternately."""
    from qrfield.render import render_view

    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        camera, side, pose = _draw(rng, i)
        length = round(math.exp(rng.uniform(*np.log(PAYLOAD_BYTES))))
        text = "".join(rng.choice(list(_ALPHABET), length))
        view = render_view(
            camera,
            side,
            pose,
            text=text,
            noise_sigma=float(rng.uniform(0.0, 4.0)),
            blur_px=float(rng.uniform(0.3, 1.2)),
            gradient=float(rng.uniform(0.0, 0.3)),
            seed=seed * 100003 + i,
        )
        out.append(BenchView(camera, side, pose, view.corners_px, view.image, view.modules, text))
    return out


def hard_set(count: int, seed: int) -> list[BenchView]:
    """The hard benchmark set of ``qrfield benchmark detect`` (qrfield.testing.hardset: segno
    symbols of versions 1-10, 30/50/100 mm codes, z 150-1000 mm, tilt up to 60 deg, noise 0-4, blur
    0.3-1.2 px, lighting gradients, pinhole and DISTORTED; module size its views' shortest side over
    the modules)."""
    from qrfield.testing.hardset import hard_views

    return [
        BenchView(v.camera, v.side_mm, v.pose, v.corners_px, v.image, v.modules, v.text, v.module_px)
        for v in hard_views(count, seed)
    ]


def steep_set(count: int, seed: int) -> list[BenchView]:
    """The steep set of ``qrfield benchmark detect`` (qrfield.testing.hardset.steep_view: the hard
    set's symbols and degradations, alpha and beta each up to 55 deg, z 150-600 mm; module size its
    views' shortest side over the modules)."""
    from qrfield.testing.hardset import steep_views

    return [
        BenchView(v.camera, v.side_mm, v.pose, v.corners_px, v.image, v.modules, v.text, v.module_px)
        for v in steep_views(count, seed)
    ]


#: View sets with pictures, by name (``qrfield benchmark pose --view-set NAME``).
VIEW_SETS: dict[str, Callable[[int, int], list[BenchView]]] = {
    "hard": hard_set,
    "render": render_set,
    "steep": steep_set,
}
