"""The live stream in the app: Setup's "live stream" box sets the filter (it reaches the worker and
is saved), and the pose panel says when a flip was resolved by history and when a value is filtered."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from qrfield.pipeline import FrameResult
from qrfield.stream import StreamMark
from ui.pose_panel import PosePanel

pytestmark = pytest.mark.gui
WAIT_MS = 15000


@pytest.mark.slow
def test_setup_sets_the_filter_it_reaches_the_worker_and_is_saved(make_window, qtbot, tmp_path: Path) -> None:
    first = make_window({"source": "virtual", "method": "ippe"})
    form = first.solver_controls.stream
    assert set(form.widgets) == {"continuity", "filter_s"}
    form.widgets["filter_s"].setValue(0.25)
    qtbot.waitUntil(lambda: first.worker._config.stream.filter_s == pytest.approx(0.25), timeout=WAIT_MS)
    # The bench's frames are filtered from then on, and the panel says so.
    qtbot.waitUntil(lambda: first.last is not None and first.last.result.filtered, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: "filtered" in first.pose_panel.headline.text(), timeout=WAIT_MS)
    first.shutdown()
    assert '"filter_s": 0.25' in (tmp_path / "config" / "app.json").read_text()
    second = make_window()
    assert second.solver_controls.stream.value().filter_s == pytest.approx(0.25)


def _pose(method: str, ambiguous: bool = False):
    return SimpleNamespace(
        method=method,
        position_mm=np.array([1.0, 2.0, 300.0]),
        angles_deg=np.array([3.0, 4.0, 5.0]),
        converged=True,
        iterations=4,
        reprojection_px=0.1,
        ambiguity=0.9,
        ambiguous=ambiguous,
        position_std_mm=np.full(3, 0.1),
        angles_std_deg=np.full(3, 0.2),
        reason="",
    )


def test_the_pose_panel_says_what_the_stream_did(qtbot) -> None:
    panel = PosePanel()
    qtbot.addWidget(panel)
    result = FrameResult(
        1,
        33,
        "OK",
        detection=SimpleNamespace(text="qrfield", corners_px=np.zeros((4, 2))),
        poses={"numerical": _pose("numerical"), "ippe": _pose("ippe", ambiguous=True)},
        stream={
            "numerical": StreamMark("history", True, True, flipped=True),
            "ippe": StreamMark("frame", False, True),
        },
    )
    panel.show_result(result, ("numerical", "ippe"), simulated=False)
    numerical = panel._status["numerical"].text()
    ippe = panel._status["ippe"].text()
    assert "flip resolved by history (the mirror branch)" in numerical and "filtered" in numerical
    assert "flip risk" not in numerical
    assert "flip risk" in ippe and "history" not in ippe and "filtered" not in ippe
    assert panel.headline.text().startswith("OK") and "flip resolved by history" in panel.headline.text()
