"""The pose panel: large values per method, the true pose, solver status and the flip warning."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from qrfield.geometry import Pose
from qrfield.pipeline import FrameResult
from ui.pose_panel import PosePanel, solver_status_text

pytestmark = pytest.mark.gui


def pose_result(method: str, position, angles, ambiguity=None, converged=True, reason=""):
    return SimpleNamespace(
        method=method,
        position_mm=np.array(position, float),
        angles_deg=np.array(angles, float),
        converged=converged,
        iterations=5 if method == "numerical" else 0,
        reprojection_px=0.12,
        ambiguity=ambiguity,
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
            "ippe": pose_result("ippe", [12.0, -5.0, 309.0], [18.0, -20.0, 10.0], ambiguity=0.93),
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
    text, warn = solver_status_text(pose_result("ippe", [0, 0, 1], [0, 0, 0], ambiguity=1.4))
    assert "ambiguity 1.40" in text and warn


def test_no_negative_zero_and_stale_only_after_a_real_pose(qtbot) -> None:
    panel = PosePanel()
    qtbot.addWidget(panel)
    panel.mark_stale("no source")  # nothing was ever measured: nothing can be stale
    assert panel.headline.text().startswith("NO SOURCE") and "STALE" not in panel.headline.text()
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
    panel.mark_stale("no source")
    assert panel.headline.text().startswith("STALE")
    panel.source_opened()  # a new source has shown no pose of its own yet
    panel.mark_stale("no source")
    assert panel.headline.text().startswith("NO SOURCE")


def test_numbers_on_screen_never_read_minus_zero() -> None:
    from ui.plots import ZeroSafeAxis
    from ui.text import fixed

    assert fixed(-0.004, 2) == "0.00" and fixed(-0.005001, 2) == "-0.01" and fixed(float("nan"), 1) == "—"
    assert fixed(-0.0, 0) == "0" and fixed(None, 1, missing="-") == "-"
    axis = ZeroSafeAxis("left")
    assert axis.tickStrings([-1e-17, 0.01, -0.01], 1.0, 0.01) == ["0", "0.01", "-0.01"]  # not "-1e-17"
