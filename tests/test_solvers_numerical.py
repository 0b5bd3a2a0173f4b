"""The numerical model: seeded round trips, the seed's criteria, the mirror, batch == single."""

from __future__ import annotations

import numpy as np
import pytest
from solver_cases import DISTORTED, SIDE_MM, cases, errors, opencv_pose

from qrfield.geometry import Pose, angles_from_rotation, marker_vertices, project_points
from qrfield.settings import SettingError
from qrfield.solvers import SEED_SETTINGS, IppeSettings, NumericalSettings, SolverError, solve, solve_batch


def test_default_guess_recovers_exact_poses():
    camera, _, corners, positions, angles = cases(150, seed=31)
    for c, p, a in zip(corners, positions, angles, strict=True):
        r = solve(c, camera, SIDE_MM)
        assert r.method == "numerical" and r.converged and r.reason == ""
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, p, a)
        assert pos_err < 1e-6 and ang_err < 1e-6
        assert r.reprojection_px < 1e-6 and r.residual_mm < 1e-6
        # The solved vertices lie on the true vertices (independent: the true pose's square).
        np.testing.assert_allclose(r.vertices_mm, Pose(p, a).vertices_mm(SIDE_MM), atol=1e-6)


def test_thesis_settings_meet_the_seed_criteria_wherever_converged():
    camera, _, corners, positions, angles = cases(150, seed=31)
    converged = 0
    for c, p, a in zip(corners, positions, angles, strict=True):
        r = solve(c, camera, SIDE_MM, "numerical", SEED_SETTINGS)
        assert r.iterations <= SEED_SETTINGS.n_max
        if r.converged:
            converged += 1
            pos_err, ang_err = errors(r.position_mm, r.angles_deg, p, a)
            assert pos_err < 5.0 and ang_err <= 2.0
        else:
            assert r.reason  # says why (n_max reached or stalled)
    # The weak spot the issue describes: equal starting depths fail for part of the workspace.
    assert 0.5 < converged / len(corners) < 1.0


def test_seed_guess_with_loose_tolerance_flags_the_mirror_when_it_lands_on_it():
    camera, _, corners, positions, angles = cases(150, seed=31)
    settings = NumericalSettings(initial_guess="seed", tolerance_mm=1.0, stop="settled")
    wrong = 0
    for c, p, a in zip(corners, positions, angles, strict=True):
        r = solve(c, camera, SIDE_MM, "numerical", settings)
        if not r.converged:
            continue
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, p, a)
        if pos_err < 5.0 and ang_err <= 2.0:
            continue
        # Converged on the mirror side: the alternative is the true pose and explains the image better.
        wrong += 1
        assert r.alternative is not None and r.alternative.reprojection_px < r.reprojection_px
        assert r.ambiguity == pytest.approx(r.alternative.reprojection_px / r.reprojection_px)
        assert r.ambiguous  # the mirror fits better: flagged even without a corner covariance
        alt_pos, alt_ang = errors(r.alternative.position_mm, r.alternative.angles_deg, p, a)
        assert alt_pos < 5.0 and alt_ang <= 2.0
    assert wrong > 0  # the case exists in this seeded set, so the branch above ran


def test_mirror_candidate_is_reported_and_worse_for_exact_corners():
    camera, _, corners, _, _ = cases(150, seed=32)
    found = 0
    for c in corners[:40]:
        r = solve(c, camera, SIDE_MM)
        if r.alternative is None:
            continue
        found += 1
        assert r.ambiguity < 1e-6  # exact corners: the true pose fits, its mirror does not
        assert r.alternative.reprojection_px > 1e-3
        n_true, n_alt = r.rotation[:, 2], r.alternative.rotation[:, 2]
        assert np.degrees(np.arccos(np.clip(n_true @ n_alt, -1, 1))) > 1.0  # another card normal
    assert found > 20
    no_mirror = solve(corners[0], camera, SIDE_MM, "numerical", NumericalSettings(mirror=False))
    assert no_mirror.alternative is None and no_mirror.ambiguity is None


def test_agrees_with_a_direct_opencv_solvepnp():
    camera, _, corners, _, _ = cases(150, seed=33)
    for c in corners[:60]:
        theirs, _, _ = opencv_pose(c, camera)
        r = solve(c, camera, SIDE_MM)
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, theirs.position_mm, theirs.angles_deg)
        assert pos_err < 1e-4 and ang_err < 1e-4  # OpenCV's LM stops at about 1e-5 mm


def test_orientation_is_the_least_squares_rotation_of_the_solved_vertices():
    # Independent: Kabsch by numpy SVD on the marker points and the solved (noisy, non-rigid) vertices.
    camera, _, corners, _, _ = cases(150, seed=34)
    rng = np.random.default_rng(2)
    q = marker_vertices(SIDE_MM)
    for c in corners[:30]:
        r = solve(c + rng.normal(0, 0.7, c.shape), camera, SIDE_MM)
        p = r.vertices_mm
        h = (q - q.mean(0)).T @ (p - p.mean(0))
        u, _, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(vt.T @ u.T))
        kabsch = vt.T @ np.diag([1, 1, d]) @ u.T
        np.testing.assert_allclose(r.rotation, kabsch, atol=1e-9)
        np.testing.assert_allclose(r.position_mm, p.mean(0), atol=1e-9)
        # The solved vertices lie on the lines of sight through the corners.
        np.testing.assert_allclose(project_points(p, camera), r.corners_px, atol=1e-6)


def test_seed_guess_is_the_apparent_size_and_is_clamped():
    camera, *_ = cases(10, seed=31)
    corners = Pose([0.0, 0.0, 400.0], [0.0, 0.0, 0.0]).corners_px(camera, SIDE_MM)
    # Fronto-parallel on the axis: z = f L / side(px) is the exact depth, so no update is needed.
    r = solve(corners, camera, SIDE_MM, "numerical", SEED_SETTINGS)
    assert r.converged and r.iterations == 0
    assert r.position_mm[2] == pytest.approx(400.0, abs=0.01 * 400 / SIDE_MM)
    clamped = NumericalSettings(initial_guess="seed", stop="seed", tolerance_mm=0.01, z_max_mm=300.0)
    r = solve(corners, camera, SIDE_MM, "numerical", clamped)
    assert r.iterations > 0  # the guess was 300 mm, not 400


def test_no_solution_is_a_result_not_an_exception():
    camera, _, corners, *_ = cases(150, seed=31)
    settings = NumericalSettings(initial_guess="seed", stop="seed", tolerance_mm=1e-9, n_max=1, mirror=False)
    r = solve(corners[0], camera, SIDE_MM, "numerical", settings)
    assert not r.converged and r.iterations == 1
    assert "n_max = 1" in r.reason
    js = r.to_json_dict()
    assert js["converged"] is False and js["reason"] == r.reason
    noisy = corners[1] + np.random.default_rng(0).normal(0, 2.0, (4, 2))
    r = solve(noisy, camera, SIDE_MM, "numerical", NumericalSettings(tolerance_mm=1e-6, mirror=False))
    assert not r.converged and "settled after" in r.reason
    assert np.all(np.isfinite(r.position_mm))  # the last iterate is still reported


def test_damped_steps_converge_to_the_same_pose():
    camera, _, corners, positions, angles = cases(150, seed=35)
    settings = NumericalSettings(tf=0.6, initial_guess="seed", stop="seed", tolerance_mm=0.001, n_max=200)
    full_step = NumericalSettings(initial_guess="seed", stop="seed", tolerance_mm=0.001, n_max=200)
    converged = 0
    for c, p, a in list(zip(corners, positions, angles, strict=True))[:40]:
        r = solve(c, camera, SIDE_MM, "numerical", settings)
        if r.converged:
            converged += 1
            pos_err, ang_err = errors(r.position_mm, r.angles_deg, p, a)
            assert pos_err < 5.0 and ang_err <= 2.0
            # tf scales the step: damped Gauss-Newton converges linearly, so it needs more updates.
            undamped = solve(c, camera, SIDE_MM, "numerical", full_step)
            if undamped.converged:
                assert r.iterations > undamped.iterations
    assert converged >= 30  # measured 33 of 40: the checks above ran


def test_distortion_is_undone_before_solving():
    camera, _, corners, positions, angles = cases(80, seed=36, camera_name=DISTORTED.name)
    for c, p, a in zip(corners, positions, angles, strict=True):
        r = solve(c, camera, SIDE_MM)
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, p, a)
        assert pos_err < 1e-6 and ang_err < 1e-6
        assert r.reprojection_px < 1e-6


def _assert_batch_equals_single(corners, camera, settings):
    b = solve_batch(corners, camera, SIDE_MM, "numerical", settings)
    assert len(b) == len(corners)
    single = (
        NumericalSettings(**{**settings.__dict__, "mirror": False})
        if settings
        else NumericalSettings(mirror=False)
    )
    for i, c in enumerate(corners):
        r = solve(c, camera, SIDE_MM, "numerical", single)
        assert b.converged[i] == r.converged and b.iterations[i] == r.iterations
        np.testing.assert_allclose(b.position_mm[i], r.position_mm, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.rotation[i], r.rotation, rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.angles_deg[i], r.angles_deg, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.residual_mm[i], r.residual_mm, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.reprojection_px[i], r.reprojection_px, rtol=0, atol=1e-9)
    return b


@pytest.mark.slow
@pytest.mark.parametrize(
    "settings",
    [None, SEED_SETTINGS, NumericalSettings(initial_guess="seed", tf=0.8, tolerance_mm=0.3)],
    ids=["defaults", "thesis", "seed-damped"],
)
def test_batch_equals_single(settings):
    camera, _, corners, *_ = cases(150, seed=37)
    rng = np.random.default_rng(3)
    sample = np.concatenate([corners[:50], corners + rng.normal(0, 0.5, corners.shape)])
    b = _assert_batch_equals_single(sample, camera, settings)
    assert b.valid.all()


def test_batch_equals_single_with_distortion():
    camera, _, corners, *_ = cases(80, seed=36, camera_name=DISTORTED.name)
    _assert_batch_equals_single(corners[:30] + 0.2, camera, SEED_SETTINGS)


def test_batch_marks_unusable_rows_and_carries_on():
    camera, _, corners, *_ = cases(150, seed=37)
    batch = corners[:6].copy()
    batch[1, 2] = np.nan  # NaN
    batch[2] = batch[2][::-1]  # counter-clockwise
    batch[3, 1], batch[3, 2] = corners[3, 2], corners[3, 1]  # self-intersecting
    batch[4, 2] = (batch[4, 1] + batch[4, 3]) / 2  # V2, V3, V4 collinear
    b = solve_batch(batch, camera, SIDE_MM)
    assert b.valid.tolist() == [True, False, False, False, False, True]
    assert b.converged.tolist() == [True, False, False, False, False, True]
    assert np.all(np.isnan(b.position_mm[1:5]))
    with pytest.raises(SolverError, match=r"\(N, 4, 2\)"):
        solve_batch(corners[0], camera, SIDE_MM)


def test_settings_are_checked():
    camera, _, corners, *_ = cases(10, seed=31)
    with pytest.raises(SettingError, match="tf"):
        solve(corners[0], camera, SIDE_MM, "numerical", NumericalSettings(tf=5.0))
    with pytest.raises(SolverError, match="z_min_mm"):
        solve(corners[0], camera, SIDE_MM, "numerical", NumericalSettings(z_min_mm=900.0, z_max_mm=800.0))
    with pytest.raises(SolverError, match="NumericalSettings"):
        from qrfield.solvers import IppeSettings

        solve(corners[0], camera, SIDE_MM, "numerical", IppeSettings())
    with pytest.raises(SolverError, match="unknown solver method"):
        solve(corners[0], camera, SIDE_MM, "epnp")


@pytest.mark.slow
def test_batch_in_chunks_equals_single(monkeypatch):
    from qrfield.solvers import numerical_batch

    monkeypatch.setattr(numerical_batch, "BATCH_CHUNK", 7)  # 60 rows: 8 full chunks and a partial one
    camera, _, corners, *_ = cases(150, seed=37)
    sample = corners[:60] + np.random.default_rng(8).normal(0, 0.5, (60, 4, 2))
    sample[9, 0] = np.nan
    b = _assert_batch_equals_single(np.delete(sample, 9, axis=0), camera, SEED_SETTINGS)
    assert len(b) == 59
    b = solve_batch(sample, camera, SIDE_MM, settings=SEED_SETTINGS)
    assert len(b) == 60 and not b.valid[9] and b.valid.sum() == 59


def test_scalar_angle_extraction_is_the_geometry_one_also_at_gimbal_lock():
    # The single-solve path extracts angles with a pure-Python twin of geometry.angles_from_rotation.
    from qrfield.geometry import rotation_matrix
    from qrfield.solvers.floats import angles_single

    rng = np.random.default_rng(6)
    angles = rng.uniform(-180, 180, (200, 3))
    angles[:50, 1] = 90.0
    angles[50:100, 1] = -90.0
    angles[100, :] = [0.0, 0.0, 180.0]
    for r in rotation_matrix(angles):
        np.testing.assert_allclose(angles_single(r.tolist()), angles_from_rotation(r), rtol=0, atol=1e-9)


def _near_square_on_views(count: int, seed: int, camera):
    """Seeded codes tilted less than 12 degrees, their exact corners plus 0.03 px of noise."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        tilt, turn = rng.uniform(0.0, 12.0), np.radians(rng.uniform(0.0, 360.0))
        pose = Pose(
            [rng.uniform(-60, 60), rng.uniform(-40, 40), rng.uniform(200, 500)],
            [tilt * np.cos(turn), tilt * np.sin(turn), rng.uniform(-180, 180)],
        )
        out.append((pose, pose.corners_px(camera, SIDE_MM) + rng.normal(0.0, 0.03, (4, 2))))
    return out


def test_nearly_square_on_the_settled_rule_converges_and_meets_the_criteria():
    """Seen nearly square-on the lengths change only to second order with the tilt; the full
    Gauss-Newton step overshot and cycled until n_max with every length within 0.005 mm (NOCONV on
    about one such view in ten: 3 of these 40, and 10 of the 60 frames of benchmark detect's sequence).
    The damped step converges, to a pose within the seed's criteria."""
    camera, *_ = cases(1, seed=1)
    views = _near_square_on_views(40, seed=0, camera=camera)
    for pose, corners in views:
        r = solve(corners, camera, SIDE_MM)
        assert r.converged, r.reason
        assert r.iterations <= 30
        pos_err, ang_err = errors(r.position_mm, r.angles_deg, pose.position_mm, pose.angles_deg)
        assert pos_err < 5.0 and ang_err <= 2.0
    # Damped or not, the batch path gives the same numbers.
    _assert_batch_equals_single(np.array([c for _, c in views]), camera, None)


def test_solve_batch_takes_the_arguments_of_solve_in_its_order():
    import inspect

    names = lambda f: list(inspect.signature(f).parameters)  # noqa: E731
    assert (
        names(solve_batch)
        == names(solve)
        == [
            "corners_px",
            "camera",
            "side_mm",
            "method",
            "settings",
            "corners_cov",
        ]
    )
    camera, _, corners, *_ = cases(4, seed=41)
    loose = NumericalSettings(tolerance_mm=1.0, stop="seed")
    plain = IppeSettings(refine="none")
    for method, settings in (("numerical", loose), ("ippe", plain)):
        batch = solve_batch(corners, camera, SIDE_MM, method, settings)
        for i in range(len(corners)):
            one = solve(corners[i], camera, SIDE_MM, method, settings)
            np.testing.assert_allclose(batch.position_mm[i], one.position_mm, atol=1e-6)
            np.testing.assert_allclose(batch.angles_deg[i], one.angles_deg, atol=1e-6)
        if method == "numerical":
            assert batch.iterations.tolist() == [
                solve(c, camera, SIDE_MM, method, settings).iterations for c in corners
            ]
    # A caller of the old order (settings fourth) is told, not misread.
    with pytest.raises(
        SolverError, match=r"method must be a name, got NumericalSettings; pass settings=\.\.\. by keyword"
    ):
        solve_batch(corners, camera, SIDE_MM, loose)
