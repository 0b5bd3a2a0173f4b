"""Small dense linear systems (up to about 16 x 16) without numpy.linalg's per-call overhead.

np.linalg.solve and np.linalg.inv spend 5-20 us per call on their checks and dispatch on such
sizes; cv2.solve and cv2.invert (LAPACK-free LU or Cholesky in C++) take a quarter to a half of
that. The per-frame paths (the tracker's warm fit, one corner set's uncertainty) call these a few
times per frame. Where cv2 reports a singular (or, for Cholesky, not positive definite) matrix,
numpy.linalg does the work, so a singular matrix raises np.linalg.LinAlgError as numpy's own call would.
"""

from __future__ import annotations

import numpy as np


def small_solve(a: np.ndarray, b: np.ndarray, symmetric: bool = False) -> np.ndarray:
    """a^-1 b for a small square float64 matrix ``a`` (n, n) and ``b`` (n, k) or (n,) (the result
    has b's shape); ``symmetric``: ``a`` is symmetric positive definite (Cholesky)."""
    import cv2

    rhs = b[:, None] if b.ndim == 1 else b
    ok, out = cv2.solve(
        np.ascontiguousarray(a),
        np.ascontiguousarray(rhs),
        flags=cv2.DECOMP_CHOLESKY if symmetric else cv2.DECOMP_LU,
    )
    if not ok:
        return np.linalg.solve(a, b)
    return out[:, 0] if b.ndim == 1 else out


def small_inverse(a: np.ndarray, symmetric: bool = False) -> np.ndarray:
    """a^-1 for a small square float64 matrix; ``symmetric``: positive definite (Cholesky)."""
    import cv2

    ok, out = cv2.invert(np.ascontiguousarray(a), flags=cv2.DECOMP_CHOLESKY if symmetric else cv2.DECOMP_LU)
    return out if ok else np.linalg.inv(a)
