"""Arithmetic of the numerical model, written once for Python floats and for numpy arrays.

Every function here takes its values as lists of 4 (or 6) items that are either Python floats
(the single-pose path, fast on 4 points: no numpy call overhead) or numpy arrays of shape (N,)
(the batch path, one pass of numpy per operation). Only +, -, *, / and the ``sqrt``/``maximum``
passed in are used, all correctly rounded IEEE operations applied in the same order, so both
paths give bit-identical depths and iteration counts.

Notation (docs/conventions.md): the corner i has normalised (undistorted) image coordinates (x_i, y_i), its
line of sight m_i = (x_i, y_i, 1), and the vertex V_i = z_i * m_i at depth z_i (mm). The six
lengths are the four sides V1V2, V2V3, V3V4, V4V1 (L) and the diagonals V1V3, V2V4 (L*sqrt(2)).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

#: Vertex pairs of the six lengths: four sides, then two diagonals.
PAIRS = ((0, 1), (1, 2), (2, 3), (3, 0), (0, 2), (1, 3))
#: Pivots of the 4x4 normal equations below this share of their trace count as singular.
PIVOT_FLOOR = 1e-12

Num = Any  # float or np.ndarray


def lengths_for(side: float) -> list[float]:
    """Actual lengths L_i of the six pairs in :data:`PAIRS`, mm."""
    diagonal = side * math.sqrt(2.0)
    return [side, side, side, side, diagonal, diagonal]


def gn_system(
    z: list[Num], x: list[Num], y: list[Num], lengths: list[float], sqrt: Callable
) -> tuple[list[Num], list[Num], list[Num], list[Num]]:
    """Residuals diff_k (calculated minus actual length, mm) and the normal equations J^T J, J^T diff.

    Row k of the Jacobian J = d diff_k / d z has two entries, at the pair's vertices i and j:
    (V_i - V_j) . m_i / |V_i - V_j| and -(V_i - V_j) . m_j / |V_i - V_j|. Each vertex pair
    occurs once, so the off-diagonal of J^T J is one product per pair.
    Returns (diff[6] in PAIRS order, diag[4], off[6] in PAIRS order, grad[4]). Unrolled: this is
    the inner loop of both paths.
    """
    z0, z1, z2, z3 = z
    x0, x1, x2, x3 = x
    y0, y1, y2, y3 = y
    px0, px1, px2, px3 = z0 * x0, z1 * x1, z2 * x2, z3 * x3
    py0, py1, py2, py3 = z0 * y0, z1 * y1, z2 * y2, z3 * y3
    # Pair (i, j): diff = |V_i - V_j| - L_ij, a_ij = d diff / d z_i, b_ij = d diff / d z_j.
    dx = px0 - px1
    dy = py0 - py1
    dz = z0 - z1
    d = sqrt(dx * dx + dy * dy + dz * dz)
    r01 = d - lengths[0]
    a01 = (dx * x0 + dy * y0 + dz) / d
    b01 = -(dx * x1 + dy * y1 + dz) / d
    dx = px1 - px2
    dy = py1 - py2
    dz = z1 - z2
    d = sqrt(dx * dx + dy * dy + dz * dz)
    r12 = d - lengths[1]
    a12 = (dx * x1 + dy * y1 + dz) / d
    b12 = -(dx * x2 + dy * y2 + dz) / d
    dx = px2 - px3
    dy = py2 - py3
    dz = z2 - z3
    d = sqrt(dx * dx + dy * dy + dz * dz)
    r23 = d - lengths[2]
    a23 = (dx * x2 + dy * y2 + dz) / d
    b23 = -(dx * x3 + dy * y3 + dz) / d
    dx = px3 - px0
    dy = py3 - py0
    dz = z3 - z0
    d = sqrt(dx * dx + dy * dy + dz * dz)
    r30 = d - lengths[3]
    a30 = (dx * x3 + dy * y3 + dz) / d
    b30 = -(dx * x0 + dy * y0 + dz) / d
    dx = px0 - px2
    dy = py0 - py2
    dz = z0 - z2
    d = sqrt(dx * dx + dy * dy + dz * dz)
    r02 = d - lengths[4]
    a02 = (dx * x0 + dy * y0 + dz) / d
    b02 = -(dx * x2 + dy * y2 + dz) / d
    dx = px1 - px3
    dy = py1 - py3
    dz = z1 - z3
    d = sqrt(dx * dx + dy * dy + dz * dz)
    r13 = d - lengths[5]
    a13 = (dx * x1 + dy * y1 + dz) / d
    b13 = -(dx * x3 + dy * y3 + dz) / d
    diag = [
        a01 * a01 + b30 * b30 + a02 * a02,
        b01 * b01 + a12 * a12 + a13 * a13,
        b12 * b12 + a23 * a23 + b02 * b02,
        b23 * b23 + a30 * a30 + b13 * b13,
    ]
    grad = [
        a01 * r01 + b30 * r30 + a02 * r02,
        b01 * r01 + a12 * r12 + a13 * r13,
        b12 * r12 + a23 * r23 + b02 * r02,
        b23 * r23 + a30 * r30 + b13 * r13,
    ]
    off = [a01 * b01, a12 * b12, a23 * b23, a30 * b30, a02 * b02, a13 * b13]
    return [r01, r12, r23, r30, r02, r13], diag, off, grad


def misfit(diff: list[Num]) -> Num:
    """Sum of the squared residuals diff_k (mm^2), in PAIRS order."""
    return (
        diff[0] * diff[0]
        + diff[1] * diff[1]
        + diff[2] * diff[2]
        + diff[3] * diff[3]
        + diff[4] * diff[4]
        + diff[5] * diff[5]
    )


def solve4(
    diag: list[Num], off: dict[tuple[int, int], Num], grad: list[Num], maximum: Callable
) -> tuple[list[Num], Num]:
    """Solve (J^T J) dz = J^T diff by an unrolled LDL^T factorisation; returns (dz[4], singular).

    Pivots are floored at PIVOT_FLOOR times the trace; ``singular`` is True where one was floored.
    """
    a01, a12, a23, a03, a02, a13 = off  # PAIRS order: (0,1) (1,2) (2,3) (3,0) (0,2) (1,3)
    floor = PIVOT_FLOOR * (diag[0] + diag[1] + diag[2] + diag[3])
    p0 = diag[0]
    d0 = maximum(p0, floor)
    l10 = a01 / d0
    l20 = a02 / d0
    l30 = a03 / d0
    p1 = diag[1] - l10 * l10 * d0
    d1 = maximum(p1, floor)
    l21 = (a12 - l20 * l10 * d0) / d1
    l31 = (a13 - l30 * l10 * d0) / d1
    p2 = diag[2] - l20 * l20 * d0 - l21 * l21 * d1
    d2 = maximum(p2, floor)
    l32 = (a23 - l30 * l20 * d0 - l31 * l21 * d1) / d2
    p3 = diag[3] - l30 * l30 * d0 - l31 * l31 * d1 - l32 * l32 * d2
    d3 = maximum(p3, floor)
    singular = (p0 <= floor) | (p1 <= floor) | (p2 <= floor) | (p3 <= floor)
    y0 = grad[0]
    y1 = grad[1] - l10 * y0
    y2 = grad[2] - l20 * y0 - l21 * y1
    y3 = grad[3] - l30 * y0 - l31 * y1 - l32 * y2
    x3 = y3 / d3
    x2 = y2 / d2 - l32 * x3
    x1 = y1 / d1 - l21 * x2 - l31 * x3
    x0 = y0 / d0 - l10 * x1 - l20 * x2 - l30 * x3
    return [x0, x1, x2, x3], singular


def mean_side(x: list[Num], y: list[Num], sqrt: Callable) -> Num:
    """Mean length of the four sides of the corner quadrilateral in normalised image units."""
    total: Num = 0.0
    for i, j in PAIRS[:4]:
        dx = x[i] - x[j]
        dy = y[i] - y[j]
        total = total + sqrt(dx * dx + dy * dy)
    return total / 4.0


def _det3(a: tuple[Num, Num, Num], b: tuple[Num, Num, Num], c: tuple[Num, Num, Num]) -> Num:
    """a . (b x c)."""
    return (
        a[0] * (b[1] * c[2] - b[2] * c[1])
        - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
    )


def parallelogram_depths(x: list[Num], y: list[Num], sqrt: Callable) -> tuple[list[Num], Num]:
    """Depths up to scale from V1 + V3 = V2 + V4 (the square is a parallelogram); ours, not the seed's.

    z1 m1 - z2 m2 + z3 m3 = z4 m4 is three linear equations; with z4 = 1 Cramer's rule gives z1..z3.
    Returns ([z1, z2, z3, 1], det); the caller rejects det == 0 or a non-positive depth.
    """

    m1 = (x[0], y[0], 1.0)
    m2n = (-x[1], -y[1], -1.0)
    m3 = (x[2], y[2], 1.0)
    m4 = (x[3], y[3], 1.0)
    det = _det3(m1, m2n, m3)
    return [_det3(m4, m2n, m3), _det3(m1, m4, m3), _det3(m1, m2n, m4), det], det


def scale_to_side(z: list[Num], x: list[Num], y: list[Num], lengths: list[float], sqrt: Callable) -> Num:
    """Least-squares scale s making the six lengths of s * z match the actual ones."""
    px = [z[i] * x[i] for i in range(4)]
    py = [z[i] * y[i] for i in range(4)]
    num: Num = 0.0
    den: Num = 0.0
    for k, (i, j) in enumerate(PAIRS):
        dx = px[i] - px[j]
        dy = py[i] - py[j]
        dz = z[i] - z[j]
        d = sqrt(dx * dx + dy * dy + dz * dz)
        num = num + d * lengths[k]
        den = den + d * d
    return num / den


def pose_from_vertices(
    z: list[Num], x: list[Num], y: list[Num], sqrt: Callable, maximum: Callable
) -> tuple[list[list[Num]], list[Num]]:
    """Rotation (rows of R) and centre of the solved vertices V_i = z_i m_i (our reconstruction).

    The seed extracts the orientation "using the rotation matrix" of the solved vertices; we fit the
    marker's X axis to V1->V2 (and V4->V3) and its Y axis to V1->V4 (and V2->V3) by the nearest
    orthonormal pair (polar decomposition), which is exactly the least-squares (Procrustes/Kabsch)
    rotation of the marker's four points onto the solved ones; Z = X x Y. Centre = mean vertex.
    """
    z0, z1, z2, z3 = z
    x0, x1, x2, x3 = z0 * x[0], z1 * x[1], z2 * x[2], z3 * x[3]
    y0, y1, y2, y3 = z0 * y[0], z1 * y[1], z2 * y[2], z3 * y[3]
    # a: mean of V1->V2 and V4->V3 (marker X); b: mean of V1->V4 and V2->V3 (marker Y).
    ax = (x1 - x0 + x2 - x3) * 0.5
    ay = (y1 - y0 + y2 - y3) * 0.5
    az = (z1 - z0 + z2 - z3) * 0.5
    bx = (x3 - x0 + x2 - x1) * 0.5
    by = (y3 - y0 + y2 - y1) * 0.5
    bz = (z3 - z0 + z2 - z1) * 0.5
    saa = ax * ax + ay * ay + az * az
    sbb = bx * bx + by * by + bz * bz
    sab = ax * bx + ay * by + az * bz
    s = sqrt(maximum(saa * sbb - sab * sab, 0.0))
    t = sqrt(saa + sbb + 2.0 * s)
    # sqrt of the 2x2 Gram matrix in closed form, then its inverse.
    q00 = (saa + s) / t
    q01 = sab / t
    q11 = (sbb + s) / t
    dq = q00 * q11 - q01 * q01
    i00 = q11 / dq
    i01 = -q01 / dq
    i11 = q00 / dq
    ex0, ex1, ex2 = ax * i00 + bx * i01, ay * i00 + by * i01, az * i00 + bz * i01
    ey0, ey1, ey2 = ax * i01 + bx * i11, ay * i01 + by * i11, az * i01 + bz * i11
    rows = [
        [ex0, ey0, ex1 * ey2 - ex2 * ey1],
        [ex1, ey1, ex2 * ey0 - ex0 * ey2],
        [ex2, ey2, ex0 * ey1 - ex1 * ey0],
    ]
    centre = [(x0 + x1 + x2 + x3) * 0.25, (y0 + y1 + y2 + y3) * 0.25, (z0 + z1 + z2 + z3) * 0.25]
    return rows, centre
