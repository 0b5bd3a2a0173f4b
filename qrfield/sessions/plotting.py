"""Small scatter plots drawn with OpenCV (no matplotlib): axes, ticks, labels, legend, reference lines.

A :class:`Panel` maps data to pixels inside one rectangle of a white BGR canvas; :func:`figure`
makes a canvas for a grid of panels with a title. Colours are BGR tuples.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

FONT = cv2.FONT_HERSHEY_SIMPLEX
BLACK = (0, 0, 0)
GREY = (150, 150, 150)
LIGHT = (228, 228, 228)
WHITE = (255, 255, 255)
#: Colours that stay distinct for colour-blind readers (Okabe-Ito), BGR.
BLUE = (178, 114, 0)
ORANGE = (0, 159, 230)
GREEN = (115, 158, 0)
RED = (0, 94, 213)
PURPLE = (167, 121, 204)
MARKERS = ("circle", "square", "triangle", "cross")


def nice_ticks(lo: float, hi: float, count: int = 5) -> tuple[np.ndarray, int]:
    """Round tick values covering [lo, hi] (steps 1, 2, 2.5 or 5 x 10^k) and the decimals to print."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        lo, hi = 0.0, 1.0
    if hi <= lo:
        lo, hi = lo - 1.0, hi + 1.0
    raw = (hi - lo) / max(count, 1)
    magnitude = 10.0 ** math.floor(math.log10(raw))
    step = next(m * magnitude for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * magnitude >= raw * 0.999)
    first = math.ceil(lo / step - 1e-9) * step
    ticks = np.arange(first, hi + step * 1e-6, step)
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    if abs(step / 10**-decimals - round(step / 10**-decimals)) > 1e-6:
        decimals += 1  # e.g. 2.5 needs one more digit than 2
    return ticks, decimals


def padded_range(values: Sequence[float] | np.ndarray, pad: float = 0.06) -> tuple[float, float]:
    """[min, max] of the finite values widened by ``pad`` of the span (a unit around a single value)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    if hi - lo < 1e-9:
        return lo - 1.0, hi + 1.0
    span = hi - lo
    return lo - pad * span, hi + pad * span


def text_size(text: str, scale: float, thickness: int = 1) -> tuple[int, int]:
    (w, h), _ = cv2.getTextSize(text, FONT, scale, thickness)
    return w, h


def put_text(
    img: np.ndarray,
    text: str,
    x: float,
    y: float,
    scale: float = 0.45,
    colour=BLACK,
    anchor: str = "lb",
    thickness=1,
) -> None:
    """Text anchored at (x, y): anchor letters l/c/r horizontally, t/m/b vertically."""
    w, h = text_size(text, scale, thickness)
    dx = {"l": 0, "c": -w / 2, "r": -w}[anchor[0]]
    dy = {"t": h, "m": h / 2, "b": 0}[anchor[1]]
    cv2.putText(img, text, (round(x + dx), round(y + dy)), FONT, scale, colour, thickness, cv2.LINE_AA)


def put_vertical_text(img: np.ndarray, text: str, x: float, y: float, scale: float = 0.45) -> None:
    """Text turned 90 degrees counter-clockwise, centred at (x, y) (for y-axis labels)."""
    w, h = text_size(text, scale)
    tile = np.full((h + 8, w + 4, 3), 255, np.uint8)
    cv2.putText(tile, text, (2, h + 2), FONT, scale, BLACK, 1, cv2.LINE_AA)
    tile = cv2.rotate(tile, cv2.ROTATE_90_COUNTERCLOCKWISE)
    th, tw = tile.shape[:2]
    x0, y0 = round(x - tw / 2), round(y - th / 2)
    x0, y0 = max(0, x0), max(0, y0)
    region = img[y0 : y0 + th, x0 : x0 + tw]
    np.minimum(region, tile[: region.shape[0], : region.shape[1]], out=region)


def draw_marker(img: np.ndarray, x: float, y: float, colour, marker: str = "circle", size: int = 4) -> None:
    p = (round(x), round(y))
    if marker == "circle":
        cv2.circle(img, p, size, colour, -1, cv2.LINE_AA)
    elif marker == "square":
        cv2.rectangle(img, (p[0] - size, p[1] - size), (p[0] + size, p[1] + size), colour, -1)
    elif marker == "triangle":
        pts = np.array(
            [[p[0], p[1] - size - 1], [p[0] - size - 1, p[1] + size], [p[0] + size + 1, p[1] + size]]
        )
        cv2.fillPoly(img, [pts.astype(np.int32)], colour, cv2.LINE_AA)
    else:
        cv2.line(img, (p[0] - size, p[1] - size), (p[0] + size, p[1] + size), colour, 2, cv2.LINE_AA)
        cv2.line(img, (p[0] - size, p[1] + size), (p[0] + size, p[1] - size), colour, 2, cv2.LINE_AA)


@dataclass
class Panel:
    """One plot area: ``rect`` = (left, top, width, height) of the whole panel in canvas pixels."""

    img: np.ndarray
    rect: tuple[int, int, int, int]
    xlim: tuple[float, float]
    ylim: tuple[float, float]
    title: str = ""
    xlabel: str = ""
    ylabel: str = ""
    legend: list[tuple[str, tuple[int, int, int], str]] = field(default_factory=list)
    points: list[tuple[float, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        left, top, width, height = self.rect
        # Room for tick labels and axis labels on the left and bottom, the title on top.
        self.x0, self.x1 = left + 62, left + width - 14
        self.y0, self.y1 = top + 30, top + height - 48
        self.xticks, self.xdec = nice_ticks(*self.xlim, count=6)
        self.yticks, self.ydec = nice_ticks(*self.ylim, count=6)
        self.xlim = (min(self.xlim[0], self.xticks[0]), max(self.xlim[1], self.xticks[-1]))
        self.ylim = (min(self.ylim[0], self.yticks[0]), max(self.ylim[1], self.yticks[-1]))

    def px(self, x: float, y: float) -> tuple[float, float]:
        """Canvas pixel of a data point."""
        fx = (x - self.xlim[0]) / (self.xlim[1] - self.xlim[0])
        fy = (y - self.ylim[0]) / (self.ylim[1] - self.ylim[0])
        return self.x0 + fx * (self.x1 - self.x0), self.y1 - fy * (self.y1 - self.y0)

    def draw_axes(self) -> None:
        img = self.img
        for t in self.xticks:
            x, _ = self.px(t, self.ylim[0])
            cv2.line(img, (round(x), self.y0), (round(x), self.y1), LIGHT, 1)
            cv2.line(img, (round(x), self.y1), (round(x), self.y1 + 5), BLACK, 1)
            put_text(img, f"{t:.{self.xdec}f}", x, self.y1 + 8, 0.4, anchor="ct")
        for t in self.yticks:
            _, y = self.px(self.xlim[0], t)
            cv2.line(img, (self.x0, round(y)), (self.x1, round(y)), LIGHT, 1)
            cv2.line(img, (self.x0 - 5, round(y)), (self.x0, round(y)), BLACK, 1)
            put_text(img, f"{t:.{self.ydec}f}", self.x0 - 8, y, 0.4, anchor="rm")
        cv2.rectangle(img, (self.x0, self.y0), (self.x1, self.y1), BLACK, 1)
        if self.title:
            put_text(img, self.title, (self.x0 + self.x1) / 2, self.y0 - 10, 0.5, anchor="cb", thickness=1)
        if self.xlabel:
            put_text(img, self.xlabel, (self.x0 + self.x1) / 2, self.y1 + 28, 0.45, anchor="ct")
        if self.ylabel:
            put_vertical_text(img, self.ylabel, self.rect[0] + 12, (self.y0 + self.y1) / 2)

    def _inside(self, x: float, y: float) -> bool:
        return self.x0 - 1 <= x <= self.x1 + 1 and self.y0 - 1 <= y <= self.y1 + 1

    def scatter(self, xs, ys, colour, marker: str = "circle", label: str = "") -> None:
        for x, y in zip(np.asarray(xs, float), np.asarray(ys, float), strict=True):
            if math.isfinite(x) and math.isfinite(y):
                px, py = self.px(x, y)
                if self._inside(px, py):
                    draw_marker(self.img, px, py, colour, marker)
                    self.points.append((px, py))
        if label:
            self.legend.append((label, colour, marker))

    def line(
        self, p: tuple[float, float], q: tuple[float, float], colour, label: str = "", dashed=False
    ) -> None:
        """A straight reference line between two data points, clipped to the plot area."""
        a, b = self.px(*p), self.px(*q)
        ok, pa, pb = cv2.clipLine(
            (self.x0, self.y0, self.x1 - self.x0 + 1, self.y1 - self.y0 + 1),
            (round(a[0]), round(a[1])),
            (round(b[0]), round(b[1])),
        )
        if ok:
            if dashed:
                length = math.dist(pa, pb)
                n = max(1, int(length // 8))
                for k in range(0, n, 2):
                    s = np.array(pa) + (np.array(pb) - np.array(pa)) * (k / n)
                    e = np.array(pa) + (np.array(pb) - np.array(pa)) * (min(k + 1, n) / n)
                    cv2.line(self.img, tuple(map(round, s)), tuple(map(round, e)), colour, 2, cv2.LINE_AA)
            else:
                cv2.line(self.img, pa, pb, colour, 1, cv2.LINE_AA)
        if label:
            self.legend.append((label, colour, "dash" if dashed else "line"))

    def draw_legend(self, corner: str | None = None) -> None:
        """The legend in ``corner`` ("tl", "tr", "bl", "br"), or where it hides the fewest points."""
        if not self.legend:
            return
        scale = 0.4
        width = max(text_size(label, scale)[0] for label, _, _ in self.legend) + 36
        height = 18 * len(self.legend) + 8

        def origin(c: str) -> tuple[int, int]:
            x = self.x0 + 8 if c[1] == "l" else self.x1 - width - 8
            y = self.y0 + 8 if c[0] == "t" else self.y1 - height - 8
            return x, y

        def hidden(c: str) -> int:
            x, y = origin(c)
            return sum(
                1 for px, py in self.points if x - 6 <= px <= x + width + 6 and y - 6 <= py <= y + height + 6
            )

        x, y = origin(corner or min(("tl", "tr", "bl", "br"), key=hidden))
        cv2.rectangle(self.img, (x, y), (x + width, y + height), WHITE, -1)
        cv2.rectangle(self.img, (x, y), (x + width, y + height), GREY, 1)
        for k, (label, colour, marker) in enumerate(self.legend):
            cy = y + 13 + 18 * k
            if marker in ("line", "dash"):
                cv2.line(self.img, (x + 6, cy), (x + 24, cy), colour, 2, cv2.LINE_AA)
            else:
                draw_marker(self.img, x + 15, cy, colour, marker)
            put_text(self.img, label, x + 30, cy, scale, anchor="lm")


def figure(
    columns: int, rows: int, title: str, panel_size: tuple[int, int] = (420, 330)
) -> tuple[np.ndarray, list]:
    """A white canvas for ``rows`` x ``columns`` panels under a title; returns it and the panel rects."""
    pw, ph = panel_size
    head = 36
    img = np.full((head + rows * ph, columns * pw, 3), 255, np.uint8)
    put_text(img, title, columns * pw / 2, 24, 0.6, anchor="cb", thickness=1)
    rects = [(c * pw, head + r * ph, pw, ph) for r in range(rows) for c in range(columns)]
    return img, rects
