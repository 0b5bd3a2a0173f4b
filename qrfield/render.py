"""The virtual bench: renders a real QR code on a white card at a known pose through a camera model.

The QR symbol (quiet zone excluded) is a square of side L mm centred on the marker frame's origin
(docs/conventions.md); around it lie the quiet zone (4 modules) and a white card margin. The returned
``corners_px`` are the exact projections of V1..V4 (top-left, top-right, bottom-right,
bottom-left of the symbol), distortion included: the independent truth that detectors and solvers
are tested against.

How the picture is made: the card is a texture whose texel centres map exactly to card
millimetres; one homography (camera K, pose, texture scale) warps it into a supersampled region of
interest around the card; an area average brings it back to camera pixels (anti-aliasing). With
lens distortion the ideal pinhole picture is rendered first and remapped through the exact
undistortion of every camera pixel. Optional blur, brightness gradient and Gaussian noise follow.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from qrfield.camera import CameraModel
from qrfield.geometry import Pose, project_points, transform_points
from qrfield.lens import undistort_points
from qrfield.texts import check_text
from qrfield.visibility import view_problem

#: Quiet zone around the symbol, in modules (ISO/IEC 18004 asks for 4).
QUIET_ZONE_MODULES = 4
#: White card beyond the quiet zone, in modules.
CARD_MARGIN_MODULES = 2
#: Default grey level of the background behind the card.
BACKGROUND_GREY = 110
#: Default supersampling factor per axis (3 x 3 samples per camera pixel).
SUPERSAMPLE = 3


class RenderError(ValueError):
    """The pose cannot be rendered: card behind the camera, facing away, or out of view."""


@dataclass(frozen=True)
class RenderedView:
    """One rendered camera image and its truth.

    Attributes:
        image: (H, W) uint8 grey, or (H, W, 3) uint8 BGR when rendered in colour.
        corners_px: (4, 2) float pixels of V1..V4, exact (OpenCV pixel convention).
        pose: the true pose (mm, degrees; marker to camera).
        camera: the camera model rendered through.
        side_mm: the symbol's side L in mm.
        text: the QR payload.
        modules: the symbol's module count per side (21 for version 1).
    """

    image: np.ndarray
    corners_px: np.ndarray
    pose: Pose
    camera: CameraModel
    side_mm: float
    text: str
    modules: int


@functools.lru_cache(maxsize=32)
def qr_symbol(text: str) -> np.ndarray:
    """(n, n) bool modules of the QR symbol for ``text`` (True = dark), quiet zone excluded.

    Encoded by OpenCV's QRCodeEncoder (error correction level L, smallest version that fits).
    """
    if not text:
        raise ValueError("QR text must not be empty")
    check_text(text, "QR text")  # OpenCV's binding crashes on a text that is not UTF-8
    try:
        image = cv2.QRCodeEncoder.create().encode(text)
    except cv2.error as exc:
        raise ValueError(
            f"OpenCV cannot encode a {len(text)}-character text as a QR code: {exc.err}"
        ) from None
    if image is None or image.size == 0:
        raise ValueError(f"OpenCV could not encode {text!r} as a QR code")
    dark = image < 128
    rows, cols = np.nonzero(dark)
    symbol = dark[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    if symbol.shape[0] != symbol.shape[1] or (symbol.shape[0] - 17) % 4:
        raise ValueError(f"unexpected QR symbol size {symbol.shape} for {text!r}")
    symbol.setflags(write=False)
    return symbol


@functools.lru_cache(maxsize=64)
def _card_texture(text: str, texels_per_module: int) -> np.ndarray:
    """uint8 texture of the whole card (symbol, quiet zone, margin), 255 = white."""
    symbol = qr_symbol(text)
    pad = QUIET_ZONE_MODULES + CARD_MARGIN_MODULES
    modules = np.pad(symbol, pad, constant_values=False)
    texture = np.where(modules, 0, 255).astype(np.uint8)
    texture = np.repeat(np.repeat(texture, texels_per_module, axis=0), texels_per_module, axis=1)
    texture.setflags(write=False)
    return texture


@functools.lru_cache(maxsize=8)
def _ideal_pixel_map(camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """For every camera pixel, the pixel of the ideal (distortion-free) pinhole image it sees."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], axis=-1).reshape(-1, 1, 2)
    ideal = undistort_points(pts, camera.K, camera.dist, pixels=True)
    ideal = ideal.reshape(camera.height, camera.width, 2).astype(np.float32)
    return ideal[..., 0].copy(), ideal[..., 1].copy()


@dataclass(frozen=True)
class IdealCanvas:
    """The pinhole (distortion-free) canvas a camera's picture is drawn on before the lens.

    Attributes:
        offset: the camera pixel (x, y) of the canvas' pixel (0, 0); (0, 0) without distortion.
        size: the canvas' (width, height) in pixels: the camera's, or with distortion the bounds
            of every ideal pixel the camera sees, 2 px wider on the top and left and 3 px on the
            bottom and right (the remap's bilinear neighbours).
        maps: (map_u, map_v), each (H, W) float32: the ideal pixel each camera pixel sees
            (:func:`_ideal_pixel_map`); None without distortion.
    """

    offset: tuple[float, float]
    size: tuple[int, int]
    maps: tuple[np.ndarray, np.ndarray] | None

    def to_camera(self, canvas: np.ndarray) -> np.ndarray:
        """``canvas`` (the size of :attr:`size`) brought to camera pixels through the lens (bilinear,
        edge pixels replicated); the canvas itself without distortion."""
        if self.maps is None:
            return canvas
        map_u, map_v = self.maps
        return cv2.remap(
            canvas,
            map_u - np.float32(self.offset[0]),
            map_v - np.float32(self.offset[1]),
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )


def ideal_canvas(camera: CameraModel) -> IdealCanvas:
    """The canvas that holds every ideal pixel ``camera`` sees (see :class:`IdealCanvas`)."""
    if not camera.has_distortion:
        return IdealCanvas((0.0, 0.0), camera.size, None)
    map_u, map_v = _ideal_pixel_map(camera)
    x0, y0 = math.floor(float(map_u.min())) - 2, math.floor(float(map_v.min())) - 2
    x1, y1 = math.ceil(float(map_u.max())) + 3, math.ceil(float(map_v.max())) + 3
    return IdealCanvas((float(x0), float(y0)), (x1 - x0, y1 - y0), (map_u, map_v))


@functools.lru_cache(maxsize=8)
def _gradient_ramp(width: int, height: int) -> np.ndarray:
    """(H, W) float32 ramp from -1 (left) to +1 (right) with a slight vertical slant."""
    u = np.linspace(-1.0, 1.0, width, dtype=np.float32)
    v = np.linspace(-0.3, 0.3, height, dtype=np.float32)
    return np.clip(u[None, :] + v[:, None], -1.0, 1.0)


def card_side_mm(side_mm: float, modules: int) -> float:
    """Side of the whole white card in mm for a symbol of side L and ``modules`` modules."""
    return side_mm * (modules + 2 * (QUIET_ZONE_MODULES + CARD_MARGIN_MODULES)) / modules


def check_view(camera: CameraModel, side_mm: float, pose: Pose, allow_partial: bool = False) -> np.ndarray:
    """Return the (4, 2) vertex pixels of a visible pose, or raise RenderError saying why not.

    Visible: :mod:`qrfield.visibility`'s rule (``allow_partial``: in front and facing the camera).
    """
    if not math.isfinite(side_mm) or side_mm <= 0:
        raise RenderError(f"QR side must be a positive length in mm, got {side_mm!r}")
    problem = view_problem(camera, side_mm, pose.rotation, pose.position_mm, allow_partial)
    if problem:
        if "faces away" in problem:
            problem += f"; angles {np.round(pose.angles_deg, 2).tolist()} deg"
        raise RenderError(problem)
    return project_points(pose.vertices_mm(side_mm), camera)


def render_view(
    camera: CameraModel,
    side_mm: float,
    pose: Pose,
    *,
    text: str = "qrfield",
    noise_sigma: float = 0.0,
    blur_px: float = 0.0,
    gradient: float = 0.0,
    background: np.ndarray | int = BACKGROUND_GREY,
    supersample: int = SUPERSAMPLE,
    seed: int | None = None,
    allow_partial: bool = False,
    color: bool = False,
) -> RenderedView:
    """Render the camera's view of a QR card at ``pose``.

    Args:
        camera: camera model (image size, intrinsics, distortion).
        side_mm: side L of the QR symbol without quiet zone, mm.
        pose: marker-to-camera pose (mm, degrees).
        text: QR payload.
        noise_sigma: Gaussian noise standard deviation in grey levels (0 = none).
        blur_px: Gaussian blur sigma in pixels (0 = none), e.g. defocus.
        gradient: brightness gradient across the image, relative (0.3 = +-30 % left to right).
        background: a grey level, or an (H, W) uint8 camera image behind the card (e.g. an earlier
            view: with lens distortion it is taken as already distorted and is not remapped).
        supersample: samples per pixel per axis (anti-aliasing); 1 disables it.
        seed: seed of the noise (None = fresh randomness).
        allow_partial: render even when the code is cut by the image border (for detector tests).
        color: return a 3-channel BGR image instead of grey.

    Raises:
        RenderError: the card is behind the camera, faces away, or (unless allow_partial) a vertex
            is outside the image.
    """
    if supersample < 1 or int(supersample) != supersample:
        raise ValueError(f"supersample must be a whole number >= 1, got {supersample!r}")
    corners = check_view(camera, side_mm, pose, allow_partial=allow_partial)
    modules = qr_symbol(text).shape[0]
    ideal = ideal_canvas(camera)
    ideal_camera = camera
    if camera.has_distortion:
        ideal_camera = CameraModel(
            fx=camera.fx,
            fy=camera.fy,
            cx=camera.cx - ideal.offset[0],
            cy=camera.cy - ideal.offset[1],
            width=ideal.size[0],
            height=ideal.size[1],
            name="ideal-canvas",
        )

    def view_over(behind: np.ndarray | int) -> np.ndarray:
        """The card drawn over ``behind`` on the ideal canvas, brought to camera pixels."""
        canvas = _background(behind, ideal.size, camera)
        _draw_card(canvas, ideal_camera, side_mm, pose, text, modules, int(supersample))
        return ideal.to_camera(canvas)

    if camera.has_distortion and isinstance(background, np.ndarray):
        # A background image is a camera image (already distorted): it must not go through the
        # remap. The card over black and over white gives its coverage; composite after the remap.
        _check_background_image(background, camera)
        dark = view_over(0).astype(np.float32)
        light = view_over(255).astype(np.float32)
        composite = dark + (light - dark) * (background.astype(np.float32) / 255.0)
        canvas = np.clip(composite + 0.5, 0, 255).astype(np.uint8)
    else:
        canvas = view_over(background)
    image = _degrade(canvas, noise_sigma, blur_px, gradient, seed)
    if color:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return RenderedView(image, corners, pose, camera, float(side_mm), text, modules)


def _check_background_image(background: np.ndarray, camera: CameraModel) -> None:
    if background.shape != (camera.height, camera.width) or background.dtype != np.uint8:
        raise ValueError(
            f"background must be a ({camera.height}, {camera.width}) uint8 grey image, "
            f"got {background.shape} {background.dtype}"
        )


def _background(background: np.ndarray | int, size: tuple[int, int], camera: CameraModel) -> np.ndarray:
    """The canvas to draw on: a copy of a background image (pinhole cameras only), or a grey level."""
    width, height = size
    if isinstance(background, np.ndarray):
        _check_background_image(background, camera)
        return background.copy()
    grey = int(background)
    if not 0 <= grey <= 255:
        raise ValueError(f"background grey level must be 0..255, got {grey}")
    return np.full((height, width), grey, dtype=np.uint8)


def _draw_card(
    canvas: np.ndarray, camera: CameraModel, side_mm: float, pose: Pose, text: str, modules: int, ss: int
) -> None:
    """Warp the card texture into ``canvas`` (an ideal pinhole image of ``camera``) in place."""
    card_mm = card_side_mm(side_mm, modules)
    half = card_mm / 2.0
    card_corners = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])
    card_cam = transform_points(pose.rotation, pose.position_mm, card_corners)
    if np.any(card_cam[:, 2] <= 1e-6):
        # Only the card margin crosses the camera plane: clip by drawing the symbol's surroundings
        # smaller is not worth it; such poses are far outside any working distance.
        raise RenderError("the card reaches behind the camera; move it further away")
    card_px = card_cam[:, :2] / card_cam[:, 2:3] * [camera.fx, camera.fy] + [camera.cx, camera.cy]
    height, width = canvas.shape
    x0 = max(0, math.floor(card_px[:, 0].min()) - 1)
    y0 = max(0, math.floor(card_px[:, 1].min()) - 1)
    x1 = min(width, math.ceil(card_px[:, 0].max()) + 2)
    y1 = min(height, math.ceil(card_px[:, 1].max()) + 2)
    if x1 <= x0 or y1 <= y0:
        return  # the card is entirely outside the canvas
    # Texture resolution: about one texel per supersampled pixel where the card looks largest.
    card_modules = modules + 2 * (QUIET_ZONE_MODULES + CARD_MARGIN_MODULES)
    longest_edge_px = max(np.linalg.norm(card_px[i] - card_px[(i + 1) % 4]) for i in range(4))
    texels_per_module = int(np.clip(math.ceil(ss * longest_edge_px / card_modules), 2, 48))
    texture = _card_texture(text, texels_per_module)
    texels = texture.shape[0]
    mm_per_texel = card_mm / texels
    # texel (j, i) centre -> card mm -> ideal camera pixel -> supersampled ROI pixel
    texel_to_mm = np.array(
        [
            [mm_per_texel, 0.0, -half + 0.5 * mm_per_texel],
            [0.0, mm_per_texel, -half + 0.5 * mm_per_texel],
            [0.0, 0.0, 1.0],
        ]
    )
    r = pose.rotation
    plane_to_px = camera.K @ np.column_stack([r[:, 0], r[:, 1], pose.position_mm])
    px_to_roi = np.array(
        [[ss, 0.0, ss * (0.5 - x0) - 0.5], [0.0, ss, ss * (0.5 - y0) - 0.5], [0.0, 0.0, 1.0]]
    )
    homography = px_to_roi @ plane_to_px @ texel_to_mm
    roi = canvas[y0:y1, x0:x1]
    roi_ss = cv2.resize(roi, ((x1 - x0) * ss, (y1 - y0) * ss), interpolation=cv2.INTER_NEAREST)
    cv2.warpPerspective(
        texture,
        homography,
        (roi_ss.shape[1], roi_ss.shape[0]),
        dst=roi_ss,
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_TRANSPARENT,
    )
    if ss > 1:
        roi[:] = cv2.resize(roi_ss, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
    else:
        roi[:] = roi_ss


def _degrade(
    image: np.ndarray, noise_sigma: float, blur_px: float, gradient: float, seed: int | None
) -> np.ndarray:
    """Blur, then brightness gradient, then Gaussian noise; returns uint8."""
    for name, value in (("noise_sigma", noise_sigma), ("blur_px", blur_px), ("gradient", gradient)):
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    if blur_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), sigmaX=blur_px, borderType=cv2.BORDER_REPLICATE)
    if gradient == 0 and noise_sigma == 0:
        return image
    out = image.astype(np.float32)
    if gradient > 0:
        out *= 1.0 + np.float32(gradient) * _gradient_ramp(image.shape[1], image.shape[0])
    if noise_sigma > 0:
        # OpenCV's generator is 4x faster than numpy's here; it is per thread, so seeding it
        # makes the image repeatable without touching other threads.
        cv2.setRNGSeed(int(seed) if seed is not None else int(np.random.SeedSequence().entropy % 2**31))
        noise = np.empty(out.shape, np.float32)
        cv2.randn(noise, 0.0, float(noise_sigma))
        out += noise
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)
