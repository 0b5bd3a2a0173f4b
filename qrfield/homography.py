"""Plane-to-plane homographies: from four point pairs, applied, composed, inverted; in arrays and floats.

A homography H (3, 3) maps a point (x, y) to (u, v) = (h0 . p, h1 . p) / (h2 . p) with p = (x, y, 1);
every H here is scaled so that H[2, 2] = 1. The symbol's *module square* of n modules has its corners
V1 (0, 0), V2 (n, 0), V3 (n, n), V4 (0, n) (docs/conventions.md's vertex order: V1 top-left,
clockwise on screen), so :func:`square_to_quad` is the map from module coordinates to the image (or
from the marker plane to normalised coordinates, with a scale and shift in front).

Two forms of the same maths: :class:`Homography` (a (3, 3) float64 array, for code that handles one
at a time or batches of points) and the ``*_floats`` functions on 9 Python floats, row by row, for
the per-frame paths where numpy's per-call cost dominates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def square_to_quad(x: np.ndarray, y: np.ndarray, n: float = 1.0) -> np.ndarray:
    """(..., 3, 3) homographies taking the n x n module square's corners (0, 0), (n, 0), (n, n),
    (0, n) to the quadrilaterals with corners (x[..., i], y[..., i]), i = V1..V4.

    Heckbert's closed form for the unit square (Fundamentals of Texture Mapping and Image Warping,
    1989, sec. 2.2.3), its first two columns divided by n. Quadrilaterals that admit no homography
    (three corners collinear) give NaN or inf entries, never an error (batches keep their rows)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.shape[-1:] != (4,) or y.shape != x.shape:
        raise ValueError(f"corners must be x, y of shape (..., 4) (V1..V4), got {x.shape} and {y.shape}")
    x0, x1, x2, x3 = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
    y0, y1, y2, y3 = y[..., 0], y[..., 1], y[..., 2], y[..., 3]
    sx = x0 - x1 + x2 - x3
    sy = y0 - y1 + y2 - y3
    dx1, dx2 = x1 - x2, x3 - x2
    dy1, dy2 = y1 - y2, y3 - y2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = dx1 * dy2 - dx2 * dy1
        g = (sx * dy2 - dx2 * sy) / den
        k = (dx1 * sy - sx * dy1) / den
    h = np.empty((*x.shape[:-1], 3, 3))
    q = 1.0 / n
    h[..., 0, 0] = (x1 - x0 + g * x1) * q
    h[..., 0, 1] = (x3 - x0 + k * x3) * q
    h[..., 0, 2] = x0
    h[..., 1, 0] = (y1 - y0 + g * y1) * q
    h[..., 1, 1] = (y3 - y0 + k * y3) * q
    h[..., 1, 2] = y0
    h[..., 2, 0] = g * q
    h[..., 2, 1] = k * q
    h[..., 2, 2] = 1.0
    return h


def square_to_quad_floats(n: float, quad: list[list[float]]) -> list[float] | None:
    """:func:`square_to_quad` for one quadrilateral in Python floats: the 9 entries row by row
    (h22 = 1), or None when its corners are collinear. ``quad``: V1..V4 as 4 x [x, y]."""
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = quad
    sx, sy = x0 - x1 + x2 - x3, y0 - y1 + y2 - y3
    if sx == 0.0 and sy == 0.0:  # a parallelogram: an affine map
        g = k = 0.0
    else:
        dx1, dx2, dy1, dy2 = x1 - x2, x3 - x2, y1 - y2, y3 - y2
        den = dx1 * dy2 - dx2 * dy1
        if den == 0.0:
            return None
        g, k = (sx * dy2 - dx2 * sy) / den, (dx1 * sy - sx * dy1) / den
    q = 1.0 / n
    return [
        (x1 - x0 + g * x1) * q,
        (x3 - x0 + k * x3) * q,
        x0,
        (y1 - y0 + g * y1) * q,
        (y3 - y0 + k * y3) * q,
        y0,
        g * q,
        k * q,
        1.0,
    ]


def apply_floats(h: list[float], x: float, y: float) -> tuple[float, float]:
    """The point (x, y) through the homography ``h`` (9 floats, row by row)."""
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = h
    w = h20 * x + h21 * y + h22
    return (h00 * x + h01 * y + h02) / w, (h10 * x + h11 * y + h12) / w


def determinant_floats(h: list[float]) -> float:
    """det H of 9 floats, row by row."""
    a, b, c, d, e, f, g, hh, i = h
    return a * (e * i - f * hh) - b * (d * i - f * g) + c * (d * hh - e * g)


def usable_floats(h: list[float]) -> bool:
    """A finite homography (9 floats, row by row) with |det| >= 1e-12: one that can be inverted."""
    return math.isfinite(sum(h)) and abs(determinant_floats(h)) >= 1e-12


@dataclass(frozen=True)
class Homography:
    """One homography, a (3, 3) float64 matrix with H[2, 2] = 1 (see the module doc)."""

    matrix: np.ndarray

    def __post_init__(self) -> None:
        m = np.array(self.matrix, dtype=np.float64)
        if m.shape != (3, 3):
            raise ValueError(f"a homography is a (3, 3) matrix, got shape {m.shape}")
        if not np.all(np.isfinite(m)) or m[2, 2] == 0.0:
            raise ValueError("a homography must be finite with H[2, 2] != 0")
        m = m / m[2, 2]
        m.setflags(write=False)
        object.__setattr__(self, "matrix", m)

    @classmethod
    def from_points(cls, src: np.ndarray, dst: np.ndarray) -> Homography:
        """The homography taking four points ``src`` (4, 2) to ``dst`` (4, 2), in float64 (the
        8 x 8 linear system; cv2.getPerspectiveTransform solves the same one in float32).
        ValueError when three points of either set are collinear."""
        src = np.asarray(src, dtype=np.float64)
        dst = np.asarray(dst, dtype=np.float64)
        if src.shape != (4, 2) or dst.shape != (4, 2):
            raise ValueError(f"four point pairs (4, 2) expected, got {src.shape} and {dst.shape}")
        a = np.zeros((8, 8))
        b = np.zeros(8)
        for i, ((x, y), (u, v)) in enumerate(zip(src.tolist(), dst.tolist(), strict=True)):
            a[2 * i] = [x, y, 1, 0, 0, 0, -u * x, -u * y]
            a[2 * i + 1] = [0, 0, 0, x, y, 1, -v * x, -v * y]
            b[2 * i], b[2 * i + 1] = u, v
        try:
            h = np.linalg.solve(a, b)
        except np.linalg.LinAlgError:
            raise ValueError("no homography: three of the four points are collinear") from None
        return cls(np.append(h, 1.0).reshape(3, 3))

    @classmethod
    def square(cls, n: float, corners: np.ndarray) -> Homography:
        """The map from the n x n module square to ``corners`` (4, 2), V1..V4 (:func:`square_to_quad`)."""
        c = np.asarray(corners, dtype=np.float64)
        if c.shape != (4, 2):
            raise ValueError(f"corners must have shape (4, 2) (V1..V4), got {c.shape}")
        return cls(square_to_quad(c[:, 0], c[:, 1], n))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Points (..., 2) through the homography, float64 (..., 2)."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (2,):
            raise ValueError(f"points must have shape (..., 2), got {p.shape}")
        m = self.matrix
        q = p @ m[:, :2].T + m[:, 2]
        return q[..., :2] / q[..., 2:3]

    def compose(self, first: Homography) -> Homography:
        """self o first: ``first`` applied, then this one."""
        return Homography(self.matrix @ first.matrix)

    def inverse(self) -> Homography:
        """The inverse map; ValueError when the matrix is singular."""
        try:
            return Homography(np.linalg.inv(self.matrix))
        except np.linalg.LinAlgError:
            raise ValueError("the homography is singular: it has no inverse") from None

    def square_corners(self, n: float) -> np.ndarray:
        """(4, 2) images of the n x n square's corners (0, 0), (n, 0), (n, n), (0, n): V1..V4."""
        return self.apply(np.array([[0.0, 0.0], [n, 0.0], [n, n], [0.0, n]]))

    def floats(self) -> list[float]:
        """The 9 entries row by row, for the ``*_floats`` functions."""
        return self.matrix.reshape(9).tolist()
