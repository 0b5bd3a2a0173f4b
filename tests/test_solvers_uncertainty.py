"""Pose uncertainty (docs/conventions.md "Pose uncertainty", docs/uncertainty.md): the propagated
covariance against central differences through the actual solvers and against Monte-Carlo spreads;
calibration and the flip flag on seeded views with a known injected corner noise (independent
truth: the vertices' exact pixels plus noise drawn from that covariance); input checks."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
from solver_cases import DISTORTED, SIDE_MM, cases

from qrfield.camera import resolve_camera
from qrfield.geometry import (
    Pose,
    angle_difference,
    angles_from_rotation,
    marker_vertices,
    project_points,
    rotation_matrix,
)
from qrfield.methods import METHODS
from qrfield.solvers import SolverError, solve, solve_batch
from qrfield.solvers import uncertainty as unc
from qrfield.testing.corner_noise import draw_noise, random_corner_cov
from qrfield.testing.pose_views import corner_set

CAMERAS = ("picam-v2@640x480", DISTORTED.name)


def _pose_vector(result) -> np.ndarray:
    return np.concatenate([result.position_mm, result.angles_deg])


def _central_differences(corners, camera, method, h=1e-2) -> np.ndarray:
    """(6, 8) d(x, y, z, alpha, beta, gamma)/d(corner pixels) through qrfield.solvers.solve itself."""
    out = np.zeros((6, 8))
    for k in range(8):
        step = np.zeros(8)
        step[k] = h
        plus = solve(corners + step.reshape(4, 2), camera, SIDE_MM, method)
        minus = solve(corners - step.reshape(4, 2), camera, SIDE_MM, method)
        diff = _pose_vector(plus) - _pose_vector(minus)
        diff[3:] = angle_difference(plus.angles_deg, minus.angles_deg)
        out[:, k] = diff / (2 * h)
    return out


@pytest.mark.parametrize("camera_name", CAMERAS)
@pytest.mark.parametrize("method", METHODS)
def test_propagated_covariance_equals_central_differences_through_the_solver(camera_name, method):
    """For exact corners the analytic Jacobian is exact: J Sigma J^T with J by central differences
    of the real solver (undistortion, iteration, pose extraction and all) must agree."""
    camera, _, corners, _, _ = cases(12, seed=71, camera_name=camera_name)
    rng = np.random.default_rng(5)
    for c in corners[:6]:
        cov = random_corner_cov(rng)
        result = solve(c, camera, SIDE_MM, method, corners_cov=cov)
        jac = _central_differences(c, camera, method)
        sigma = np.zeros((8, 8))
        for i in range(4):
            sigma[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = cov[i]
        expected = jac @ sigma @ jac.T
        scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
        # IPPE's own LM stops at its tolerance: its differences carry ~3e-4 relative noise.
        assert np.abs(result.pose_cov - expected).max() / scale.max() < 5e-3
        np.testing.assert_allclose(result.position_std_mm, np.sqrt(np.diag(expected)[:3]), rtol=5e-3)
        np.testing.assert_allclose(result.angles_std_deg, np.sqrt(np.diag(expected)[3:]), rtol=5e-3)
        np.testing.assert_allclose(result.corners_std_px, np.sqrt(cov[:, 0, 0] + cov[:, 1, 1]))


@pytest.mark.slow
@pytest.mark.parametrize("camera_name", CAMERAS)
@pytest.mark.parametrize("method", METHODS)
def test_monte_carlo_spread_matches_the_reported_std(camera_name, method):
    """400 noisy draws of one seeded view: the sample std of each component against the std reported
    for the exact corners (the sample std of 400 draws is good to about 3.5 %: 15 % is > 4 sigma)."""
    camera = DISTORTED if camera_name == DISTORTED.name else resolve_camera(camera_name)
    truth = Pose([40.0, -25.0, 320.0], [20.0, -15.0, 30.0])
    exact = truth.corners_px(camera, SIDE_MM)
    rng = np.random.default_rng(9)
    cov = np.empty((4, 2, 2))  # 0.15-0.4 px, aspect 2:1, each corner turned another way
    for i, (major, turn) in enumerate(((0.3, 0.2), (0.4, 1.1), (0.2, 2.0), (0.3, 2.9))):
        rot = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
        cov[i] = rot @ np.diag([major**2, (major / 2) ** 2]) @ rot.T
    reported = solve(exact, camera, SIDE_MM, method, corners_cov=cov)
    samples = []
    for _ in range(400):
        r = solve(exact + draw_noise(rng, cov), camera, SIDE_MM, method)
        assert r.converged
        samples.append(np.concatenate([r.position_mm, angle_difference(r.angles_deg, truth.angles_deg)]))
    spread = np.std(np.array(samples), axis=0, ddof=1)
    std = np.concatenate([reported.position_std_mm, reported.angles_std_deg])
    np.testing.assert_allclose(spread, std, rtol=0.15)


@pytest.fixture(scope="module")
def noisy_views():
    """Seeded views (sides 30/50/100 mm, z 150-1000 mm, tilt <= 60 deg, pinhole and distorted) with
    a known per-corner anisotropic covariance (0.01-1 px) and noise drawn from it, solved by both."""
    views = corner_set(500, seed=3)
    rng = np.random.default_rng(4)
    out = {m: [] for m in METHODS}
    for view in views:
        cov = random_corner_cov(rng)
        corners = view.corners_px + draw_noise(rng, cov)
        for method in METHODS:
            r = solve(corners, view.camera, view.side_mm, method, corners_cov=cov)
            if r.converged:
                err_pos = r.position_mm - view.truth.position_mm
                err = np.concatenate([err_pos, angle_difference(r.angles_deg, view.truth.angles_deg)])
                out[method].append((err / _std(r), r.ambiguous, np.abs(err[3:]).max()))
    return out


def _std(result) -> np.ndarray:
    return np.concatenate([result.position_std_mm, result.angles_std_deg])


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
def test_std_is_calibrated_against_the_injected_noise(noisy_views, method):
    """Targets (issue 13): RMS of error / std in 0.7-1.4 and 90-99 % within 2, per component, over
    the views the mirror test leaves unflagged (near the planar ambiguity the linearisation fails:
    the flag is there for those). Measured here 0.97-1.03 and 94-96 %."""
    rows = noisy_views[method]
    z = np.array([r[0] for r in rows])
    flagged = np.array([r[1] for r in rows])
    assert len(rows) > 450 and 0.02 < flagged.mean() < 0.3
    rms = np.sqrt(np.mean(z[~flagged] ** 2, axis=0))
    within = np.mean(np.abs(z[~flagged]) < 2.0, axis=0)
    assert np.all((rms > 0.7) & (rms < 1.4)), rms
    assert np.all((within > 0.90) & (within < 0.99)), within


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
def test_flip_flag_catches_the_flips(noisy_views, method):
    """Flips (an angle more than 10 deg off) on these views: the flag catches at least 90 % (measured
    100 %). Its precision (measured 20-30 %) cannot reach the issue's 50 % for a solver that
    reports the better-fitting branch (docs/uncertainty.md); the floor here catches a flag raised on
    everything."""
    rows = noisy_views[method]
    flagged = np.array([r[1] for r in rows])
    flip = np.array([r[2] for r in rows]) > 10.0
    assert flip.sum() >= 5  # the seeded set has flips, so the recall is measured
    assert np.sum(flagged & flip) / flip.sum() >= 0.9
    assert np.sum(flagged & flip) / flagged.sum() > 0.12


def test_unknown_covariance_leaves_the_std_unknown_and_json_null():
    camera, _, corners, _, _ = cases(5, seed=72)
    for method in METHODS:
        r = solve(corners[0], camera, SIDE_MM, method)
        assert np.all(np.isnan(r.position_std_mm)) and np.all(np.isnan(r.angles_std_deg))
        assert np.all(np.isnan(r.corners_std_px)) and np.all(np.isnan(r.pose_cov))
        data = json.loads(json.dumps(r.to_json_dict(), allow_nan=False))
        assert data["position_std_mm"] == [None] * 3 and data["angles_std_deg"] == [None] * 3
        assert data["corners_std_px"] == [None] * 4 and data["ambiguous"] is False
        known = solve(corners[0], camera, SIDE_MM, method, corners_cov=unc.isotropic_cov(0.1)).to_json_dict()
        assert all(v > 0 for v in known["position_std_mm"] + known["angles_std_deg"])
        assert known["corners_std_px"] == pytest.approx([0.1 * math.sqrt(2.0)] * 4)


def test_std_scales_with_the_corner_std_and_exact_corners_are_not_ambiguous():
    camera, _, corners, _, _ = cases(5, seed=73)
    for method in METHODS:
        small = solve(corners[1], camera, SIDE_MM, method, corners_cov=unc.isotropic_cov(0.05))
        big = solve(corners[1], camera, SIDE_MM, method, corners_cov=unc.isotropic_cov(0.5))
        np.testing.assert_allclose(_std(big), 10.0 * _std(small), rtol=1e-9)
        assert not small.ambiguous and small.chi2 < 1e-6  # exact corners fit; their mirror does not
        zero = solve(corners[1], camera, SIDE_MM, method, corners_cov=np.zeros((4, 2, 2)))
        assert np.all(_std(zero) == 0.0) and not zero.ambiguous


def test_unconverged_results_carry_no_pose_std():
    camera, _, corners, _, _ = cases(5, seed=74)
    from qrfield.solvers import NumericalSettings

    noisy = corners[0] + np.random.default_rng(1).normal(0.0, 0.3, (4, 2))  # no depths fit 1e-9 mm
    r = solve(
        noisy,
        camera,
        SIDE_MM,
        "numerical",
        NumericalSettings(n_max=1, tolerance_mm=1e-9, stop="seed"),
        corners_cov=unc.isotropic_cov(0.1),
    )
    assert not r.converged and np.all(np.isnan(_std(r))) and not r.ambiguous
    assert np.all(r.corners_std_px > 0)


@pytest.mark.parametrize(
    ("cov", "message"),
    [
        (np.zeros((4, 2)), "shape"),
        (np.full((4, 2, 2), np.nan), "NaN"),
        (np.array([[[1.0, 0.5], [0.0, 1.0]]] * 4), "symmetric"),
        (np.array([[[-1.0, 0.0], [0.0, 1.0]]] * 4), "not a covariance"),
        (np.array([[[1.0, 2.0], [2.0, 1.0]]] * 4), "not a covariance"),
        ("0.1", "shape"),
    ],
)
def test_bad_covariances_are_refused_by_name(cov, message):
    camera, _, corners, _, _ = cases(5, seed=75)
    with pytest.raises(SolverError, match=message):
        solve(corners[0], camera, SIDE_MM, corners_cov=cov)
    with pytest.raises(SolverError, match="finite number of pixels"):
        unc.isotropic_cov(-0.1)


@pytest.mark.slow
@pytest.mark.parametrize("camera_name", CAMERAS)
@pytest.mark.parametrize("method", METHODS)
def test_batch_std_equals_the_single_solve(camera_name, method):
    camera, _, corners, _, _ = cases(40, seed=76, camera_name=camera_name)
    rng = np.random.default_rng(6)
    covs = np.array([random_corner_cov(rng) for _ in corners])
    noisy = corners + np.array([draw_noise(rng, c) for c in covs])
    noisy[3] = np.nan  # an unusable row stays unknown
    batch = solve_batch(noisy, camera, SIDE_MM, method=method, corners_cov=covs)
    assert np.all(np.isnan(batch.position_std_mm[3])) and not batch.valid[3]
    # numerical: the same iterations bit for bit; ippe: the vectorised IPPE's LM and OpenCV's stop
    # at slightly different points of the same minimum (up to 3e-3 mm apart on noisy corners), so
    # the stds, evaluated there, agree to about 1e-4 (an uncertainty needs no more).
    rtol = 1e-9 if method == "numerical" else 1e-3
    for i in np.flatnonzero(batch.converged):
        single = solve(noisy[i], camera, SIDE_MM, method, corners_cov=covs[i])
        np.testing.assert_allclose(batch.position_std_mm[i], single.position_std_mm, rtol=rtol)
        np.testing.assert_allclose(batch.angles_std_deg[i], single.angles_std_deg, rtol=rtol)
    np.testing.assert_allclose(batch.corners_std_px, np.sqrt(covs[..., 0, 0] + covs[..., 1, 1]))
    plain = solve_batch(noisy, camera, SIDE_MM, method=method)
    assert np.all(np.isnan(plain.angles_std_deg))


def test_euler_jacobian_against_finite_differences_and_nan_at_gimbal_lock():
    rng = np.random.default_rng(7)
    for _ in range(5):
        angles = rng.uniform([-170, -80, -170], [170, 80, 170])
        rotation = rotation_matrix(angles)
        numeric = np.zeros((3, 3))
        for k in range(3):
            omega = np.zeros(3)
            omega[k] = 1e-6
            plus = angles_from_rotation(cv2.Rodrigues(omega)[0] @ rotation)  # exp([omega]x) R
            minus = angles_from_rotation(cv2.Rodrigues(-omega)[0] @ rotation)
            numeric[:, k] = angle_difference(plus, minus) / 2e-6
        np.testing.assert_allclose(unc.euler_jacobian(angles), numeric, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(unc.euler_jacobian(angles[None])[0], numeric, rtol=1e-5, atol=1e-6)
    assert np.all(np.isnan(unc.euler_jacobian(np.array([10.0, 90.0, 0.0]))[0, 1:]))


def test_distortion_jacobian_against_opencv_model_finite_differences():
    points = np.array([[-0.4, -0.3], [0.1, 0.2], [0.35, -0.05], [0.0, 0.0]])
    numeric = np.zeros((4, 2, 2))
    for k in range(2):
        step = np.zeros(2)
        step[k] = 1e-7

        def distorted(p):
            pix = project_points(np.column_stack([p, np.ones(len(p))]), DISTORTED)
            return (pix - [DISTORTED.cx, DISTORTED.cy]) / [DISTORTED.fx, DISTORTED.fy]

        numeric[:, :, k] = (distorted(points + step) - distorted(points - step)) / 2e-7
    analytic = unc.distortion_jacobian(points[:, 0], points[:, 1], DISTORTED)
    np.testing.assert_allclose(analytic, numeric, atol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("camera_name", ["picam-v2@640x480", DISTORTED.name])
def test_solve_methods_gives_what_solve_gives_method_by_method(camera_name):
    """The pipeline solves every method in one call (the checks, undistortion and uncertainty once):
    the same poses, stds and flags as one solve per method, to float rounding."""
    from qrfield.solvers import solve_methods

    camera, _, corners, *_ = cases(30, seed=41, camera_name=camera_name)
    rng = np.random.default_rng(4)
    for c in corners:
        cov = random_corner_cov(rng)
        noisy = c + draw_noise(rng, cov)
        together = solve_methods(noisy, camera, SIDE_MM, METHODS, None, cov)
        assert list(together) == list(METHODS)
        for method in METHODS:
            alone, both = solve(noisy, camera, SIDE_MM, method, corners_cov=cov), together[method]
            assert both.converged == alone.converged and both.ambiguous == alone.ambiguous
            for name in ("position_mm", "angles_deg", "position_std_mm", "angles_std_deg", "corners_std_px"):
                np.testing.assert_allclose(getattr(both, name), getattr(alone, name), rtol=1e-9, atol=1e-12)
            assert both.chi2 == pytest.approx(alone.chi2, rel=1e-9, abs=1e-12)


# ---------------------------------------------------------------------- ambiguity: one definition
def test_ambiguity_ratio_by_hand():
    # Better-fitting over worse-fitting RMS error, whichever is given first: in [0, 1].
    assert unc.ambiguity_ratio(0.3, 0.6) == pytest.approx(0.5)
    assert unc.ambiguity_ratio(0.6, 0.3) == pytest.approx(0.5)  # this pose fits worse: still 0.5
    assert unc.ambiguity_ratio(0.0, 0.0) == 1.0  # both exact: indistinguishable
    assert unc.ambiguity_ratio(0.2, math.inf) == 0.0
    assert math.isnan(unc.ambiguity_ratio(math.nan, 1.0))


def _rms_reprojection_by_opencv(result, corners, camera) -> float:
    """RMS px between ``corners`` and the square V1..V4 of side SIDE_MM placed by ``result``
    (docs/conventions.md marker frame: V1 (-L/2, -L/2), V2 (+L/2, -L/2), V3 (+L/2, +L/2), V4),
    projected by cv2.projectPoints: an answer computed without the solvers' own code."""
    h = SIDE_MM / 2.0
    square = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    rvec, _ = cv2.Rodrigues(np.asarray(result.rotation, dtype=float))
    pixels, _ = cv2.projectPoints(
        square,
        rvec,
        np.asarray(result.position_mm, dtype=float),
        camera.K,
        np.asarray(camera.dist, dtype=float),
    )
    return float(np.sqrt(np.mean(np.sum((pixels.reshape(4, 2) - corners) ** 2, axis=1))))


#: Hand-made views (true pose, solver settings, whether the answer fits better than its mirror).
#: The second: the numerical model from the seed's equal-depth guess with a loose stop settles on
#: the mirror side, so the mirror fits better (this/mirror would be 6.7; the ratio stays below 1).
AMBIGUITY_VIEWS = [
    ("numerical", [25.0, -15.0, 10.0], 400.0, None, True),
    (
        "numerical",
        [40.0, 40.0, 0.0],
        500.0,
        {"initial_guess": "seed", "tolerance_mm": 1.0, "stop": "settled"},
        False,
    ),
    ("ippe", [25.0, -15.0, 10.0], 400.0, None, True),
    ("ippe", [40.0, 40.0, 0.0], 500.0, None, True),
]


@pytest.mark.parametrize(("method", "angles", "z_mm", "settings", "answer_fits_better"), AMBIGUITY_VIEWS)
def test_ambiguity_is_the_same_ratio_for_both_methods_on_hand_made_views(
    method, angles, z_mm, settings, answer_fits_better
):
    """A card at (20, -10, z) mm at the given angles, its corners projected by OpenCV and V3 pushed
    0.6 px right and 0.4 px down by hand: both poses of the planar ambiguity fit it with some error.
    For either method ``ambiguity`` is min/max of the two RMS reprojection errors, each measured
    here with cv2.projectPoints, whichever of the two fits better."""
    from qrfield.solvers import settings_class

    camera = resolve_camera("picam-v2@640x480")
    h = SIDE_MM / 2.0
    square = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    rvec, _ = cv2.Rodrigues(rotation_matrix(angles))
    dist = np.asarray(camera.dist, dtype=float)
    pixels, _ = cv2.projectPoints(square, rvec, np.array([20.0, -10.0, z_mm]), camera.K, dist)
    corners = pixels.reshape(4, 2) + np.array([[0.0, 0.0], [0.0, 0.0], [0.6, 0.4], [0.0, 0.0]])
    chosen = None if settings is None else settings_class(method)(**settings)
    result = solve(corners, camera, SIDE_MM, method, chosen)
    assert result.converged and result.alternative is not None
    answer = _rms_reprojection_by_opencv(result, corners, camera)
    mirror = _rms_reprojection_by_opencv(result.alternative, corners, camera)
    assert min(answer, mirror) > 0.05
    assert (answer < mirror) is answer_fits_better
    assert result.ambiguity == pytest.approx(min(answer, mirror) / max(answer, mirror), rel=1e-6)
    assert 0.0 < result.ambiguity < 1.0


def test_a_fit_its_corners_covariance_cannot_explain_is_a_misfit_and_says_so_in_json():
    """Exact projections of a known pose fit (chi2 ~ 0, misfit False); V3 moved by (2.0, -1.5) px
    under a corner std of 0.1 px cannot be fitted by any square's pose. Independent truth: OpenCV's
    least-squares fit of the square (IPPE_SQUARE, then solvePnPRefineLM) to the same corners leaves
    a squared residual whose ratio to 0.1^2 is the chi-square; it is far above FIT_CHI2 (9.21)."""
    camera = resolve_camera("picam-v2@640x480")
    pose = Pose([-25.0, 15.0, 320.0], [25.0, -30.0, 40.0])
    corners = project_points(
        marker_vertices(SIDE_MM) @ rotation_matrix(pose.angles_deg).T + pose.position_mm, camera
    )
    bad = corners.copy()
    bad[2] += (2.0, -1.5)
    k = camera.K
    obj = marker_vertices(SIDE_MM) * [1.0, -1.0, 1.0]  # IPPE_SQUARE's frame (+Y up), its vertex order
    pts = np.ascontiguousarray(bad, dtype=np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, pts, k, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    rvec, tvec = cv2.solvePnPRefineLM(obj, pts, k, None, rvec, tvec)
    reproj, _ = cv2.projectPoints(obj, rvec, tvec, k, None)
    opencv_chi2 = float(np.sum((reproj.reshape(4, 2) - bad) ** 2)) / 0.1**2
    assert ok and opencv_chi2 > 10 * unc.FIT_CHI2
    cov = unc.isotropic_cov(0.1)
    for method in METHODS:
        clean = solve(corners, camera, SIDE_MM, method, corners_cov=cov)
        assert clean.converged and clean.chi2 < 1e-3 and clean.misfit is False
        data = clean.to_json_dict()
        assert data["misfit"] is False and data["chi2"] == pytest.approx(clean.chi2)
        off = solve(bad, camera, SIDE_MM, method, corners_cov=cov)
        assert off.converged and off.misfit is True
        assert off.chi2 == pytest.approx(opencv_chi2, rel=0.05)
        data = json.loads(json.dumps(off.to_json_dict(), allow_nan=False))
        assert data["misfit"] is True and data["chi2"] > unc.FIT_CHI2
        unknown = solve(bad, camera, SIDE_MM, method).to_json_dict()  # no covariance: no verdict
        assert unknown["misfit"] is False and unknown["chi2"] is None
