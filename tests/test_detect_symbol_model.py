"""The whole-symbol fit's model (qrfield.detect.symbol_fit.darkness_at) against a direct evaluation
of its formula, point by point in float64, and its derivatives against finite differences of that
evaluation; the layout cache against layouts built afresh."""

from __future__ import annotations

import math

import numpy as np
import pytest

from qrfield.detect.symbol import QUIET_RINGS, fixed_cells
from qrfield.detect.symbol_fit import _Layout, _layout, darkness_at


def _lncosh(t: float) -> float:
    return float(np.logaddexp(t, -t)) - math.log(2.0)


def reference_darkness(uv, corner, inv_grad, colour, edge_px: float) -> np.ndarray:
    """D at each point, straight from the formula of qrfield.detect.symbol_fit's docstring: each
    cell's colour times (F(z_j) - F(z_j+1)) across u times the same across v, F the logistic of
    width s convolved with a 1 px box, F(z) = 1/2 + s/2 [ln cosh((z + 1/2)/s) - ln cosh((z - 1/2)/s)],
    z_j the distance in px to boundary j (module coordinate corner + j)."""
    s = edge_px
    out = np.empty(len(uv))
    for i in range(len(uv)):
        m = colour.shape[1]
        shares = []
        for axis in range(2):
            offset, scale = uv[i, axis] - corner[i, axis], inv_grad[i, axis]
            z = [(offset - j) * scale for j in range(m + 1)]  # px to boundary j
            f = [0.5 + s / 2.0 * (_lncosh((zj + 0.5) / s) - _lncosh((zj - 0.5) / s)) for zj in z]
            shares.append([f[j] - f[j + 1] for j in range(m)])
        along_u, along_v = shares
        out[i] = sum(colour[i, r, c] * along_v[r] * along_u[c] for r in range(m) for c in range(m))
    return out


def _points(rng: np.random.Generator, m: int, k: int):
    """k points each inside the middle cell of its window of m x m cells (as _windows makes them),
    random px per module unit and random (not only 0/1, not symmetric) cell colours."""
    corner = np.floor(rng.uniform(-4.0, 20.0, (k, 2)))
    uv = corner + (m - 1) / 2 + rng.uniform(0.0, 1.0, (k, 2))
    inv_grad = rng.uniform(0.8, 9.0, (k, 2))
    colour = rng.uniform(0.0, 1.0, (k, m, m))
    return uv, corner, inv_grad, colour


@pytest.mark.parametrize("radius", [1, 2])
@pytest.mark.parametrize("edge_px", [0.35, 0.9, 2.5])
def test_darkness_matches_the_formula_evaluated_point_by_point(radius, edge_px):
    rng = np.random.default_rng([radius, round(edge_px * 100)])
    m = 2 * radius + 1
    uv, corner, inv_grad, colour = _points(rng, m, 60)
    truth = reference_darkness(uv, corner, inv_grad, colour, edge_px)
    plain = darkness_at(uv, corner, inv_grad, colour, edge_px, derivatives=False)
    with_d, _, _ = darkness_at(uv, corner, inv_grad, colour, edge_px)
    no_s, _, d_s = darkness_at(uv, corner, inv_grad, colour, edge_px, edge_derivative=False)
    assert plain.shape == (60,)
    # float32 edge terms: 1e-6 of a grey level's share is far below noise
    np.testing.assert_allclose(plain, truth, atol=2e-6)
    np.testing.assert_array_equal(with_d, plain)
    np.testing.assert_array_equal(no_s, plain)
    assert d_s is None


@pytest.mark.parametrize("radius", [1, 2])
@pytest.mark.parametrize("edge_px", [0.5, 1.6])
def test_derivatives_match_finite_differences_of_the_formula(radius, edge_px):
    rng = np.random.default_rng([7, radius, round(edge_px * 10)])
    m = 2 * radius + 1
    uv, corner, inv_grad, colour = _points(rng, m, 40)
    _, d_uv, d_s = darkness_at(uv, corner, inv_grad, colour, edge_px)
    _, d_uv_only, none = darkness_at(uv, corner, inv_grad, colour, edge_px, edge_derivative=False)
    assert d_uv.shape == (40, 2) and d_s.shape == (40,) and none is None
    np.testing.assert_array_equal(d_uv_only, d_uv)
    h = 1e-6
    for axis in range(2):
        step = np.zeros(2)
        step[axis] = h
        fd = (
            reference_darkness(uv + step, corner, inv_grad, colour, edge_px)
            - reference_darkness(uv - step, corner, inv_grad, colour, edge_px)
        ) / (2 * h)
        np.testing.assert_allclose(d_uv[:, axis], fd, rtol=1e-4, atol=1e-4, err_msg=f"dD/d{'uv'[axis]}")
    fd_s = (
        reference_darkness(uv, corner, inv_grad, colour, edge_px + h)
        - reference_darkness(uv, corner, inv_grad, colour, edge_px - h)
    ) / (2 * h)
    np.testing.assert_allclose(d_s, fd_s, rtol=1e-4, atol=1e-4, err_msg="dD/ds")
    # the derivatives are not trivially small: a dropped term would show
    assert np.abs(d_uv).max() > 0.5 and np.abs(d_s).max() > 0.05


def test_an_equal_cell_map_shares_cells_and_edges_but_not_candidates():
    cells = fixed_cells(25)
    again = cells.copy()  # a code found again: an equal map, another object
    first = _layout(cells, 1)
    # Fills the first map's candidate cache at a module size within 5 % of the next request's.
    first.candidates(5, 5.0, 2.0, 1500)
    shared = _layout(again, 1)
    assert shared is not first and shared is _layout(again, 1)
    np.testing.assert_array_equal(shared.mids, first.mids)
    np.testing.assert_array_equal(shared.colour, first.colour)
    fresh = _Layout(again, 1).candidates(5, 5.05, 2.0, 1500)
    np.testing.assert_array_equal(shared.candidates(5, 5.05, 2.0, 1500), fresh)
    assert shared.size == 25 + 2 * QUIET_RINGS
