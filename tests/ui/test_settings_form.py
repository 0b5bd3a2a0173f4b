"""Widgets generated from settings declarations (the config file itself: tests/test_runconfig.py)."""

from __future__ import annotations

import pytest
from PySide6 import QtWidgets

from qrfield.runconfig import RunSettings
from qrfield.settings import specs
from qrfield.sources import VirtualBenchSettings
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
    method = widget_for(spec_of(RunSettings, "method"))
    assert isinstance(method, QtWidgets.QComboBox)
    assert [method.itemText(i) for i in range(method.count())] == ["numerical", "ippe", "both"]
    assert isinstance(widget_for(spec_of(RunSettings, "loop")), QtWidgets.QCheckBox)
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


def test_spin_boxes_step_with_44_px_buttons_and_a_whole_check_box_row_toggles(qtbot) -> None:
    """A tap on the left 44x44 px of a spin box steps it down, on the right 44x44 px up (the two
    stacked 10 px arrows were too small for a finger); a check box toggles by a tap anywhere on its
    44 px row, far from its small square too."""
    from PySide6 import QtCore

    from ui.touch import TOUCH_PX, install_touch_style

    install_touch_style()
    form = SettingsForm(VirtualBenchSettings, VirtualBenchSettings(z_mm=250.0))
    qtbot.addWidget(form)
    form.resize(400, 800)
    form.show()
    z = form.widgets["z_mm"]
    qtbot.waitUntil(lambda: z.height() >= TOUCH_PX)
    step = z.singleStep()
    left = QtCore.Qt.MouseButton.LeftButton
    for x, y, expected in (
        (TOUCH_PX - 4, 3, 250.0 - step),  # near the top edge of the down button, left
        (z.width() - TOUCH_PX + 4, z.height() - 3, 250.0),  # the bottom edge of the up button, right
        (z.width() - 3, z.height() // 2, 250.0 + step),
    ):
        qtbot.mouseClick(z, left, pos=QtCore.QPoint(x, y))
        assert z.value() == pytest.approx(expected), (x, y)
    loop = widget_for(spec_of(RunSettings, "loop"))
    qtbot.addWidget(loop)
    loop.resize(300, TOUCH_PX)
    loop.show()
    qtbot.waitUntil(lambda: loop.height() >= TOUCH_PX)
    was = loop.isChecked()
    qtbot.mouseClick(loop, left, pos=QtCore.QPoint(loop.width() - 5, 2))  # the row's far corner
    assert loop.isChecked() != was
