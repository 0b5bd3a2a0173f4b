"""The virtual bench: a simulated camera that renders a QR card at a settable true pose.

Every frame is rendered by :func:`qrfield.render.render_view` through the bench's camera model,
with optional noise and blur, and carries its true pose (``Frame.truth``), the independent truth
the measured pose is compared with. An optional wobble makes the pose change slowly over time:
alpha and beta swing sinusoidally by ``wobble_deg`` about the set pose, x by ``wobble_mm``.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, replace

import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose
from qrfield.render import RenderError, render_view
from qrfield.settings import setting, validated
from qrfield.sources.base import Frame, FrameSource, Pacer

#: The most notes a bench makes of its card leaving the view, over its life: one each time the card
#: leaves (not one a frame: the vertex pixels in the text change with every frame of a wobble, and
#: a note a frame grew ``notes`` without bound, copied by the frame loop each frame, and said each on
#: ``run``'s stderr), then no more once this many were made (the last one says so).
MAX_VIEW_NOTES = 10


@dataclass(frozen=True)
class VirtualBenchSettings:
    """The virtual bench's true pose (marker to camera, mm and degrees), image degradations and motion."""

    x_mm: float = setting(10.0, label="true x", unit="mm", minimum=-2000.0, maximum=2000.0, decimals=1)
    y_mm: float = setting(-5.0, label="true y", unit="mm", minimum=-2000.0, maximum=2000.0, decimals=1)
    z_mm: float = setting(300.0, label="true z", unit="mm", minimum=20.0, maximum=5000.0, decimals=1)
    alpha_deg: float = setting(
        15.0, label="true alpha", unit="deg", minimum=-180.0, maximum=180.0, decimals=2
    )
    beta_deg: float = setting(-20.0, label="true beta", unit="deg", minimum=-90.0, maximum=90.0, decimals=2)
    gamma_deg: float = setting(
        10.0, label="true gamma", unit="deg", minimum=-180.0, maximum=180.0, decimals=2
    )
    noise_sigma: float = setting(
        2.0,
        label="noise",
        unit="grey levels",
        minimum=0.0,
        maximum=64.0,
        decimals=1,
        help="standard deviation of Gaussian pixel noise",
    )
    blur_px: float = setting(
        0.6, label="blur", unit="px", minimum=0.0, maximum=10.0, decimals=2, help="Gaussian blur sigma"
    )
    wobble_deg: float = setting(
        0.0,
        label="wobble",
        unit="deg",
        minimum=0.0,
        maximum=45.0,
        decimals=1,
        help="amplitude of a slow swing of alpha and beta about the set pose (0 = still)",
    )
    wobble_mm: float = setting(0.0, label="wobble x", unit="mm", minimum=0.0, maximum=200.0, decimals=1)
    wobble_period_s: float = setting(
        6.0, label="wobble period", unit="s", minimum=0.5, maximum=600.0, decimals=1
    )
    fps: float = setting(
        30.0,
        label="frame rate",
        unit="fps",
        minimum=0.0,
        maximum=1000.0,
        decimals=1,
        help="frames per second delivered (0 = as fast as rendering allows)",
    )
    text: str = setting("qrfield", label="QR text", help="payload of the rendered code")
    seed: int = setting(0, label="noise seed", minimum=0, maximum=2**31 - 1, help="frame i uses seed + i")

    @property
    def pose(self) -> Pose:
        """The set (still) pose."""
        return Pose([self.x_mm, self.y_mm, self.z_mm], [self.alpha_deg, self.beta_deg, self.gamma_deg])

    def with_pose(self, pose: Pose) -> VirtualBenchSettings:
        x, y, z = (float(v) for v in pose.position_mm)
        a, b, g = (float(v) for v in pose.angles_deg)
        return replace(self, x_mm=x, y_mm=y, z_mm=z, alpha_deg=a, beta_deg=b, gamma_deg=g)


def pose_at(settings: VirtualBenchSettings, t_s: float) -> Pose:
    """The bench's true pose ``t_s`` seconds after the start: the set pose plus the slow wobble."""
    s = settings
    if s.wobble_deg == 0 and s.wobble_mm == 0:
        return s.pose
    phase = 2 * math.pi * t_s / s.wobble_period_s
    angles = s.pose.angles_deg + s.wobble_deg * np.array(
        [math.sin(phase), math.sin(phase + math.pi / 2), 0.0]
    )
    position = s.pose.position_mm + np.array([s.wobble_mm * math.sin(phase / 2), 0.0, 0.0])
    return Pose(position, angles)


class VirtualBenchSource(FrameSource):
    """Renders the card at the settings' pose; settings may be changed while frames are read."""

    name = "virtual"
    live = False  # a frame is rendered when read(): nothing to drain
    simulated = True

    def __init__(
        self, camera: CameraModel, side_mm: float, settings: VirtualBenchSettings | None = None
    ) -> None:
        super().__init__()
        if not math.isfinite(side_mm) or side_mm <= 0:
            raise ValueError(f"QR side must be a positive length in mm, got {side_mm!r}")
        self.camera = camera
        self.side_mm = float(side_mm)
        self._settings = validated(settings or VirtualBenchSettings())
        self._lock = threading.Lock()
        self._pacer = Pacer(self._settings.fps)
        self._t0 = 0.0
        self._in_view = True  # the last frame showed the whole card (a note when it leaves)
        self._view_notes = 0  # notes made of the card leaving the view (at most MAX_VIEW_NOTES)

    @property
    def description(self) -> str:
        cam = self.camera
        return f"virtual bench ({cam.name}, {cam.width}x{cam.height}, {self.side_mm:g} mm code)"

    @property
    def settings(self) -> VirtualBenchSettings:
        with self._lock:
            return self._settings

    def set_settings(self, settings: VirtualBenchSettings) -> None:
        """Change pose, noise or motion; takes effect at the next frame (thread-safe)."""
        settings = validated(settings)
        with self._lock:
            self._settings = settings
            self._pacer.fps = settings.fps

    def true_pose(self, t_s: float) -> Pose:
        """The true pose ``t_s`` seconds after the source was opened (the set pose plus wobble)."""
        return pose_at(self.settings, t_s)

    def _open_impl(self) -> None:
        self._t0 = time.monotonic()
        self._pacer = Pacer(self.settings.fps)

    def _read_impl(self, index: int) -> Frame:
        self._pacer.wait()
        s = self.settings
        t = time.monotonic()
        pose = self.true_pose(t - self._t0)
        kwargs = dict(text=s.text, noise_sigma=s.noise_sigma, blur_px=s.blur_px, seed=s.seed + index)
        try:
            image = render_view(self.camera, self.side_mm, pose, **kwargs).image
        except RenderError as exc:
            try:  # a code partly out of view is still a picture (the detector then finds nothing)
                image = render_view(self.camera, self.side_mm, pose, allow_partial=True, **kwargs).image
            except RenderError:
                image = np.full((self.camera.height, self.camera.width), 110, np.uint8)
            self._note_out_of_view(str(exc))
        else:
            self._in_view = True
        return Frame(image, t, index, truth=pose, label=f"virtual #{index}")

    def _note_out_of_view(self, why: str) -> None:
        """A note when the card leaves the view (the frame before it showed it whole), at most
        MAX_VIEW_NOTES over the bench's life (:data:`MAX_VIEW_NOTES`)."""
        leaving, self._in_view = self._in_view, False
        if not leaving or self._view_notes >= MAX_VIEW_NOTES:
            return
        self._view_notes += 1
        if self._view_notes == MAX_VIEW_NOTES:
            why += f" (noted {MAX_VIEW_NOTES} times: further times the code leaves the view are not noted)"
        self.notes.append(why)

    def _close_impl(self) -> None:
        pass
