"""Drawn video sequences of a QR card, independent truth for the stream's tests and ``qrfield
benchmark stream``: each a pure function of (name, seed), drawn by the hard set's rasteriser
(:mod:`qrfield.testing.hardset`: exact area sampling of a segno symbol through the pose and the
lens, not qrfield.render), blurred, and given fresh sensor noise every frame, at :data:`FPS`.
Frames are (H, W) uint8 grey with their true :class:`qrfield.geometry.Pose` (camera frame, mm and
degrees, docs/conventions.md)."""

from __future__ import annotations

import math
import string
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Frames a second of every sequence.
FPS = 30.0


@dataclass(frozen=True)
class Sequence:
    """One drawn video: its frames (grey image, true pose), the pose as a function of time (s),
    the camera, the QR side (mm), modules per side and the module size facing the camera (px)."""

    name: str
    seed: int
    camera: Any
    side_mm: float
    modules: int
    module_px: float
    frames: list[tuple[np.ndarray, Any]]
    pose_at: Callable[[float], Any]
    moving: bool
    lag: bool


def _symbol(rng: np.random.Generator, version: int) -> np.ndarray:
    """(n, n) bool module matrix of a random payload encoded by segno at QR ``version``."""
    import segno

    alphabet = string.ascii_letters + string.digits + " -_.:/?="
    for _ in range(100):
        text = "".join(rng.choice(list(alphabet), int(rng.integers(6, 15))))
        try:
            qr = segno.make(text, error="m", version=version, micro=False, boost_error=False)
        except segno.DataOverflowError:
            continue
        return np.array(qr.matrix, dtype=bool)
    raise RuntimeError(f"no payload fits QR version {version}")


def _wave(
    rng: np.random.Generator, amplitude: float, low_hz: float, high_hz: float
) -> Callable[[float], float]:
    """t -> amplitude * sin(2 pi f t + phase), f and phase drawn."""
    f = float(rng.uniform(low_hz, high_hz))
    phase = float(rng.uniform(0.0, 2.0 * math.pi))
    return lambda t: amplitude * math.sin(2.0 * math.pi * f * t + phase)


def _trajectory(kind: str, rng: np.random.Generator, z_mm: float) -> tuple[Callable[[float], Any], bool]:
    """The pose at time t (s) of sequence ``kind`` at about ``z_mm``, and whether it moves."""
    from qrfield.geometry import Pose

    x0, y0 = rng.uniform(-15.0, 15.0), rng.uniform(-10.0, 10.0)
    g0 = float(rng.uniform(-30.0, 30.0))
    if kind == "frontal":  # held facing the camera: a slow drift of a few degrees and mm
        wx, wy, wz = _wave(rng, 6, 0.05, 0.2), _wave(rng, 5, 0.05, 0.2), _wave(rng, 8, 0.05, 0.2)
        wa, wb, wg = _wave(rng, 3.0, 0.1, 0.3), _wave(rng, 3.0, 0.1, 0.3), _wave(rng, 4, 0.05, 0.2)
        return (lambda t: Pose([x0 + wx(t), y0 + wy(t), z_mm + wz(t)], [wa(t), wb(t), g0 + wg(t)])), True
    if kind == "sweep":  # turned about one axis through frontal to +-40 degrees and back
        axis = int(rng.integers(2))
        sweep = _wave(rng, 40.0, 0.18, 0.25)
        other = _wave(rng, 3.0, 0.1, 0.3)
        wx, wy = _wave(rng, 10, 0.05, 0.2), _wave(rng, 8, 0.05, 0.2)

        def sweep_pose(t: float) -> Any:
            a, b = (sweep(t), other(t)) if axis == 0 else (other(t), sweep(t))
            return Pose([x0 + wx(t), y0 + wy(t), z_mm], [a, b, g0])

        return sweep_pose, True
    if kind == "wobble":  # a slow wobble of about 12 degrees
        wa, wb, wg = _wave(rng, 12.0, 0.2, 0.3), _wave(rng, 12.0, 0.2, 0.3), _wave(rng, 10, 0.1, 0.2)
        wx, wy, wz = _wave(rng, 20, 0.1, 0.2), _wave(rng, 15, 0.1, 0.2), _wave(rng, 20, 0.1, 0.2)
        return (lambda t: Pose([x0 + wx(t), y0 + wy(t), z_mm + wz(t)], [wa(t), wb(t), g0 + wg(t)])), True
    if kind == "swing":  # a fast swing: 35 degrees at 1 Hz (220 deg/s at its fastest), 60 mm across
        axis = int(rng.integers(2))
        swing = _wave(rng, 35.0, 0.9, 1.1)
        across = _wave(rng, 60.0, 0.4, 0.6)
        tilt = float(rng.uniform(-10.0, 10.0))

        def swing_pose(t: float) -> Any:
            a, b = (swing(t), tilt) if axis == 0 else (tilt, swing(t))
            return Pose([x0 + across(t), y0, z_mm], [a, b, g0])

        return swing_pose, True
    if kind == "turn":  # turned steadily by 24 degrees in 5 s, tilted 12-36 degrees away
        axis = int(rng.integers(2))
        sign = 1.0 if rng.random() < 0.5 else -1.0
        other = _wave(rng, 3.0, 0.1, 0.3)

        def turn_pose(t: float) -> Any:
            tilt = sign * (12.0 + 4.8 * t)
            a, b = (tilt, other(t)) if axis == 0 else (other(t), tilt)
            return Pose([x0, y0, z_mm], [a, b, g0])

        return turn_pose, True
    if kind == "still":
        angles = [float(rng.uniform(-15, 15)), float(rng.uniform(-15, 15)), g0]
        pose = Pose([x0, y0, z_mm], angles)
        return (lambda t: pose), False
    raise ValueError(f"unknown sequence kind {kind!r}")


#: name -> (trajectory kind, QR version, module size facing the camera (px) or None, z mm, distorted).
#: Modules 25 (version 2) and 29 (version 3) of a 50 mm code; z from the module size where given.
SEQUENCES = {
    "frontal 450 mm": ("frontal", 2, None, 450.0, False),
    "frontal far 1.4 px": ("frontal", 2, 1.4, None, False),
    "frontal far 1.2 px": ("frontal", 3, 1.2, None, False),
    "sweep 40 deg 300 mm": ("sweep", 2, None, 300.0, False),
    "wobble 450 mm": ("wobble", 2, None, 450.0, True),
    "still 450 mm": ("still", 2, None, 450.0, False),
    "fast swing 400 mm": ("swing", 2, None, 400.0, False),
    "fast swing far 1.4 px": ("swing", 2, 1.4, None, False),
    "steady turn far 1.4 px": ("turn", 2, 1.4, None, False),
}
#: The kinds whose lag is measured (a motion well above the noise; the frontal ones drift by
#: less than their noise).
LAG_KINDS = ("sweep", "wobble", "swing", "turn")
SIDE_MM = 50.0


def make_sequence(name: str, seed: int, count: int) -> Sequence:
    """Sequence ``name`` (SEQUENCES) of ``count`` frames: a pure function of (name, seed)."""
    import cv2

    from qrfield.testing.hardset import DISTORTED_CAMERA, _pinhole, rasterise

    kind, version, module_px, z_mm, distorted = SEQUENCES[name]
    rng = np.random.default_rng([seed, 25, list(SEQUENCES).index(name)])
    camera = DISTORTED_CAMERA if distorted else _pinhole()
    matrix = _symbol(rng, version)
    n = matrix.shape[0]
    z = camera.fx * SIDE_MM / (n * module_px) if module_px else float(z_mm)
    pose_at, moving = _trajectory(kind, rng, z)
    light, dark, background = rng.uniform(180, 230), rng.uniform(20, 60), rng.uniform(60, 170)
    blur, noise = float(rng.uniform(0.55, 0.8)), float(rng.uniform(1.5, 2.5))
    noise_rng = np.random.default_rng([seed, 26, list(SEQUENCES).index(name)])
    frames = []
    still_image = None
    for i in range(count):
        pose = pose_at(i / FPS)
        if still_image is None or moving:
            image = rasterise(camera, pose, SIDE_MM, matrix, background, light, dark)
            image = cv2.GaussianBlur(image, (0, 0), sigmaX=blur, borderType=cv2.BORDER_REPLICATE)
            still_image = image
        grey = still_image + noise_rng.normal(0.0, noise, still_image.shape)
        frames.append((np.clip(np.round(grey), 0, 255).astype(np.uint8), pose))
    module = camera.fx * SIDE_MM / (n * z)
    return Sequence(name, seed, camera, SIDE_MM, n, module, frames, pose_at, moving, kind in LAG_KINDS)
