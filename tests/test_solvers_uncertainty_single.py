"""The single-solve uncertainty path (qrfield.solvers.uncertainty_single, Python floats and a few
fused numpy calls) gives the numbers of the array functions of qrfield.solvers.uncertainty (the
reference, itself checked against central differences and Monte-Carlo spreads in
tests/test_solvers_uncertainty.py), on seeded noisy poses, pinhole and distorted, both methods,
with and without a mirror candidate."""

from __future__ import annotations

import math

import numpy as np
import pytest
from solver_cases import DISTORTED, SIDE_MM, cases

from qrfield.benchmarks.pose import draw_noise, random_corner_cov
from qrfield.methods import METHODS
from qrfield.solvers import kernel, numerical, solve_methods
from qrfield.solvers import uncertainty as unc
from qrfield.solvers import uncertainty_single as one
from qrfield.solvers.checks import check_corners_single
from qrfield.solvers.rays import normalised_single


def _reference_mirror_start(result, x, y):
    """(R, t) arrays the mirror test starts from: the method's finite alternative, else for the
    numerical model the rigid pose on its reflected plane (the mirror search's own start)."""
    alt = result.alternative
    if alt is not None and np.isfinite(alt.rotation).all():
        return alt.rotation, alt.position_mm
    if result.method != "numerical":
        return None
    guess = numerical._mirror_guess(result.rotation.tolist(), result.position_mm.tolist(), x, y)
    if guess is None:
        return None
    rows, centre = kernel.pose_from_vertices(guess, x, y, math.sqrt, max)
    return np.array(rows), np.array(centre)


def _reference_fields(result, corners, camera, cov):
    """The uncertainty fields of one converged result by the array functions: the implementation
    the pipeline used before the single path (kept here as the reference)."""
    c, flat = check_corners_single(corners)
    x_list, y_list = normalised_single(c, flat, camera)
    x, y = np.array(x_list), np.array(y_list)
    cov_n = unc.normalised_cov(cov, x, y, camera)
    mirror = _reference_mirror_start(result, x_list, y_list)
    rotations = [result.rotation] + ([] if mirror is None else [mirror[0]])
    positions = [result.position_mm] + ([] if mirror is None else [mirror[1]])
    projection = unc.rigid_projection(np.array(rotations), np.array(positions), SIDE_MM)
    if result.method == "numerical":
        jac = unc.numerical_jacobian(result.vertices_mm[:, 2], x, y)
    else:
        jac = unc.least_squares_jacobian(projection[1][0], camera)
    pose_cov = unc.pose_covariance(jac[None], cov_n, result.angles_deg[None])[0]
    pos_std, ang_std = unc.pose_std(pose_cov)
    n_obs = np.array([v for pair in zip(x_list, y_list, strict=True) for v in pair])
    chi2 = unc.branch_chi2(projection, n_obs, unc.information_matrix(cov_n))
    return {
        "pose_cov": pose_cov,
        "position_std_mm": pos_std,
        "angles_std_deg": ang_std,
        "chi2": chi2[0],
        "mirror_chi2": chi2[1] if mirror is not None else np.nan,
        "ambiguous": bool(mirror is not None and unc.is_ambiguous(chi2[0], chi2[1])),
    }


@pytest.mark.parametrize("camera_name", ["picam-v2@640x480", DISTORTED.name])
def test_the_single_path_gives_the_array_functions_numbers(camera_name):
    camera, _, corners, *_ = cases(40, seed=83, camera_name=camera_name)
    rng = np.random.default_rng(83)
    compared = {method: 0 for method in METHODS}
    mirrors = ambiguous = 0
    for k, c in enumerate(corners):
        cov = random_corner_cov(rng) * (4.0 if k % 4 == 0 else 1.0)  # some views near the ambiguity
        noisy = c + draw_noise(rng, cov)
        results = solve_methods(noisy, camera, SIDE_MM, METHODS, None, cov)
        for method, result in results.items():
            if not result.converged:
                continue
            want = _reference_fields(result, noisy, camera, cov)
            for name in ("pose_cov", "position_std_mm", "angles_std_deg"):
                np.testing.assert_allclose(getattr(result, name), want[name], rtol=1e-7, atol=1e-10)
            assert result.chi2 == pytest.approx(want["chi2"], rel=1e-6, abs=1e-9)
            if np.isfinite(want["mirror_chi2"]):
                mirrors += 1
                assert result.mirror_chi2 == pytest.approx(want["mirror_chi2"], rel=1e-6, abs=1e-9)
            else:
                assert not np.isfinite(result.mirror_chi2)
            assert result.ambiguous == want["ambiguous"]
            ambiguous += result.ambiguous
            compared[method] += 1
    assert all(n >= 30 for n in compared.values()), compared
    assert mirrors >= 30  # the mirror's chi-square was compared, not skipped
    assert ambiguous >= 1  # and the flag raised at least once on this seeded set


def test_single_path_numerical_jacobian_matches_the_array_one_on_exact_depths():
    camera, _, corners, *_ = cases(10, seed=5)
    for c in corners:
        c, flat = check_corners_single(c)
        x, y = normalised_single(c, flat, camera)
        z = [300.0 + 10.0 * i for i in range(4)]
        np.testing.assert_allclose(
            one.numerical_jacobian_single(z, x, y),
            unc.numerical_jacobian(np.array(z), np.array(x), np.array(y)),
            rtol=1e-9,
            atol=1e-9,
        )


def _noisy_views(camera_name, count, seed, noise=1.0):
    """(camera, [(corners, cov, x list, y list)]) of seeded views with random corner covariances,
    the corners drawn from them (times ``noise``)."""
    camera, _, corners, *_ = cases(count, seed=seed, camera_name=camera_name)
    rng = np.random.default_rng(seed)
    out = []
    for c in corners:
        cov = random_corner_cov(rng)
        noisy = c + noise * draw_noise(rng, cov)
        checked, flat = check_corners_single(noisy)
        out.append((noisy, cov, *normalised_single(checked, flat, camera)))
    return camera, out


@pytest.mark.parametrize("camera_name", ["picam-v2@640x480", DISTORTED.name])
def test_fast_blocks_give_the_array_functions_numbers(camera_name):
    """Each building block of the per-frame path against its array function, term by term: the
    numerical and IPPE pose rows with the Euler rates folded in, the pose covariance, the batched
    branch chi-squares (a branch behind the camera: inf) and the stacked block diagonals."""
    camera, views = _noisy_views(camera_name, 12, seed=29)
    for noisy, cov, x, y in views:
        results = solve_methods(noisy, camera, SIDE_MM, METHODS, None, cov)
        xa, ya = np.array(x), np.array(y)
        cov_n = unc.normalised_cov(cov, xa, ya, camera)
        cov16 = cov_n.reshape(16).tolist()
        sigma_n, info = unc.block_diagonal(cov16 + unc.information_blocks(cov16))
        want_sigma = np.zeros((8, 8))
        for i in range(4):
            want_sigma[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = cov_n[i]
        np.testing.assert_array_equal(sigma_n, want_sigma)
        np.testing.assert_array_equal(info, unc.information_matrix(cov_n))
        np.testing.assert_allclose(
            np.array(one.normalised_cov_single(cov, x, y, camera, camera.has_distortion)), cov16, rtol=1e-12
        )
        n_obs = np.array([v for pair in zip(x, y, strict=True) for v in pair])
        for method, r in results.items():
            assert r.converged
            euler = unc.euler_rows(*r.angles_deg.tolist()[:2])
            rows, t = r.rotation.tolist(), r.position_mm.tolist()
            proj = one.rigid_projection_single(rows, t, SIDE_MM)
            want_proj = unc.rigid_projection(r.rotation[None], r.position_mm[None], SIDE_MM)
            np.testing.assert_allclose(proj[0], want_proj[0][0], rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(np.reshape(proj[1], (8, 6)), want_proj[1][0], rtol=1e-12, atol=1e-15)
            if method == "numerical":
                jac = unc.numerical_jacobian(r.vertices_mm[:, 2], xa, ya)
                got = one._pose_rows(*one._numerical_terms(r.vertices_mm[:, 2].tolist(), x, y), 0.25, euler)
            else:
                jac = unc.least_squares_jacobian(want_proj[1][0], camera)
                got = one._pose_rows(one.ippe_jacobian_single(want_proj[1][0], camera), one._EYE9, 1.0, euler)
            want_rows = np.concatenate([jac[3:], unc.euler_jacobian(r.angles_deg) @ jac[:3]])
            scale = np.abs(want_rows).max(axis=1, keepdims=True)
            np.testing.assert_allclose(got / scale, want_rows / scale, rtol=0, atol=1e-10)
            want_cov = unc.pose_covariance(jac[None], cov_n, r.angles_deg[None])[0]
            np.testing.assert_allclose(got @ sigma_n @ got.T, want_cov, rtol=1e-8, atol=1e-12)
            # Three branches in one batch: this pose, its mirror start and one behind the camera.
            mirror = _reference_mirror_start(r, x, y)
            behind = (r.rotation, -r.position_mm)
            branches = [(r.rotation, r.position_mm)] + ([mirror] if mirror is not None else []) + [behind]
            projections = [
                one.rigid_projection_single(b[0].tolist(), b[1].tolist(), SIDE_MM) for b in branches
            ]
            stacked = np.array([p[1] for p in projections]).reshape(-1, 8, 6)
            got_chi2 = one.branch_chi2_many(projections, stacked, n_obs, info)
            want_chi2 = unc.branch_chi2(
                unc.rigid_projection(
                    np.array([b[0] for b in branches]), np.array([b[1] for b in branches]), SIDE_MM
                ),
                n_obs,
                info,
            )
            assert got_chi2[-1] == math.inf == want_chi2[-1]
            np.testing.assert_allclose(got_chi2[:-1], want_chi2[:-1], rtol=1e-7, atol=1e-9)
            first = one.branch_chi2_many(
                [projections[0]], np.array(projections[0][1]).reshape(1, 8, 6), n_obs, info
            )
            assert first[0] == pytest.approx(want_chi2[0], rel=1e-9, abs=1e-12)


def test_numerical_jacobian_of_the_fast_terms_against_central_differences():
    """Independent truth for the fast numerical Jacobian: central differences of the solver itself
    (depths re-solved to the least-squares optimum, pose from them) over each normalised corner,
    at exact corners (where the implicit-function Jacobian is exact)."""
    _, views = _noisy_views("picam-v2@640x480", 3, seed=41, noise=0.0)
    settings = numerical.NumericalSettings(mirror=False, tolerance_mm=1e-6)
    lengths = kernel.lengths_for(SIDE_MM)
    for _, _, x, y in views:

        def pose(xs, ys):
            z0 = numerical._initial_single(xs, ys, lengths, SIDE_MM, settings)
            z = numerical.iterate_single(z0, xs, ys, lengths, settings, stall_mm=1e-12)[0]
            rows, centre = kernel.pose_from_vertices(z, xs, ys, math.sqrt, max)
            return np.array(rows), np.array(centre), z

        rot, _, z = pose(x, y)
        got = one.numerical_jacobian_single(z, x, y)
        step = 1e-7
        for k in range(8):
            xs_p, ys_p, xs_m, ys_m = list(x), list(y), list(x), list(y)
            (xs_p if k % 2 == 0 else ys_p)[k // 2] += step
            (xs_m if k % 2 == 0 else ys_m)[k // 2] -= step
            rp, tp, _ = pose(xs_p, ys_p)
            rm, tm, _ = pose(xs_m, ys_m)
            d_rot = (rp - rm) @ rot.T / (2 * step)  # [d omega]x
            d_omega = (
                np.array([d_rot[2, 1] - d_rot[1, 2], d_rot[0, 2] - d_rot[2, 0], d_rot[1, 0] - d_rot[0, 1]])
                / 2
            )
            np.testing.assert_allclose(got[:3, k], d_omega, rtol=1e-4, atol=1e-4 * np.abs(got[:3]).max())
            np.testing.assert_allclose(
                got[3:, k], (tp - tm) / (2 * step), rtol=1e-4, atol=1e-4 * np.abs(got[3:]).max()
            )


def test_one_corner_sets_std_in_floats_is_the_array_formulas() -> None:
    """corners_std_px of one (4, 2, 2) set (floats) against the (N, 4, 2, 2) array path and by hand:
    sqrt of each block's trace, 0 for a negative trace, NaN kept."""
    from qrfield.solvers.uncertainty import corners_std_px

    rng = np.random.default_rng(5)
    a = rng.normal(0, 0.2, (4, 2, 2))
    cov = a @ a.transpose(0, 2, 1)
    cov[2] = [[-1.0, 0.0], [0.0, 0.5]]  # a negative trace
    cov[3, 0, 0] = np.nan
    one, batch = corners_std_px(cov), corners_std_px(cov[None])[0]
    np.testing.assert_array_equal(one, batch)
    np.testing.assert_allclose(one[:2], np.sqrt(cov[:2, 0, 0] + cov[:2, 1, 1]), rtol=1e-15)
    assert one[2] == 0.0 and np.isnan(one[3])
