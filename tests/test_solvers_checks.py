"""Bad input is a SolverError (a ValueError) that says what is wrong; order is checked on a rendered view."""

from __future__ import annotations

import math

import numpy as np
import pytest
from solver_cases import SIDE_MM, cases

from qrfield.camera import resolve_camera
from qrfield.geometry import Pose
from qrfield.render import render_view
from qrfield.solvers import NumericalSettings, PoseResult, SolverError, solve

GOOD = [[100.0, 100.0], [200.0, 104.0], [196.0, 205.0], [98.0, 198.0]]


def _signed_area(corners) -> float:
    """Shoelace sum in image coordinates (y down); positive = clockwise on screen."""
    c = np.asarray(corners)
    return 0.5 * float(np.sum(c[:, 0] * np.roll(c[:, 1], -1) - np.roll(c[:, 0], -1) * c[:, 1]))


@pytest.mark.parametrize("gamma", [0.0, 90.0, 180.0, -135.0])
def test_rendered_views_run_clockwise_and_are_accepted(gamma):
    camera = resolve_camera("picam-v2@640x480")
    view = render_view(camera, SIDE_MM, Pose([10.0, -5.0, 300.0], [10.0, -15.0, gamma]))
    corners = view.corners_px
    if gamma == 0.0:
        # Upright code: V1 is the top-left corner, V2 to its right, V4 below it (image y down).
        assert corners[1, 0] > corners[0, 0] and corners[3, 1] > corners[0, 1]
    assert _signed_area(corners) > 0
    for method in ("numerical", "ippe"):
        r = solve(corners, camera, SIDE_MM, method)
        assert r.converged
        assert r.angles_deg[2] == pytest.approx(gamma if gamma != 180.0 else 180.0, abs=1e-6)
    with pytest.raises(SolverError, match="counter-clockwise"):
        solve(corners[::-1], camera, SIDE_MM)


@pytest.mark.parametrize(
    ("corners", "message"),
    [
        ([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]], r"shape \(4, 2\)"),
        ([[1.0, 2.0, 3.0]] * 4, r"shape \(4, 2\)"),
        ("not corners", "4 pixel pairs"),
        ([[100.0, math.nan], *GOOD[1:]], r"NaN or inf \(at V1\)"),
        ([*GOOD[:2], [math.inf, 200.0], GOOD[3]], r"NaN or inf \(at V3\)"),
        ([GOOD[0], GOOD[3], GOOD[2], GOOD[1]], "counter-clockwise"),
        ([GOOD[0], GOOD[2], GOOD[1], GOOD[3]], "self-intersecting"),
        ([GOOD[0], GOOD[1], [150.0, 120.0], GOOD[3]], "concave"),
        ([GOOD[0], [150.0, 102.0], GOOD[1], GOOD[3]], "V1, V2, V3 are collinear"),
        ([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [30.0, 0.0]], "collinear"),
        ([GOOD[0], GOOD[0], GOOD[2], GOOD[3]], "V1 and V2 coincide"),
    ],
)
def test_bad_corners_are_named(corners, message):
    camera = resolve_camera("picam-v2@640x480")
    for method in ("numerical", "ippe"):
        with pytest.raises(SolverError, match=message):
            solve(corners, camera, SIDE_MM, method)


@pytest.mark.parametrize("side", [0.0, -50.0, math.nan, math.inf, "fifty"])
def test_bad_side_is_named(side):
    camera = resolve_camera("picam-v2@640x480")
    with pytest.raises(SolverError, match="QR side must be a positive"):
        solve(GOOD, camera, side)


def test_camera_must_be_a_camera_model():
    with pytest.raises(SolverError, match="CameraModel with a focal length"):
        solve(GOOD, {"fx": 500}, SIDE_MM)
    with pytest.raises(ValueError):  # SolverError is a ValueError: the CLI reports it in one line
        solve(GOOD, None, SIDE_MM)


def test_failed_result_has_nan_pose_and_plain_json():
    r = PoseResult.failed("numerical", np.array(GOOD), "the update equations became singular")
    assert not r.converged and np.all(np.isnan(r.position_mm)) and np.all(np.isnan(r.rotation))
    js = r.to_json_dict()
    assert js["position_mm"] == [None, None, None] and js["reprojection_px"] is None
    assert js["corners"] == GOOD and js["reason"] == "the update equations became singular"


def test_json_dict_has_plain_floats():
    camera, _, corners, positions, _ = cases(10, seed=31)
    js = solve(corners[0], camera, SIDE_MM, "numerical", NumericalSettings()).to_json_dict()
    assert set(js) >= {
        "method",
        "position_mm",
        "angles_deg",
        "converged",
        "iterations",
        "reprojection_px",
        "corners",
    }
    assert set(js) >= {"reason", "ambiguity", "residual_mm"}
    assert all(type(v) is float for v in js["position_mm"] + js["angles_deg"])
    assert type(js["iterations"]) is int and type(js["converged"]) is bool
    assert js["position_mm"] == pytest.approx(positions[0].tolist(), abs=1e-6)
