"""The app's simulation tab, offscreen with pytest-qt: Run and Stop by clicks, the coverage table
against run_study called directly (and against a hand verdict), the study's errors next to their
fields, the window staying responsive, settings persisted, a screenshot."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from PySide6 import QtCore

from qrfield.simulation import load_study, run_study
from ui.simulation_tab import SimulationTab

pytestmark = [pytest.mark.gui, pytest.mark.slow]
WAIT_MS = 60_000
CAMERA = "picam-v2@640x480"


@pytest.fixture
def make_tab(qtbot, tmp_path: Path):
    tabs: list[SimulationTab] = []

    def make(saved: dict | None = None) -> SimulationTab:
        tab = SimulationTab(CAMERA, 50.0, saved)
        tab.output_dir.setText(str(tmp_path / "out"))
        tab.resize(560, 980)
        qtbot.addWidget(tab)
        tab.show()
        tabs.append(tab)
        return tab

    yield make
    for tab in tabs:
        tab.shutdown()


def type_into(qtbot, tab: SimulationTab, name: str, text: str) -> None:
    """Replace the text of form field ``name`` by typing, as a user does."""
    widget = tab.widgets[name]
    widget.selectAll()
    qtbot.keyClick(widget, QtCore.Qt.Key.Key_Delete)
    qtbot.keyClicks(widget, text)


def fill(qtbot, tab: SimulationTab, texts: dict[str, str], values: dict[str, object] | None = None) -> None:
    for name, text in texts.items():
        type_into(qtbot, tab, name, text)
    for name, value in (values or {}).items():
        widget = tab.widgets[name]
        if hasattr(widget, "setCurrentText"):
            widget.setCurrentText(value)
        else:
            widget.setValue(value)


WITHIN, CONVERGED = "\nwithin criteria", "\nconverged + within"


def table_cells(tab: SimulationTab) -> dict[tuple[str, str], str]:
    """{(row header, column header): text} of the coverage table (columns "KEY\nwithin criteria",
    "KEY\nconverged + within", ..., "seed (Teoh 2022)")."""
    table = tab.table
    out = {}
    for r in range(table.rowCount()):
        for c in range(table.columnCount()):
            item = table.item(r, c)
            if item is not None:
                out[(table.verticalHeaderItem(r).text(), table.horizontalHeaderItem(c).text())] = item.text()
    return out


def run_by_click(qtbot, tab: SimulationTab) -> None:
    assert tab.run_button.isEnabled(), tab.status.text()
    with qtbot.waitSignal(tab.finished, timeout=WAIT_MS):
        qtbot.mouseClick(tab.run_button, QtCore.Qt.MouseButton.LeftButton)


SMALL = {"x_range": "-60, 60, 60", "y_range": "-40, 40, 40", "z_range": "300", "solvers": "numerical, ippe"}
SMALL_OVERRIDES = [
    f"camera={CAMERA}",
    "side_mm=50",
    "x_range=-60,60,60",
    "y_range=-40,40,40",
    "z_range=300",
    "solvers=numerical,ippe",
    "sweep_limit_deg=60",
    "sweep_step_deg=10",
]


def test_the_default_form_is_the_small_study(make_tab) -> None:
    tab = make_tab()
    assert tab.config is not None and tab.run_button.isEnabled()
    assert tab.config.size() == {"grid_points": 30, "combinations": 12, "angles": 13, "poses": 4680}
    assert "4680 poses" in tab.size_label.text()
    assert (tab.config.camera, tab.config.side_mm) == (CAMERA, 50.0)
    # The "Default study" preset is the shipped study of `qrfield simulate`.
    tab.default_button.click()
    assert tab.config == load_study(overrides=[f"camera={CAMERA}", "side_mm=50"])
    tab.small_button.click()
    assert tab.config.size()["poses"] == 4680


def test_run_shows_the_coverage_of_run_study_and_stays_responsive(make_tab, qtbot, tmp_path: Path) -> None:
    tab = make_tab()
    fill(qtbot, tab, SMALL, {"sweep_step_deg": 10.0})
    expected_config = load_study(overrides=SMALL_OVERRIDES)
    assert tab.config == expected_config

    ticks: list[int] = []
    timer = QtCore.QTimer()
    timer.timeout.connect(lambda: ticks.append(1) if tab.run is not None else None)
    timer.start(5)
    progress: list[object] = []
    tab.progressed.connect(progress.append)
    run_by_click(qtbot, tab)
    timer.stop()
    # The GUI thread handled a timer event while the study ran (a study run on the GUI thread
    # shows none: it sets and clears tab.run before the event loop runs again). One, not two:
    # on a loaded machine the 756-pose study may end within two 5 ms ticks.
    assert len(ticks) >= 1
    assert progress and progress[-1].done_poses == progress[-1].total_poses == 9 * 12 * 7

    expected = run_study(expected_config)  # the same study, run directly
    cells = table_cells(tab)
    for c, combo in enumerate(expected.combinations):
        for key in ("numerical", "ippe"):
            want = expected.coverage(key, c)
            assert cells[(combo.name, key + WITHIN)] == f"{100 * want:.2f} %", (combo.name, key)
            want = expected.coverage(key, c, converged_only=True)
            assert cells[(combo.name, key + CONVERGED)] == f"{100 * want:.2f} %", (combo.name, key)
    for key in ("numerical", "ippe"):
        assert cells[("mean", key + WITHIN)] == f"{100 * expected.mean_coverage(key):.2f} %"
        want = expected.mean_coverage(key, converged_only=True)
        assert cells[("mean", key + CONVERGED)] == f"{100 * want:.2f} %"
    assert cells[("mean", "seed (Teoh 2022)")] == "77.28 %"
    assert "done: 756 poses" in tab.status.text() and not tab.result.partial

    # Heatmaps: one per combination and z in the output folder; the chosen one is shown.
    shown = tab.heatmap_shown()
    assert shown is not None and shown.is_file() and shown.parent.parent.parent == tmp_path / "out"
    assert shown.name == "alpha_z300.png" and not tab.heatmap.pixmap.isNull()
    tab.combo_choice.setCurrentIndex(4)
    assert tab.heatmap_shown().name == f"{expected.combinations[4].name}_z300.png"
    assert str(shown.parent.parent) in tab.output_label.text() and tab.open_button.isEnabled()
    shot = tmp_path / "simulation_tab.png"
    assert tab.grab().save(str(shot)) and shot.stat().st_size > 10_000


def test_a_study_of_two_poses_gives_the_hand_verdict(make_tab, qtbot, tmp_path: Path) -> None:
    # One combination (alpha), the card squarely in front at 300 mm, tilted 0 and 10 deg: exact
    # corners give both solvers the true pose, so both samples pass (100 %). Corners rounded to
    # whole pixels move the pose by about a millimetre, which fails a 0.001 mm criterion (0 %).
    combos = tmp_path / "alpha.csv"
    combos.write_text("name,alpha,beta,gamma\nalpha,1,0,0\n", encoding="utf-8")
    tab = make_tab()
    texts = {"x_range": "0", "y_range": "0", "z_range": "300", "combinations": str(combos)}
    texts["solvers"] = "numerical, ippe"
    fill(qtbot, tab, texts, {"sweep_limit_deg": 10.0, "sweep_step_deg": 10.0})
    assert "2 poses" in tab.size_label.text()
    run_by_click(qtbot, tab)
    cells = table_cells(tab)
    verdicts = [cells[(row, key + WITHIN)] for row in ("alpha", "mean") for key in ("numerical", "ippe")]
    assert verdicts == ["100.00 %"] * 4

    tab.auto_run.setChecked(False)  # one run per click here
    fill(qtbot, tab, {}, {"degradation": "round", "criteria.position_mm": 0.001})
    run_by_click(qtbot, tab)
    cells = table_cells(tab)
    verdicts = [cells[(row, key + WITHIN)] for row in ("alpha", "mean") for key in ("numerical", "ippe")]
    assert verdicts == ["0.00 %"] * 4


def test_stop_keeps_what_is_done_as_a_partial_result(make_tab, qtbot, monkeypatch) -> None:
    from qrfield.simulation import runner

    monkeypatch.setattr(runner, "CHUNK_POSES", 1395)  # one combination per task: 12 tasks
    tab = make_tab()
    fill(qtbot, tab, {"z_range": "250, 450, 100"}, {"sweep_step_deg": 2.0})  # 45 x 12 x 31 = 16740 poses
    progress: list[object] = []
    tab.progressed.connect(progress.append)
    with qtbot.waitSignal(tab.progressed, timeout=WAIT_MS):
        qtbot.mouseClick(tab.run_button, QtCore.Qt.MouseButton.LeftButton)
    assert tab.stop_button.isEnabled() and not tab.run_button.isEnabled()
    with qtbot.waitSignal(tab.finished, timeout=WAIT_MS):
        qtbot.mouseClick(tab.stop_button, QtCore.Qt.MouseButton.LeftButton)
    result = tab.result
    assert result is not None and result.partial and 0 < result.poses_done < 16740
    assert "PARTIAL" in tab.status.text() and tab.run_button.isEnabled()
    done_combos = [c for c in range(12) if result.done[c].all()]
    assert done_combos == list(range(len(done_combos))) and done_combos  # whole combinations, in order
    assert len(progress) == len(done_combos)

    # The same study stopped after as many tasks, run directly, gives the same figures.
    tasks = [0]
    expected = run_study(
        tab.config,
        progress=lambda p: tasks.__setitem__(0, tasks[0] + 1),
        stop=lambda: tasks[0] >= len(done_combos),
    )
    cells = table_cells(tab)
    for c, combo in enumerate(result.combinations):
        for key in result.solvers:
            want = expected.coverage(key, c)
            assert cells[(combo.name, key + WITHIN)] == ("n/a" if want is None else f"{100 * want:.2f} %")
    assert tab.combo_choice.count() == len(done_combos) and tab.heatmap_shown() is not None


def test_stop_during_a_run_on_every_core_keeps_the_finished_tasks(make_tab, qtbot, monkeypatch) -> None:
    import numpy as np

    from qrfield.simulation import parallel, runner

    monkeypatch.setattr(parallel, "PARALLEL_MIN_POSES", 0)  # this study on worker processes
    monkeypatch.setattr(runner, "CHUNK_POSES", 1395)
    tab = make_tab()
    fill(qtbot, tab, {"z_range": "250, 450, 100"}, {"sweep_step_deg": 2.0})  # 16740 poses
    with qtbot.waitSignal(tab.progressed, timeout=WAIT_MS):
        qtbot.mouseClick(tab.run_button, QtCore.Qt.MouseButton.LeftButton)
    with qtbot.waitSignal(tab.finished, timeout=WAIT_MS):
        qtbot.mouseClick(tab.stop_button, QtCore.Qt.MouseButton.LeftButton)
    result = tab.result
    assert result.partial and 0 < result.done.sum() < result.done.size
    assert "PARTIAL" in tab.status.text() and (tab.outcome.out_dir / "summary.json").is_file()
    full = run_study(tab.config, workers=1)
    done = result.done
    np.testing.assert_array_equal(result.status[:, done], full.status[:, done])


def test_a_change_after_a_run_runs_the_study_again_as_a_preview(make_tab, qtbot, tmp_path: Path) -> None:
    tab = make_tab()
    fill(qtbot, tab, SMALL, {"sweep_step_deg": 20.0})
    run_by_click(qtbot, tab)
    saved = tab.outcome.out_dir
    assert saved is not None and (saved / "summary.json").is_file()
    # Typing a new z range re-runs the study by itself (debounced), without a click.
    type_into(qtbot, tab, "z_range", "350")
    qtbot.waitUntil(lambda: tab.run is None and tab.result.config == tab.config, timeout=WAIT_MS)
    assert tab.config.z_range == (350.0, 350.0, 1.0)
    expected = run_study(tab.config)
    cells = table_cells(tab)
    for key in ("numerical", "ippe"):
        assert cells[("mean", key + WITHIN)] == f"{100 * expected.mean_coverage(key):.2f} %"
    # A preview is shown, not written: the output folder holds the one saved run only.
    assert sorted((tmp_path / "out").iterdir()) == [saved]
    assert "preview" in tab.status.text() and tab.outcome.out_dir == saved
    assert tab.heatmap_shown() is None and not tab.heatmap.pixmap.isNull()  # drawn from memory
    assert str(saved) in tab.output_label.text() and tab.open_button.isEnabled()


def test_a_change_during_a_run_supersedes_it(make_tab, qtbot, monkeypatch) -> None:
    from qrfield.simulation import runner

    monkeypatch.setattr(runner, "CHUNK_POSES", 500)
    tab = make_tab()
    fill(qtbot, tab, SMALL, {"sweep_step_deg": 20.0})
    run_by_click(qtbot, tab)
    tab.auto_run.setChecked(False)
    fill(qtbot, tab, {"z_range": "250, 450, 100"}, {"sweep_step_deg": 1.0})  # 45 x 12 x 61 poses
    tab.auto_run.setChecked(True)
    tab._rerun_timer.setInterval(10)  # re-run at once: the change below must land during the run
    finished: list[object] = []
    tab.finished.connect(finished.append)
    tab.start(save=False)
    first = tab.run
    assert first is not None
    type_into(qtbot, tab, "y_range", "0")  # changed while it runs
    qtbot.waitUntil(lambda: bool(finished) and tab.run is None, timeout=WAIT_MS)
    assert first.superseded and first.config.y_range == (-40.0, 40.0, 40.0)
    assert len(finished) == 1 and tab.result.config == tab.config and not tab.result.partial
    assert tab.config.y_range == (0.0, 0.0, 1.0)


def test_open_folder_says_where_the_run_is_when_there_is_no_desktop(make_tab, qtbot) -> None:
    tab = make_tab()
    fill(qtbot, tab, SMALL, {"sweep_step_deg": 30.0})
    run_by_click(qtbot, tab)
    assert tab.open_button.isEnabled() and tab.open_button.text() == "Open folder"
    qtbot.mouseClick(tab.open_button, QtCore.Qt.MouseButton.LeftButton)  # offscreen: nothing to open
    assert f"the run folder is {tab.outcome.out_dir}" in tab.status.text()


def test_runs_go_to_the_data_folder_by_default(qtbot, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("QRFIELD_DATA_DIR", str(tmp_path / "data"))
    tab = SimulationTab(CAMERA, 50.0)
    qtbot.addWidget(tab)
    assert (
        tab.output_dir.text() == ""
        and str(tmp_path / "data" / "simulations") in tab.output_dir.placeholderText()
    )
    folder = tab.output_folder()
    assert folder.parent == tmp_path / "data" / "simulations" and folder.is_dir()
    assert re.fullmatch(r"\d{8}-\d{6}(-\d+)?", folder.name)
    tab.shutdown()


@pytest.mark.parametrize(
    ("field", "text", "message"),
    [
        ("z_range", "200,100,50", "field 'z_range': stop 100 is below start 200"),
        ("z_range", "2OO,600,100", "field 'z_range' must be [start, stop, step]"),
        ("x_range", "-90, 90, 0", "field 'x_range': step must be positive"),
        ("solvers", "numerical, ipe", "field 'solvers': unknown solver 'ipe'"),
        ("combinations", "no-such.csv", "field 'combinations'"),
    ],
)
def test_a_bad_field_shows_the_study_error_beside_it_and_disables_run(
    make_tab, qtbot, field: str, text: str, message: str
) -> None:
    tab = make_tab()
    assert tab.run_button.isEnabled() and tab.error_text(field) == ""
    type_into(qtbot, tab, field, text)
    assert message in tab.error_text(field)
    assert not tab.run_button.isEnabled() and tab.config is None
    others = [name for name in tab.widgets if name != field]
    assert all(tab.error_text(name) == "" for name in others)
    tab.small_button.click()
    assert tab.error_text(field) == "" and tab.run_button.isEnabled()


def test_a_consistency_error_names_its_field(make_tab, qtbot) -> None:
    tab = make_tab()
    fill(qtbot, tab, {}, {"degradation": "noise"})  # noise with sigma 0
    assert "noise_px" in tab.error_text("noise_px") and not tab.run_button.isEnabled()
    fill(qtbot, tab, {}, {"noise_px": 0.5})
    assert tab.error_text("noise_px") == "" and tab.run_button.isEnabled()


def test_the_camera_follows_the_app_unless_unticked_and_settings_round_trip(make_tab, qtbot) -> None:
    tab = make_tab()
    tab.set_app_camera("picam-v2@1640x1232", 80.0)
    assert (tab.config.camera, tab.config.side_mm) == ("picam-v2@1640x1232", 80.0)
    assert not tab.widgets["camera"].isEnabled()
    tab.follow_app.setChecked(False)
    type_into(qtbot, tab, "camera", "picam-v2@640x480")
    tab.set_app_camera("picam-v2@320x240", 30.0)
    assert (tab.config.camera, tab.config.side_mm) == ("picam-v2@640x480", 80.0)
    type_into(qtbot, tab, "z_range", "200, 300, 50")
    saved = tab.settings()
    again = make_tab(saved)
    assert again.config == tab.config and again.widgets["z_range"].text() == "200, 300, 50"
    assert not again.follow_app.isChecked() and again.output_dir.text() == tab.output_dir.text()
    # A damaged saved value falls back to the default with a note, and the tab still works.
    broken = make_tab({"study": {"z_range": [1, 2], "sweep_step_deg": "abc"}})
    assert broken.problems and broken.config is not None


def test_the_main_window_has_the_tab_and_persists_it(qtbot, tmp_path: Path) -> None:
    from qrfield.runconfig import ConfigStore
    from ui.main_window import MainWindow

    def window() -> MainWindow:
        w = MainWindow(ConfigStore(tmp_path / "config"), {"source": "virtual", "side_mm": 42.0})
        qtbot.addWidget(w)
        return w

    first = window()
    tab = first.simulation_tab
    titles = [first.work_tabs.tabText(i) for i in range(first.work_tabs.count())]
    assert first.work_tabs.widget(titles.index("Simulation")) is tab
    assert tab.config is not None and tab.config.side_mm == 42.0
    type_into(qtbot, tab, "y_range", "-20, 20, 20")
    first.shutdown()
    second = window()
    assert second.simulation_tab.widgets["y_range"].text() == "-20, 20, 20"
    assert second.simulation_tab.config.y_range == (-20.0, 20.0, 20.0)
    second.shutdown()
