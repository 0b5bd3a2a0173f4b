"""The pose panel: large values per method, the true pose, solver status and the flip warning."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from qrfield.geometry import Pose
from qrfield.pipeline import FrameResult
from ui.pose_panel import PosePanel, solver_status_text

pytestmark = pytest.mark.gui


def pose_result(
    method: str, position, angles, ambiguity=None, converged=True, reason="", ambiguous=False, std=None
):
    std = np.full(6, np.nan) if std is None else np.array(std, float)
    return SimpleNamespace(
        method=method,
        position_mm=np.array(position, float),
        angles_deg=np.array(angles, float),
        converged=converged,
        iterations=5 if method == "numerical" else 0,
        reprojection_px=0.12,
        ambiguity=ambiguity,
        ambiguous=ambiguous,
        position_std_mm=std[:3],
        angles_std_deg=std[3:],
        reason=reason,
    )


def test_panel_shows_each_method_the_truth_and_the_verdict(qtbot) -> None:
    panel = PosePanel()
    qtbot.addWidget(panel)
    truth = Pose([10.0, -5.0, 300.0], [15.0, -20.0, 10.0])
    result = FrameResult(
        3,
        100,
        "OK",
        detection=SimpleNamespace(text="qrfield", corners_px=np.zeros((4, 2))),
        poses={
            "numerical": pose_result("numerical", [10.4, -5.2, 301.0], [15.5, -19.0, 10.2]),
            "ippe": pose_result(
                "ippe", [12.0, -5.0, 309.0], [18.0, -20.0, 10.0], ambiguity=0.93, ambiguous=True
            ),
        },
        truth=truth,
    )
    panel.show_result(result, ("numerical", "ippe"))
    assert np.allclose(panel.displayed("numerical"), [10.4, -5.2, 301.0, 15.5, -19.0, 10.2])
    assert np.allclose(panel.displayed("true"), [10.0, -5.0, 300.0, 15.0, -20.0, 10.0])
    lines = panel.verdict.text().splitlines()
    assert lines[0] == "vs true pose (✔ = within 2° and 5\u00a0mm):"  # the seed's criteria
    assert lines[1] == "✔ numerical: Δpos 1.10 mm, Δangle ≤ 1.00°"  # sqrt(1.2) = 1.095
    assert lines[2] == "✘ ippe: Δpos 9.22 mm, Δangle ≤ 3.00°"  # sqrt(85) = 9.220
    assert "flip risk" in panel.findChild(type(panel.headline), "status_ippe").text()
    assert "flip risk" not in panel.findChild(type(panel.headline), "status_numerical").text()


def test_solver_status_lines() -> None:
    text, warn = solver_status_text(pose_result("numerical", [0, 0, 1], [0, 0, 0], ambiguity=0.2))
    assert text == "converged, n = 5, reproj 0.12 px" and not warn
    text, warn = solver_status_text(
        pose_result("numerical", [np.nan] * 3, [np.nan] * 3, converged=False, reason="n_max reached")
    )
    assert text.startswith("NOT converged") and text.endswith("n_max reached") and warn
    # The warning follows the core's mirror test, not a ratio threshold of the panel's own.
    text, warn = solver_status_text(pose_result("ippe", [0, 0, 1], [0, 0, 0], ambiguity=0.97))
    assert "flip risk" not in text and not warn
    text, warn = solver_status_text(pose_result("ippe", [0, 0, 1], [0, 0, 0], ambiguity=0.4, ambiguous=True))
    assert "ambiguity 0.40" in text and "flip risk" in text and warn


def test_a_misfit_pose_warns_in_its_status_line() -> None:
    """A real PoseResult whose corners V3 was moved (2.0, -1.5) px under a corner std of 0.1 px
    (no square's pose fits: chi-square far above 9.21) warns; the exact projections do not."""
    from qrfield.camera import resolve_camera
    from qrfield.geometry import marker_vertices, project_points, rotation_matrix
    from qrfield.solvers import solve
    from qrfield.solvers.uncertainty import isotropic_cov

    camera = resolve_camera("picam-v2@640x480")
    pose = Pose([-25.0, 15.0, 320.0], [25.0, -30.0, 40.0])
    corners = project_points(
        marker_vertices(40.0) @ rotation_matrix(pose.angles_deg).T + pose.position_mm, camera
    )
    text, warn = solver_status_text(solve(corners, camera, 40.0, "ippe", corners_cov=isotropic_cov(0.1)))
    assert "do not fit" not in text and not warn
    corners[2] += (2.0, -1.5)
    text, warn = solver_status_text(solve(corners, camera, 40.0, "ippe", corners_cov=isotropic_cov(0.1)))
    assert "the corners do not fit the pose" in text and "> 9.21" in text and warn


def test_each_value_shows_its_uncertainty_beside_it(qtbot) -> None:
    panel = PosePanel()
    qtbot.addWidget(panel)
    std = [0.05, 0.061, 1.234, 0.57, 0.5749, np.nan]
    result = FrameResult(
        1,
        0,
        "OK",
        detection=SimpleNamespace(text="qrfield", corners_px=np.zeros((4, 2))),
        poses={"numerical": pose_result("numerical", [1.0, 2.0, 300.0], [1.0, 2.0, 3.0], std=std)},
    )
    panel.show_result(result, ("numerical",))
    assert np.allclose(panel.displayed("numerical"), [1.0, 2.0, 300.0, 1.0, 2.0, 3.0])
    shown = panel.displayed_std("numerical")
    assert np.allclose(shown[:5], [0.05, 0.06, 1.23, 0.57, 0.57]) and np.isnan(shown[5])  # NaN: none
    z_cell = panel.findChild(type(panel.headline), "numerical_2")
    assert "300.0" in z_cell.text() and "±1.23" in z_cell.text()
    assert "±" not in panel.findChild(type(panel.headline), "numerical_5").text()
    # Without a covariance nothing is shown beside the values.
    result.poses["numerical"] = pose_result("numerical", [1.0, 2.0, 300.0], [1.0, 2.0, 3.0])
    panel.show_result(result, ("numerical",))
    assert np.all(np.isnan(panel.displayed_std("numerical")))


def test_the_verdict_uses_the_criteria_it_is_given(qtbot) -> None:
    from qrfield.sessions import AcceptanceCriteria

    panel = PosePanel()
    qtbot.addWidget(panel)
    truth = Pose([10.0, -5.0, 300.0], [15.0, -20.0, 10.0])
    # 1.10 mm and 1.00 deg off the truth (worked out in the test above).
    poses = {"numerical": pose_result("numerical", [10.4, -5.2, 301.0], [15.5, -19.0, 10.2])}
    detection = SimpleNamespace(text="", corners_px=np.zeros((4, 2)))
    result = FrameResult(3, 100, "OK", detection=detection, poses=poses, truth=truth)
    panel.show_result(result, ("numerical",))
    lines = panel.verdict.text().splitlines()
    assert "within 2° and 5\u00a0mm" in lines[0] and lines[1].startswith("✔ numerical")  # the seed's
    panel.set_criteria(AcceptanceCriteria(max_angle_error_deg=0.5, max_position_error_mm=5.0))
    panel.show_result(result, ("numerical",))
    lines = panel.verdict.text().splitlines()
    assert "within 0.5° and 5\u00a0mm" in lines[0] and lines[1].startswith("✘ numerical")
    panel.set_criteria(AcceptanceCriteria(max_angle_error_deg=2.0, max_position_error_mm=1.0))
    panel.show_result(result, ("numerical",))
    lines = panel.verdict.text().splitlines()
    assert "within 2° and 1\u00a0mm" in lines[0] and lines[1].startswith("✘ numerical")


@pytest.mark.slow
def test_the_window_judges_by_the_open_sessions_criteria(make_window, tmp_path, monkeypatch) -> None:
    from qrfield.sessions import AcceptanceCriteria

    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "sessions"))
    window = make_window({"source": "virtual"})
    panel = window.session_panel
    panel.criteria_form.widgets["max_angle_error_deg"].setValue(1.0)
    assert window.pose_panel.criteria == AcceptanceCriteria(max_angle_error_deg=1.0)  # the form's, no session
    panel.name_edit.setText("strict")
    session = panel.create_from_form()
    panel.criteria_form.widgets["max_angle_error_deg"].setValue(3.0)  # for the next session, not this one
    assert session is not None and window.pose_panel.criteria == session.info.criteria
    assert window.pose_panel.criteria.max_angle_error_deg == 1.0


def test_no_negative_zero_and_stale_only_after_a_real_pose(qtbot) -> None:
    panel = PosePanel()
    qtbot.addWidget(panel)
    panel.show_source_down()  # nothing was ever measured: nothing can be stale
    assert panel.headline.text().startswith("NOSRC") and "STALE" not in panel.headline.text()
    result = FrameResult(
        4,
        101,
        "OK",
        detection=SimpleNamespace(text="qrfield", corners_px=np.zeros((4, 2))),
        poses={"numerical": pose_result("numerical", [-0.04, 0.0, 300.0], [-0.004, 0.001, -0.0])},
    )
    panel.show_result(result, ("numerical",))
    texts = [panel.findChild(type(panel.headline), f"numerical_{r}").text() for r in range(6)]
    assert texts == ["0.0", "0.0", "300.0", "0.00", "0.00", "0.00"]  # -0.04 mm and -0.004 deg round to 0
    panel.show_source_down()
    assert panel.headline.text().startswith("STALE")
    panel.source_opened()  # a new source has shown no pose of its own yet
    panel.show_source_down()
    assert panel.headline.text().startswith("NOSRC")


def test_numbers_on_screen_never_read_minus_zero() -> None:
    from ui.plots import ZeroSafeAxis
    from ui.text import fixed

    assert fixed(-0.004, 2) == "0.00" and fixed(-0.005001, 2) == "-0.01" and fixed(float("nan"), 1) == "—"
    assert fixed(-0.0, 0) == "0" and fixed(None, 1, missing="-") == "-"
    axis = ZeroSafeAxis("left")
    assert axis.tickStrings([-1e-17, 0.01, -0.01], 1.0, 0.01) == ["0", "0.01", "-0.01"]  # not "-1e-17"
