"""Widgets generated from settings declarations, and the app's config file."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from PySide6 import QtWidgets

from qrfield.settings import specs
from qrfield.sources import VirtualBenchSettings
from ui.config import AppSettings, ConfigStore, config_dir
from ui.settings_form import SettingsForm, widget_for

pytestmark = pytest.mark.gui


def spec_of(cls: type, name: str):
    return next(s for s in specs(cls) if s.name == name)


def test_each_setting_type_gets_its_widget(qtbot) -> None:
    z = widget_for(spec_of(VirtualBenchSettings, "z_mm"))
    assert isinstance(z, QtWidgets.QDoubleSpinBox)
    assert (z.minimum(), z.maximum(), z.suffix(), z.decimals(), z.value()) == (20.0, 5000.0, " mm", 1, 300.0)
    seed = widget_for(spec_of(VirtualBenchSettings, "seed"))
    assert isinstance(seed, QtWidgets.QSpinBox) and seed.maximum() == 2**31 - 1
    method = widget_for(spec_of(AppSettings, "method"))
    assert isinstance(method, QtWidgets.QComboBox)
    assert [method.itemText(i) for i in range(method.count())] == ["numerical", "ippe", "both"]
    assert isinstance(widget_for(spec_of(AppSettings, "loop")), QtWidgets.QCheckBox)
    text = widget_for(spec_of(VirtualBenchSettings, "text"))
    assert isinstance(text, QtWidgets.QLineEdit) and text.text() == "qrfield"
    assert "grey levels" in widget_for(spec_of(VirtualBenchSettings, "noise_sigma")).toolTip()
    wobble = widget_for(spec_of(VirtualBenchSettings, "wobble_deg"))  # help: "... (0 = still)"
    assert wobble.specialValueText() == "still" and wobble.text() == "still"


def test_form_emits_validated_settings(qtbot) -> None:
    form = SettingsForm(VirtualBenchSettings, VirtualBenchSettings(z_mm=250.0))
    qtbot.addWidget(form)
    assert form.widgets["z_mm"].value() == 250.0
    with qtbot.waitSignal(form.changed) as signal:
        form.widgets["beta_deg"].setValue(33.5)
    assert isinstance(signal.args[0], VirtualBenchSettings)
    assert signal.args[0].beta_deg == 33.5 and signal.args[0].z_mm == 250.0
    form.widgets["alpha_deg"].setValue(500.0)  # the spin box clamps to the declared maximum
    assert form.value().alpha_deg == 180.0


def test_config_store_round_trip_and_damage(tmp_path: Path, monkeypatch) -> None:
    store = ConfigStore(tmp_path)
    assert store.group("app", AppSettings) == AppSettings() and store.problems == []
    store.set_group("app", AppSettings(side_mm=30.0, method="ippe"))
    store.save()
    assert ConfigStore(tmp_path).group("app", AppSettings) == AppSettings(side_mm=30.0, method="ippe")
    # A bad value falls back to its default, the good ones stay, and the problem is named.
    (tmp_path / "app.json").write_text(json.dumps({"app": {"side_mm": -5, "method": "ippe", "unknown": 1}}))
    damaged = ConfigStore(tmp_path)
    assert damaged.group("app", AppSettings) == AppSettings(method="ippe")
    assert any("side_mm" in p and "below the minimum" in p for p in damaged.problems)
    (tmp_path / "app.json").write_text("{not json")
    broken = ConfigStore(tmp_path)
    assert broken.group("app", AppSettings) == AppSettings() and "unreadable" in broken.problems[0]
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path / "elsewhere"))
    assert (
        config_dir() == tmp_path / "elsewhere" and ConfigStore().path == tmp_path / "elsewhere" / "app.json"
    )
