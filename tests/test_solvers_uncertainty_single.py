"""The single-solve uncertainty path (qrfield.solvers.uncertainty_single, Python floats and a few
fused numpy calls) gives the numbers of the array functions of qrfield.solvers.uncertainty (the
reference, itself checked against central differences and Monte-Carlo spreads in
tests/test_solvers_uncertainty.py), on seeded noisy poses, pinhole and distorted, both methods,
with and without a mirror candidate."""

from __future__ import annotations

import numpy as np
import pytest
from solver_cases import DISTORTED, SIDE_MM, cases

from qrfield.benchmarks.pose import draw_noise, random_corner_cov
from qrfield.methods import METHODS
from qrfield.solvers import solve_methods
from qrfield.solvers import uncertainty as unc
from qrfield.solvers.checks import check_corners_single
from qrfield.solvers.rays import normalised_single


def _reference_fields(result, corners, camera, cov):
    """The uncertainty fields of one converged result by the array functions: the implementation
    the pipeline used before the single path (kept here as the reference)."""
    c, flat = check_corners_single(corners)
    x_list, y_list = normalised_single(c, flat, camera)
    x, y = np.array(x_list), np.array(y_list)
    cov_n = unc.normalised_cov(cov, x, y, camera)
    mirror = unc._mirror_start(result, result.rotation.tolist(), result.position_mm.tolist(), x_list, y_list)
    rotations = [result.rotation] + ([] if mirror is None else [np.array(mirror[0])])
    positions = [result.position_mm] + ([] if mirror is None else [np.array(mirror[1])])
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
    from qrfield.solvers import uncertainty_single as one

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
