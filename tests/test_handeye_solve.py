"""The hand-eye solve (qrfield.handeye.solve): exact pairs give the truth, noisy pairs an error
its reported uncertainty describes (Monte Carlo, noise drawn from the stated covariances),
degenerate pose sets are refused with a message naming what to add, residuals point at a bad pair.

The pair sets are composed here by hand from a chosen truth (X, Y) with numpy, not with the
package's model code."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qrfield.geometry import angles_from_rotation, rotation_matrix
from qrfield.handeye import HandEyeError, Pair, solve_handeye
from qrfield.handeye.rigid import difference, rotation_exp

SETUPS = ("eye-in-hand", "eye-to-hand")


def rigid(r, t):
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = r, t
    return out


def random_rigid(rng, max_deg, scale_mm, axis=None):
    if axis is None:
        axis = rng.normal(size=3)
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return rigid(
        rotation_exp(axis * math.radians(rng.uniform(-max_deg, max_deg))), rng.normal(size=3) * scale_mm
    )


def true_code_pose(setup, x, y, tool):
    """T_camera_marker by the set-up's chain of frames (docs/conventions.md, Hand-eye)."""
    if setup == "eye-in-hand":  # T_base_marker = T_base_tool T_tool_camera T_camera_marker
        return np.linalg.inv(x) @ np.linalg.inv(tool) @ y
    return np.linalg.inv(x) @ tool @ y  # T_base_camera T_camera_marker = T_base_tool T_tool_marker


def noisy(code, cov, rng):
    """The pose with noise of covariance ``cov`` on (x, y, z, alpha, beta, gamma) (mm, deg)."""
    noise = np.linalg.cholesky(cov) @ rng.normal(size=6)
    angles = angles_from_rotation(code[:3, :3]) + noise[3:]
    return rigid(rotation_matrix(angles), code[:3, 3] + noise[:3])


def random_cov(rng):
    """A pose covariance like a solver's: correlated, z and the tilts loosest (mm, deg)."""
    scale = np.array([0.03, 0.03, 0.12, 0.08, 0.08, 0.03]) * rng.uniform(0.5, 2.0)
    a = rng.normal(size=(6, 6)) * 0.3 + np.eye(6)
    corr = a @ a.T
    d = 1 / np.sqrt(np.diag(corr))
    corr = corr * d[:, None] * d[None, :]
    return corr * scale[:, None] * scale[None, :]


def cell(setup, rng, count=15, max_deg=35.0):
    x = random_rigid(rng, 180, 60)
    y = random_rigid(rng, 180, 300)
    tools = [random_rigid(rng, max_deg, 150) for _ in range(count)]
    return x, y, tools


@pytest.mark.parametrize("setup", SETUPS)
def test_exact_pairs_give_the_true_transform_and_zero_residuals(setup):
    rng = np.random.default_rng(3)
    x, y, tools = cell(setup, rng)
    pairs = [
        Pair(t, true_code_pose(setup, x, y, t), np.diag([0.03, 0.03, 0.1, 0.05, 0.05, 0.03]) ** 2)
        for t in tools
    ]
    result = solve_handeye(pairs, setup)
    assert np.abs(difference(result.transform, x)).max() < 1e-8
    assert np.abs(difference(result.other, y)).max() < 1e-8
    assert np.abs(difference(result.closed_form, x)).max() < 1e-8
    assert result.residual_mm < 1e-8 and result.residual_deg < 1e-7
    assert result.n_pairs == 15 and result.dof == 78 and result.weighted


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from(SETUPS), st.integers(5, 30))
def test_any_diverse_exact_set_gives_the_truth(seed, setup, count):
    rng = np.random.default_rng(seed)
    x, y, tools = cell(setup, rng, count, max_deg=60.0)
    pairs = [Pair(t, true_code_pose(setup, x, y, t)) for t in tools]
    try:
        result = solve_handeye(pairs, setup)
    except HandEyeError as exc:  # a random set may turn too little: then it must say so
        assert "turn" in str(exc)
        return
    assert np.abs(difference(result.transform, x)).max() < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("setup", SETUPS)
def test_the_reported_uncertainty_describes_the_error_monte_carlo(setup):
    # 200 draws of the same cell, each pair's noise from its stated covariance: the error of X over
    # its reported std must have an RMS near 1 in each of the 6 components, chi2/dof near 1.
    rng = np.random.default_rng(11)
    x, y, tools = cell(setup, rng)
    covs = [random_cov(rng) for _ in tools]
    truth = [true_code_pose(setup, x, y, t) for t in tools]
    z, ratios = [], []
    for _ in range(200):
        pairs = [Pair(t, noisy(c, cov, rng), cov) for t, c, cov in zip(tools, truth, covs, strict=True)]
        result = solve_handeye(pairs, setup)
        err = difference(result.transform, x)
        err[3:] = np.degrees(err[3:])
        z.append(err / np.sqrt(np.diag(result.covariance)))
        ratios.append(result.chi2 / result.dof)
    rms = np.sqrt(np.mean(np.square(z), axis=0))
    assert np.all((rms > 0.85) & (rms < 1.15)), rms
    assert 0.9 < np.mean(ratios) < 1.1


@pytest.mark.slow
def test_robot_pose_noise_is_carried_to_the_uncertainty():
    # The tool poses wobble by 0.2 mm / 0.05 deg: given those, the std still describes the error;
    # ignored, the std is too small (chi2/dof scales it up, but by one factor for all components).
    setup = "eye-in-hand"
    rng = np.random.default_rng(5)
    x, y, tools = cell(setup, rng)
    cov = np.diag([0.03, 0.03, 0.1, 0.05, 0.05, 0.03]) ** 2
    z_told, z_untold = [], []
    for _ in range(100):
        pairs = []
        for t in tools:
            wobble = np.r_[rng.normal(size=3) * 0.2, np.radians(rng.normal(size=3) * 0.05)]
            reported = rigid(rotation_exp(wobble[3:]) @ t[:3, :3], t[:3, 3] + wobble[:3])
            pairs.append(Pair(reported, noisy(true_code_pose(setup, x, y, t), cov, rng), cov))
        for told, out in ((True, z_told), (False, z_untold)):
            result = solve_handeye(
                pairs, setup, tool_std_mm=0.2 if told else 0.0, tool_std_deg=0.05 if told else 0.0
            )
            err = difference(result.transform, x)
            err[3:] = np.degrees(err[3:])
            out.append(err / np.sqrt(np.diag(result.covariance)))
    told = np.sqrt(np.mean(np.square(z_told), axis=0))
    untold = np.sqrt(np.mean(np.square(z_untold), axis=0))
    assert np.all((told > 0.8) & (told < 1.25)), told
    # Untold, the chi2/dof scaling widens the std, but not enough: the robot's noise must be given.
    assert untold.max() > 1.3 * told.max(), (told, untold)


@pytest.mark.slow
def test_without_pose_covariances_the_residuals_set_the_uncertainty():
    setup = "eye-to-hand"
    rng = np.random.default_rng(8)
    x, y, tools = cell(setup, rng, count=20)
    cov = np.diag([0.05, 0.05, 0.2, 0.1, 0.1, 0.05]) ** 2
    z = []
    for _ in range(150):
        pairs = [Pair(t, noisy(true_code_pose(setup, x, y, t), cov, rng)) for t in tools]
        result = solve_handeye(pairs, setup)
        assert not result.weighted
        err = difference(result.transform, x)
        err[3:] = np.degrees(err[3:])
        z.append(err / np.sqrt(np.diag(result.covariance)))
    rms = np.sqrt(np.mean(np.square(z), axis=0))
    # Unit weights are not the best weights, but the covariance still says how large the error is.
    assert np.all((rms > 0.5) & (rms < 2.0)), rms


@pytest.mark.parametrize("setup", SETUPS)
def test_turns_all_about_one_axis_are_refused_naming_the_axis_and_what_to_add(setup):
    rng = np.random.default_rng(2)
    x, y, _ = cell(setup, rng)
    # Tool poses that differ only by turns about one axis (and translations): degenerate.
    base = random_rigid(rng, 30, 100)
    axis = np.array([0.0, 0.0, 1.0])
    tools = []
    for _ in range(12):
        turn = rigid(rotation_exp(axis * math.radians(rng.uniform(-90, 90))), rng.normal(size=3) * 100)
        tools.append(base @ turn if setup == "eye-in-hand" else turn @ base)
    pairs = [Pair(t, true_code_pose(setup, x, y, t)) for t in tools]
    with pytest.raises(HandEyeError, match="all about one axis") as caught:
        solve_handeye(pairs, setup)
    message = str(caught.value)
    frame = "tool" if setup == "eye-in-hand" else "base"
    assert f"in the {frame} frame" in message and "add poses turned" in message
    assert "\n" not in message


def test_a_tool_that_hardly_turns_and_too_few_pairs_are_refused():
    setup = "eye-in-hand"
    rng = np.random.default_rng(4)
    x, y, _ = cell(setup, rng)
    tools = [random_rigid(rng, 1.0, 100) for _ in range(10)]
    with pytest.raises(HandEyeError, match="hardly turns"):
        solve_handeye([Pair(t, true_code_pose(setup, x, y, t)) for t in tools], setup)
    tools = [random_rigid(rng, 40, 100) for _ in range(4)]
    with pytest.raises(HandEyeError, match=r"4 usable pairs; .* at least 5"):
        solve_handeye([Pair(t, true_code_pose(setup, x, y, t)) for t in tools], setup)


def test_a_bad_pair_stands_out_in_the_residuals():
    setup = "eye-in-hand"
    rng = np.random.default_rng(6)
    x, y, tools = cell(setup, rng)
    cov = np.diag([0.03, 0.03, 0.1, 0.05, 0.05, 0.03]) ** 2
    codes = [noisy(true_code_pose(setup, x, y, t), cov, rng) for t in tools]
    codes[7] = rigid(codes[7][:3, :3], codes[7][:3, 3] + [3.0, 0.0, 0.0])  # a 3 mm slip at pair 7
    result = solve_handeye(
        [Pair(t, c, cov, f"#{k}") for k, (t, c) in enumerate(zip(tools, codes, strict=True))], setup
    )
    assert int(np.argmax(result.residuals_mm)) == 7
    assert result.residuals_mm[7] > 1.5
    assert result.chi2 / result.dof > 5 and result.scale == pytest.approx(result.chi2 / result.dof)


def test_bad_arguments_are_refused():
    rng = np.random.default_rng(1)
    x, y, tools = cell("eye-in-hand", rng)
    pairs = [Pair(t, true_code_pose("eye-in-hand", x, y, t)) for t in tools]
    with pytest.raises(ValueError, match="set-up 'hand-in-eye' is not one of eye-in-hand, eye-to-hand"):
        solve_handeye(pairs, "hand-in-eye")
    with pytest.raises(ValueError, match="tool_std_mm"):
        solve_handeye(pairs, "eye-in-hand", tool_std_mm=-1.0)
    with pytest.raises(ValueError, match=r"code_cov must have shape \(6, 6\)"):
        Pair(tools[0], tools[0], np.eye(3))
    with pytest.raises(ValueError, match="pair p1 code pose: the upper-left 3x3 is not a rotation"):
        Pair(tools[0], np.diag([2.0, 1.0, 1.0, 1.0]), label="p1")
