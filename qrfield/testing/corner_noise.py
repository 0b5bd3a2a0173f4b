"""Seeded corner noise of a known covariance: the injected truth of the uncertainty tests and of
``qrfield benchmark pose`` (sections 1, 2 and 5)."""

from __future__ import annotations

import math

import numpy as np


def random_corner_cov(rng: np.random.Generator) -> np.ndarray:
    """(4, 2, 2) px^2: a view's scale log-uniform in 0.02-0.5 px, each corner 0.5-2x that, an aspect
    up to 3:1 and any orientation (independent corners)."""
    base = math.exp(rng.uniform(math.log(0.02), math.log(0.5)))
    cov = np.empty((4, 2, 2))
    for i in range(4):
        major = base * rng.uniform(0.5, 2.0)
        minor = major / rng.uniform(1.0, 3.0)
        angle = rng.uniform(0.0, math.pi)
        rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
        cov[i] = rot @ np.diag([major**2, minor**2]) @ rot.T
    return cov


def draw_noise(rng: np.random.Generator, cov: np.ndarray) -> np.ndarray:
    """(4, 2) Gaussian corner noise with covariance ``cov`` (4, 2, 2)."""
    return np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.normal(size=(4, 2)))
