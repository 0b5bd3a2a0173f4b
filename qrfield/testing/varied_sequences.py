"""Drawn video sequences under conditions :data:`qrfield.testing.sequences.SEQUENCES` does not hold:
motion blur, JPEG compression, a code that leaves view (or is covered) and comes back, possibly
with its tilt's sign flipped while hidden, dropped frames, flickering light and an exposure change,
QR versions 1 and 6, a distorted lens far off the axis, a slow tilt through frontal at far range.

Each is a pure function of (name, seed), drawn as the clean sequences are (the hard set's
rasteriser, :mod:`qrfield.testing.hardset`: exact area sampling of a segno symbol through the pose
and the lens; a Gaussian blur; fresh sensor noise every frame), then given its condition. Frames
are (H, W) uint8 grey with their true :class:`qrfield.geometry.Pose` (camera frame, mm and degrees,
docs/conventions.md), captured at ``times_s`` (s from the first frame) and numbered ``indices``
(frames of a 30 fps clock: a dropped frame leaves its number out). A hidden frame keeps the card's
true pose as its truth, but no code is in the picture.

Conditions (the keys of a :data:`VARIED_SEQUENCES` entry besides the trajectory):

- ``exposure_ms``: motion blur, the card's picture averaged over the exposure (BLUR_STEPS poses
  spread evenly over it, centred on the frame's time, the truth the pose at the centre): a blur
  along the motion of speed x exposure;
- ``jpeg``: (low, high) JPEG quality, each frame encoded and decoded by OpenCV (MJPG) at a quality
  drawn per sequence, +-3 per frame;
- ``hide``: (low, high) s: the code is hidden once, for a time drawn from that range, starting
  1.2-1.8 s in; ``hide_by`` "cover" (a flat patch over the card, as a hand) or "exit" (the card
  slides out of the picture and back, HIDE_SLIDE_S each way, counted in the hidden time);
  with kind "flip" the card's tilt changes sign while hidden;
- ``drops``: (low, high) s: runs of dropped frames (each a gap drawn from the range), DROP_RUNS
  of them, and every capture time jittered by JITTER_MS (1 sigma);
- ``flicker``: the scene's brightness varies by +-FLICKER_DEPTH (mains flicker aliased to 3-9 Hz)
  and, once, the exposure steps down to 0.5-0.7 and settles back over EXPOSURE_SETTLE_S.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from qrfield.testing.sequences import FPS, SIDE_MM, Sequence, _symbol, _trajectory, _wave

#: Poses over one exposure of a blurred frame.
BLUR_STEPS = 7
#: Point samples per pixel of each of them (a Fibonacci number: 7 x 34 about the hard set's 233).
BLUR_SUPERSAMPLE = 34
#: Runs of dropped frames per sequence, and the capture times' jitter (1 sigma), ms.
DROP_RUNS = 3
JITTER_MS = 2.0
#: Brightness flicker depth (share), and how long the exposure takes to settle after a step, s.
FLICKER_DEPTH = 0.12
EXPOSURE_SETTLE_S = 0.4
#: A card leaving view slides out (and back) in this time, s.
HIDE_SLIDE_S = 0.15

#: name -> trajectory kind, QR version, module size facing the camera (px) or None, z mm or None,
#: distorted lens, the card's offset from the axis (mm, x) and the conditions (see the module doc).
VARIED_SEQUENCES: dict[str, dict[str, Any]] = {
    "blurred swing 400 mm": dict(kind="swing", version=2, z=400.0, exposure_ms=8.0),
    "blurred swing far 1.4 px": dict(kind="swing", version=2, module=1.4, exposure_ms=8.0),
    "jpeg, blurred swing far 1.4 px": dict(
        kind="swing", version=2, module=1.4, exposure_ms=12.0, jpeg=(50, 70)
    ),
    "jpeg frontal far 1.4 px": dict(kind="frontal", version=2, module=1.4, jpeg=(50, 85)),
    "jpeg frontal 450 mm": dict(kind="frontal", version=2, z=450.0, jpeg=(50, 85)),
    "jpeg frontal far 1.2 px": dict(kind="frontal", version=3, module=1.2, jpeg=(50, 85)),
    "jpeg still 450 mm": dict(kind="still", version=2, z=450.0, jpeg=(50, 85)),
    "jpeg sweep 300 mm": dict(kind="sweep", version=2, z=300.0, jpeg=(50, 85)),
    "covered, flipped 450 mm": dict(kind="flip", version=2, z=450.0, hide=(0.3, 1.5), hide_by="cover"),
    "left view, flipped far 1.4 px": dict(
        kind="flip", version=2, module=1.4, hide=(0.3, 1.5), hide_by="exit"
    ),
    "briefly covered, flipped far 1.4 px": dict(
        kind="flip", version=2, module=1.4, hide=(0.3, 0.45), hide_by="cover", tilt=(2.0, 4.0)
    ),
    "covered wobble 450 mm": dict(kind="wobble", version=2, z=450.0, hide=(0.3, 1.5), hide_by="cover"),
    "dropped frames frontal 450 mm": dict(kind="frontal", version=2, z=450.0, drops=(0.1, 0.7)),
    "dropped frames sweep 300 mm": dict(kind="sweep", version=2, z=300.0, drops=(0.1, 0.7)),
    "dropped frames far 1.4 px": dict(kind="frontal", version=2, module=1.4, drops=(0.1, 0.7)),
    "dropped frames swing far 1.4 px": dict(kind="swing", version=2, module=1.4, drops=(0.1, 0.7)),
    "flicker wobble 450 mm": dict(kind="wobble", version=2, z=450.0, flicker=True),
    "version 1 frontal far 1.4 px": dict(kind="frontal", version=1, module=1.4),
    "version 6 wobble 250 mm": dict(kind="wobble", version=6, z=250.0),
    "distorted off-axis far 1.4 px": dict(
        kind="frontal", version=2, module=1.4, distorted=True, offset=220.0
    ),
    "slow tilt through frontal far 1.4 px": dict(kind="tilt", version=2, module=1.4),
}
#: The kinds whose lag is measured (as in qrfield.testing.sequences.LAG_KINDS).
LAG_KINDS = ("sweep", "wobble", "swing", "turn", "tilt", "flip")


@dataclass(frozen=True)
class VariedSequence(Sequence):
    """A :class:`qrfield.testing.sequences.Sequence` with its frames' capture times (s from the
    first frame) and numbers on a 30 fps clock (dropped frames left out), and the hidden frames'
    numbers."""

    times_s: tuple[float, ...] = ()
    indices: tuple[int, ...] = ()
    hidden: tuple[int, ...] = ()


def _hide_window(rng: np.random.Generator, spec: dict[str, Any]) -> tuple[float, float] | None:
    """(start, end) s of the hidden time, or None."""
    if "hide" not in spec:
        return None
    start = float(rng.uniform(1.2, 1.8))
    return start, start + float(rng.uniform(*spec["hide"]))


def _special_trajectory(
    kind: str,
    rng: np.random.Generator,
    z_mm: float,
    window: tuple[float, float] | None,
    tilt_range: tuple[float, float] = (8.0, 20.0),
) -> tuple[Any, bool]:
    """The kinds of this module: "flip" (held tilted ``tilt_range`` degrees about one axis, the tilt's sign
    changed while hidden, within ``window``, or at 2 s) and "tilt" (a slow tilt, 4-6 deg/s, from
    -12 to +12 degrees and on, through frontal); else the clean sequences' kinds."""
    from qrfield.geometry import Pose

    x0, y0 = rng.uniform(-15.0, 15.0), rng.uniform(-10.0, 10.0)
    g0 = float(rng.uniform(-30.0, 30.0))
    if kind == "flip":
        axis = int(rng.integers(2))
        tilt = float(rng.uniform(*tilt_range)) * (1.0 if rng.random() < 0.5 else -1.0)
        other = _wave(rng, 3.0, 0.1, 0.3)
        wx, wy = _wave(rng, 6, 0.05, 0.2), _wave(rng, 5, 0.05, 0.2)
        start, end = window if window is not None else (1.9, 2.1)

        def flip_pose(t: float) -> Any:
            s = min(max((t - start) / max(end - start, 1e-9), 0.0), 1.0)
            a = tilt * math.cos(math.pi * s)  # +tilt before, -tilt after, smooth between
            ab = (a, other(t)) if axis == 0 else (other(t), a)
            return Pose([x0 + wx(t), y0 + wy(t), z_mm], [ab[0], ab[1], g0])

        return flip_pose, True
    if kind == "tilt":
        axis = int(rng.integers(2))
        rate = float(rng.uniform(4.0, 6.0)) * (1.0 if rng.random() < 0.5 else -1.0)
        other = _wave(rng, 2.0, 0.1, 0.3)

        def tilt_pose(t: float) -> Any:
            a = -math.copysign(12.0, rate) + rate * t
            ab = (a, other(t)) if axis == 0 else (other(t), a)
            return Pose([x0, y0, z_mm], [ab[0], ab[1], g0])

        return tilt_pose, True
    return _trajectory(kind, rng, z_mm)


def _offset(pose_at: Any, offset_x: float, slide: Any) -> Any:
    """``pose_at`` moved by ``offset_x`` mm along x, plus ``slide(t)`` mm (the exit)."""
    from qrfield.geometry import Pose

    if not offset_x and slide is None:
        return pose_at

    def moved(t: float) -> Any:
        pose = pose_at(t)
        dx = offset_x + (slide(t) if slide is not None else 0.0)
        return Pose(pose.position_mm + np.array([dx, 0.0, 0.0]), pose.angles_deg)

    return moved


def _exit_slide(window: tuple[float, float], z_mm: float, camera: Any) -> Any:
    """The sideways shift (mm) at time t that takes the card out of the picture over HIDE_SLIDE_S
    after ``window``'s start and back over HIDE_SLIDE_S before its end."""
    out = 1.2 * (camera.width / camera.fx) * z_mm  # beyond the picture's edge at z
    start, end = window
    slide = min(HIDE_SLIDE_S, (end - start) / 2.0)

    def shift(t: float) -> float:
        if t <= start or t >= end:
            return 0.0
        s = min((t - start) / slide, (end - t) / slide, 1.0)
        return out * (0.5 - 0.5 * math.cos(math.pi * s))

    return shift


def _card_box(camera: Any, pose: Any, side_mm: float, modules: int) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) px of the card (``modules`` per side) with its quiet zone and margin, a
    few px more, clipped to the picture."""
    from qrfield.geometry import project_points
    from qrfield.testing.hardset import CARD_MARGIN_MODULES, QUIET_MODULES

    half = side_mm / 2.0 + (QUIET_MODULES + CARD_MARGIN_MODULES) * side_mm / modules
    corners = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
    px = project_points(corners @ pose.rotation.T + pose.position_mm, camera)
    w, h = camera.size
    x0, y0 = np.floor(px.min(axis=0)).astype(int) - 4
    x1, y1 = np.ceil(px.max(axis=0)).astype(int) + 4
    return max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)


def make_varied(name: str, seed: int, count: int) -> VariedSequence:
    """Sequence ``name`` (:data:`VARIED_SEQUENCES`) of ``count`` frames of a 30 fps clock (fewer
    when frames are dropped): a pure function of (name, seed)."""
    import cv2

    from qrfield.testing.hardset import DISTORTED_CAMERA, _pinhole, rasterise

    spec = VARIED_SEQUENCES[name]
    index = zlib.crc32(name.encode())  # the name's own streams: adding a sequence moves no other
    rng = np.random.default_rng([seed, 251, index])
    camera = DISTORTED_CAMERA if spec.get("distorted") else _pinhole()
    matrix = _symbol(rng, int(spec["version"]))
    n = matrix.shape[0]
    z = camera.fx * SIDE_MM / (n * spec["module"]) if spec.get("module") else float(spec["z"])
    window = _hide_window(rng, spec)
    pose_at, moving = _special_trajectory(str(spec["kind"]), rng, z, window, spec.get("tilt", (8.0, 20.0)))
    slide = _exit_slide(window, z, camera) if window and spec.get("hide_by") == "exit" else None
    pose_at = _offset(pose_at, float(spec.get("offset", 0.0)), slide)
    light, dark, background = rng.uniform(180, 230), rng.uniform(20, 60), rng.uniform(60, 170)
    blur, noise = float(rng.uniform(0.55, 0.8)), float(rng.uniform(1.5, 2.5))
    cover = float(rng.uniform(90, 200))
    quality = int(rng.integers(spec["jpeg"][0], spec["jpeg"][1] + 1)) if "jpeg" in spec else 0
    flicker_hz, flicker_phase = float(rng.uniform(3.0, 9.0)), float(rng.uniform(0, 2 * math.pi))
    step_t, step_gain = float(rng.uniform(1.0, 3.0)), float(rng.uniform(0.5, 0.7))
    keep = np.ones(count, dtype=bool)
    if "drops" in spec:
        for _ in range(DROP_RUNS):
            run = max(1, round(float(rng.uniform(*spec["drops"])) * FPS) - 1)  # gap = run + 1 frames
            first = int(rng.integers(5, max(count - run - 5, 6)))
            keep[first : first + run] = False
    jitter = rng.normal(0.0, JITTER_MS / 1000.0, count) if "drops" in spec else np.zeros(count)
    exposure = float(spec.get("exposure_ms", 0.0)) / 1000.0
    noise_rng = np.random.default_rng([seed, 252, index])
    frames, times, indices, hidden = [], [], [], []
    for i in range(count):
        if not keep[i]:
            continue
        t = i / FPS + float(jitter[i])
        pose = pose_at(t)
        if exposure > 0.0:
            steps = [t + exposure * (k / (BLUR_STEPS - 1) - 0.5) for k in range(BLUR_STEPS)]
            per = BLUR_SUPERSAMPLE
            image = np.mean(
                [rasterise(camera, pose_at(s), SIDE_MM, matrix, background, light, dark, per) for s in steps],
                axis=0,
            )
        else:
            image = rasterise(camera, pose, SIDE_MM, matrix, background, light, dark)
        if window is not None and window[0] < t < window[1]:
            if slide is None:  # covered: a flat patch (a hand) over the whole card
                x0, y0, x1, y1 = _card_box(camera, pose, SIDE_MM, n)
                image[y0:y1, x0:x1] = cover
            hidden.append(i)
        image = cv2.GaussianBlur(image, (0, 0), sigmaX=blur, borderType=cv2.BORDER_REPLICATE)
        if spec.get("flicker"):
            gain = 1.0 + FLICKER_DEPTH * math.sin(2.0 * math.pi * flicker_hz * t + flicker_phase)
            if t >= step_t:
                settle = min((t - step_t) / EXPOSURE_SETTLE_S, 1.0)
                gain *= step_gain + (1.0 - step_gain) * settle
            image = image * gain
        grey = np.clip(np.round(image + noise_rng.normal(0.0, noise, image.shape)), 0, 255).astype(np.uint8)
        if quality:
            q = int(np.clip(quality + noise_rng.integers(-3, 4), 1, 100))
            ok, data = cv2.imencode(".jpg", grey, [cv2.IMWRITE_JPEG_QUALITY, q])
            assert ok
            grey = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
        frames.append((grey, pose))
        times.append(t)
        indices.append(i)
    module = camera.fx * SIDE_MM / (n * z)
    kind = str(spec["kind"])
    return VariedSequence(
        name, seed, camera, SIDE_MM, n, module, frames, pose_at, moving, kind in LAG_KINDS,
        tuple(times), tuple(indices), tuple(hidden),
    )  # fmt: skip
