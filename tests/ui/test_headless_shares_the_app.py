"""The app and the headless commands share one configuration and write the same session rows.

- ``qrfield gui --config-dir D --method ippe ...`` then ``qrfield run --config-dir D ...`` measures
  with ippe (the app wrote the setting, the run read it);
- a row logged by ``qrfield session new`` + ``session log`` on the virtual bench has the same
  columns, each in the same format, as a row the app's Session tab logs (checked column by column,
  from the CSV text as written).
"""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from qrfield.cli import main

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120), pytest.mark.slow]
REPO = Path(__file__).resolve().parents[2]
WAIT_MS = 20000


def qrfield(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO), QT_QPA_PLATFORM="offscreen")
    return subprocess.run(
        [sys.executable, "-m", "qrfield", *args], capture_output=True, text=True, timeout=90, env=env
    )


def test_the_apps_method_reaches_qrfield_run(tmp_path: Path) -> None:
    config = str(tmp_path / "config")
    gui = qrfield(
        "gui", "--config-dir", config, "--method", "ippe", "--source", "virtual", "--quit-after", "2"
    )
    assert gui.returncode == 0, gui.stderr
    saved = json.loads((tmp_path / "config" / "app.json").read_text())
    assert saved["run"]["method"] == "ippe"
    done = qrfield("run", "--config-dir", config, "--source", "virtual", "--frames", "3", "--json-lines")
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(lines) == 3 and all(x["method"] == "ippe" and "methods" not in x for x in lines)
    shown = qrfield("config", "--config-dir", config)
    assert re.search(r"method\s+= ippe\s+config file", shown.stdout), shown.stdout


def kind(text: str) -> str:
    """The format of one CSV cell: what a reader of the file relies on."""
    for name, pattern in (
        ("empty", r""),
        ("int", r"-?\d+"),
        ("mm/deg 3 decimals", r"-?\d+\.\d{3}"),
        ("2 decimals", r"-?\d+\.\d{2}"),
        ("local time", r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d\d:\d\d"),
    ):
        if re.fullmatch(pattern, text):
            return name
    return "text"


def read_rows(folder: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(folder / "rows.csv", newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        header = next(reader)
        return header, [dict(zip(header, row, strict=True)) for row in reader]


def test_cli_rows_are_the_apps_rows_column_by_column(make_window, qtbot, tmp_path: Path, capsys, monkeypatch):
    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "app"))
    window = make_window({"source": "virtual", "method": "numerical"})
    panel = window.session_panel
    panel.name_edit.setText("app")
    panel.row_settings.widgets["frames_per_row"].setValue(3)
    session = panel.create_from_form()
    assert session is not None
    panel.form.set_fields(
        {"x": "10", "y": "-5", "z": "300", "alpha": "15", "beta": "-20", "gamma": "10", "combo": "alpha"}
    )
    panel.form.note.setText("same note")
    panel.ask_combo_choice = lambda message, suggestion: "keep"  # "alpha" for (15, -20, 10), as the CLI row
    qtbot.waitUntil(panel.log_button.isEnabled, timeout=WAIT_MS)  # Log row waits for live frames
    with qtbot.waitSignal(panel.rowLogged, timeout=WAIT_MS):
        assert panel.log_row()
    app_header, (app_row,) = read_rows(session.path)
    app_meta = json.loads((session.path / "session.json").read_text())

    config = ["--config-dir", str(tmp_path / "none")]
    assert (
        main(["session", "new", str(tmp_path / "cli"), "--name", "cli", "--frames-per-row", "3", *config])
        == 0
    )
    folder = Path(capsys.readouterr().out.strip())
    truth = "--truth=10,-5,300,15,-20,10"
    args = [
        "session",
        "log",
        str(folder),
        truth,
        "--combo",
        "alpha",
        "--force-combo",  # the app's "keep" when it asks about the contradicting label
        "--note",
        "same note",
        "--source",
        "virtual",
    ]
    assert main([*args, *config]) == 0
    cli_header, (cli_row,) = read_rows(folder)
    cli_meta = json.loads((folder / "session.json").read_text())

    assert cli_header == app_header
    for column in app_header:
        a, c = app_row[column], cli_row[column]
        assert kind(a) == kind(c), (column, a, c)
    # The same truth, combination, note, frame count and solver give the same texts.
    same = [c for c in app_header if c.startswith("gt_")] + ["row", "combo", "n_frames", "note", "method"]
    assert {k: cli_row[k] for k in same} == {k: app_row[k] for k in same}
    assert (cli_row["pass"], app_row["pass"]) == ("1", "1")
    assert set(cli_meta) == set(app_meta) and cli_meta["columns"] == app_meta["columns"]
    for key in ("camera", "side_mm", "solver", "criteria", "frames_per_row", "format"):
        assert cli_meta[key] == app_meta[key], key
