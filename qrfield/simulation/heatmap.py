"""Heatmap images of the largest solvable angle over the x-y grid, drawn with OpenCV only.

One image per combination and z: a panel per solver side by side, x to the right and y downward
(the camera frame, so the map looks like the camera's view), the angle written in each cell, a
colour bar (viridis, 0 to the sweep limit) and a legend for cells without a solvable angle.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from qrfield.sessions.plotting import BLACK, FONT, WHITE

#: Cells whose sweep failed at t = 0 (no solvable angle).
NONE_COLOUR = (40, 40, 40)
#: Cells out of view already at t = 0.
OUT_COLOUR = (205, 205, 205)
#: Cells not run (a stopped study).
NOT_RUN_COLOUR = (245, 245, 245)

CELL_OUT_OF_VIEW, CELL_NONE, CELL_NOT_RUN = "out of view at 0 deg", "fails at 0 deg", "not run"


def colours(values: np.ndarray, limit: float) -> np.ndarray:
    """(..., 3) uint8 BGR viridis colours of angles 0..limit."""
    v = np.clip(np.nan_to_num(np.asarray(values, float)) / limit, 0.0, 1.0)
    grey = np.round(v * 255).astype(np.uint8).reshape(-1, 1)
    return cv2.applyColorMap(grey, cv2.COLORMAP_VIRIDIS).reshape(*np.shape(values), 3)


def _text(
    img: np.ndarray,
    text: str,
    org: tuple[int, int],
    scale: float,
    colour=BLACK,
    thick: int = 1,
    align: str = "left",
) -> None:
    (w, _h), _ = cv2.getTextSize(text, FONT, scale, thick)
    x, y = org
    if align == "center":
        x -= w // 2
    elif align == "right":
        x -= w
    cv2.putText(img, text, (x, y), FONT, scale, colour, thick, cv2.LINE_AA)


def _ticks(values: np.ndarray, room_px: float, label_px: float) -> list[int]:
    """Indices of the values to label so that labels do not overlap."""
    every = max(1, math.ceil(label_px / max(room_px, 1.0)))
    return list(range(0, values.size, every))


def draw_heatmap(
    maps: list[np.ndarray],
    kinds: list[np.ndarray],
    panel_titles: list[str],
    x_mm: np.ndarray,
    y_mm: np.ndarray,
    limit_deg: float,
    title: str,
    subtitle: str = "",
    view_ended: list[np.ndarray] | None = None,
) -> np.ndarray:
    """A BGR image of one or more (ny, nx) maps of the largest solvable angle (degrees).

    Args:
        maps: per panel, (ny, nx) angles in degrees (NaN where none).
        kinds: per panel, (ny, nx) str array: "" for a value, or CELL_OUT_OF_VIEW / CELL_NONE /
            CELL_NOT_RUN.
        panel_titles: one per panel (solver key).
        x_mm, y_mm: grid values, mm (columns and rows).
        limit_deg: top of the colour scale (the sweep limit).
        title, subtitle: text above the panels.
        view_ended: per panel, (ny, nx) bool: the sweep ended because the card left the view (not by
            a failure); such cells get a dot in their top-right corner.
    """
    ny, nx = y_mm.size, x_mm.size
    cell = int(np.clip(400 // max(nx, ny), 22, 72))
    value_scale = 0.36 * cell / 40
    left, top, gap, bottom = 78, 92 if subtitle else 70, 46, 70
    panel_w, panel_h = nx * cell, ny * cell
    bar_w, bar_room = 18, 150
    width = left + len(maps) * panel_w + (len(maps) - 1) * gap + 40 + bar_room
    width = max(width, 560)
    height = top + panel_h + bottom + 48
    img = np.full((height, width, 3), 255, np.uint8)
    _text(img, title, (12, 26), 0.62, BLACK, 1)
    if subtitle:
        _text(img, subtitle, (12, 50), 0.45, (60, 60, 60), 1)
    tick_scale = 0.4
    for p, (values, kind, name) in enumerate(zip(maps, kinds, panel_titles, strict=True)):
        x0 = left + p * (panel_w + gap)
        y0 = top
        _text(img, name, (x0 + panel_w // 2, y0 - 10), 0.5, BLACK, 1, "center")
        cols = colours(values, limit_deg)
        for iy in range(ny):
            for ix in range(nx):
                k = kind[iy, ix]
                colour = {
                    CELL_OUT_OF_VIEW: OUT_COLOUR,
                    CELL_NONE: NONE_COLOUR,
                    CELL_NOT_RUN: NOT_RUN_COLOUR,
                }.get(k, tuple(int(c) for c in cols[iy, ix]))
                p0 = (x0 + ix * cell, y0 + iy * cell)
                p1 = (p0[0] + cell - 1, p0[1] + cell - 1)
                cv2.rectangle(img, p0, p1, colour, -1)
                if k == "":
                    label = f"{values[iy, ix]:.0f}"
                    brightness = 0.114 * colour[0] + 0.587 * colour[1] + 0.299 * colour[2]
                    ink = BLACK if brightness > 110 else WHITE
                    _text(
                        img,
                        label,
                        (p0[0] + cell // 2, p0[1] + cell // 2 + int(5 * value_scale / 0.36)),
                        value_scale,
                        ink,
                        1,
                        "center",
                    )
                    if view_ended is not None and view_ended[p][iy, ix]:
                        cv2.circle(img, (p1[0] - 6, p0[1] + 6), 3, ink, -1, cv2.LINE_AA)
                elif k == CELL_NONE:
                    _text(
                        img, "x", (p0[0] + cell // 2, p0[1] + cell // 2 + 4), value_scale, WHITE, 1, "center"
                    )
        cv2.rectangle(img, (x0 - 1, y0 - 1), (x0 + panel_w, y0 + panel_h), (90, 90, 90), 1)
        # x ticks below the panel
        for ix in _ticks(x_mm, cell, 38):
            cx = x0 + ix * cell + cell // 2
            cv2.line(img, (cx, y0 + panel_h), (cx, y0 + panel_h + 4), BLACK, 1)
            _text(img, f"{x_mm[ix]:g}", (cx, y0 + panel_h + 18), tick_scale, BLACK, 1, "center")
        _text(img, "x (mm)", (x0 + panel_w // 2, y0 + panel_h + 38), 0.45, BLACK, 1, "center")
        # y ticks on the left of every panel (y grows downward, as in the camera frame)
        for iy in _ticks(y_mm, cell, 16):
            cy = y0 + iy * cell + cell // 2
            cv2.line(img, (x0 - 5, cy), (x0 - 1, cy), BLACK, 1)
            _text(img, f"{y_mm[iy]:g}", (x0 - 8, cy + 5), tick_scale, BLACK, 1, "right")
        if p == 0:
            _text(img, "y (mm)", (x0 - 8, y0 - 10), 0.45, BLACK, 1, "right")
    # colour bar
    bx = left + len(maps) * panel_w + (len(maps) - 1) * gap + 40
    by0, by1 = top, top + panel_h
    ramp = np.linspace(limit_deg, 0.0, by1 - by0)
    bar = colours(ramp, limit_deg)[:, None, :].repeat(bar_w, axis=1)
    img[by0:by1, bx : bx + bar_w] = bar
    cv2.rectangle(img, (bx - 1, by0 - 1), (bx + bar_w, by1), (90, 90, 90), 1)
    step = _nice_step(limit_deg, max(2, (by1 - by0) // 28))
    tick = 0.0
    while tick <= limit_deg + 1e-9:
        ty = round(by1 - 1 - tick / limit_deg * (by1 - by0 - 1))
        cv2.line(img, (bx + bar_w, ty), (bx + bar_w + 4, ty), BLACK, 1)
        _text(img, f"{tick:g}", (bx + bar_w + 7, ty + 5), tick_scale, BLACK, 1)
        tick += step
    _text(img, "deg", (bx, by0 - 10), 0.45, BLACK, 1)
    # legend
    ly = height - 34
    lx = 12
    for colour, label in ((NONE_COLOUR, CELL_NONE + " (x)"), (OUT_COLOUR, CELL_OUT_OF_VIEW)):
        cv2.rectangle(img, (lx, ly - 11), (lx + 14, ly + 1), colour, -1)
        cv2.rectangle(img, (lx, ly - 11), (lx + 14, ly + 1), (90, 90, 90), 1)
        _text(img, label, (lx + 20, ly), 0.42, BLACK, 1)
        lx += 30 + cv2.getTextSize(label, FONT, 0.42, 1)[0][0]
    if view_ended is not None:
        ly += 20
        cv2.circle(img, (19, ly - 5), 3, BLACK, -1, cv2.LINE_AA)
        _text(img, "the sweep ended when the card left the view (not by a failure)", (32, ly), 0.42)
    return img


def _nice_step(limit: float, max_ticks: int) -> float:
    """A round tick step (1, 2, 5 x 10^k) giving at most ``max_ticks`` intervals."""
    raw = limit / max_ticks
    base = 10 ** math.floor(math.log10(raw)) if raw > 0 else 1.0
    for m in (1, 2, 2.5, 5, 10):
        if m * base >= raw:
            return m * base
    return 10 * base
