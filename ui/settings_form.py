"""A form of widgets generated from a settings dataclass (qrfield.settings.specs).

float -> QDoubleSpinBox (unit suffix, limits, decimals), int -> QSpinBox (both with the app's 44 px
step buttons, ui/touch.py), str with choices -> QComboBox, bool -> ui.touch.TouchCheckBox, other
str -> QLineEdit. Tooltips carry each setting's help.
"""

from __future__ import annotations

import contextlib
import dataclasses
import re
from typing import Any

from PySide6 import QtCore, QtWidgets

from qrfield.settings import SettingError, SettingSpec, specs, validated
from ui.touch import TOUCH_PX, TouchCheckBox

INT_LIMIT = 2**31 - 1
FLOAT_LIMIT = 1e9


def widget_for(spec: SettingSpec) -> QtWidgets.QWidget:
    """An editor for one setting, set to its default."""
    tip = spec.describe()
    if spec.type is bool:
        widget: QtWidgets.QWidget = TouchCheckBox()
    elif spec.choices:
        widget = QtWidgets.QComboBox()
        widget.addItems(list(spec.choices))
    elif spec.type is int:
        widget = QtWidgets.QSpinBox()
        widget.setRange(
            int(spec.minimum) if spec.minimum is not None else -INT_LIMIT,
            int(min(spec.maximum, INT_LIMIT)) if spec.maximum is not None else INT_LIMIT,
        )
        if spec.unit:
            widget.setSuffix(f" {spec.unit}")
    elif spec.type is float:
        widget = QtWidgets.QDoubleSpinBox()
        widget.setDecimals(spec.decimals)
        widget.setRange(
            spec.minimum if spec.minimum is not None else -FLOAT_LIMIT,
            spec.maximum if spec.maximum is not None else FLOAT_LIMIT,
        )
        step = 10 ** -min(spec.decimals, 2) if spec.decimals else 1.0
        widget.setSingleStep(step if (spec.maximum or 0) - (spec.minimum or 0) < 50 else max(step, 1.0))
        widget.setKeyboardTracking(False)  # one change per finished edit, not per keystroke
        if spec.unit:
            widget.setSuffix(f" {spec.unit}")
    else:
        widget = QtWidgets.QLineEdit()
    if isinstance(widget, QtWidgets.QAbstractSpinBox):
        # Room for the two step buttons and a short value: the width of the range's largest value
        # (2147483647) would make forms wider than an 800x480 screen allows.
        widget.setMinimumWidth(2 * TOUCH_PX + 64)
    zero = re.search(r"\(0 = ([^)]+)\)", spec.help)
    if zero and spec.minimum == 0 and isinstance(widget, (QtWidgets.QSpinBox, QtWidgets.QDoubleSpinBox)):
        widget.setSpecialValueText(zero.group(1))  # e.g. exposure 0 shows "automatic"
    widget.setToolTip(tip)
    widget.setObjectName(spec.name)
    set_widget_value(widget, spec, spec.default)
    return widget


def set_widget_value(widget: QtWidgets.QWidget, spec: SettingSpec, value: Any) -> None:
    blocker = QtCore.QSignalBlocker(widget)
    if isinstance(widget, QtWidgets.QCheckBox):
        widget.setChecked(bool(value))
    elif isinstance(widget, QtWidgets.QComboBox):
        widget.setCurrentText(str(value))
    elif isinstance(widget, (QtWidgets.QSpinBox, QtWidgets.QDoubleSpinBox)):
        widget.setValue(value)
    elif isinstance(widget, QtWidgets.QLineEdit):
        widget.setText(str(value))
    del blocker


def widget_value(widget: QtWidgets.QWidget) -> Any:
    if isinstance(widget, QtWidgets.QCheckBox):
        return widget.isChecked()
    if isinstance(widget, QtWidgets.QComboBox):
        return widget.currentText()
    if isinstance(widget, (QtWidgets.QSpinBox, QtWidgets.QDoubleSpinBox)):
        return widget.value()
    if isinstance(widget, QtWidgets.QLineEdit):
        return widget.text()
    raise TypeError(f"no value for {type(widget).__name__}")


class SettingsForm(QtWidgets.QWidget):
    """Edits one settings dataclass; emits ``changed(instance)`` with validated values."""

    changed = QtCore.Signal(object)

    def __init__(self, cls: type, value: Any = None, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.cls = cls
        self.specs = specs(cls)
        self.widgets: dict[str, QtWidgets.QWidget] = {}
        layout = QtWidgets.QFormLayout(self)
        layout.setFieldGrowthPolicy(QtWidgets.QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        layout.setVerticalSpacing(2)  # the rows are 44 px high already (ui/touch.py)
        for spec in self.specs:
            widget = widget_for(spec)
            self.widgets[spec.name] = widget
            label = QtWidgets.QLabel(spec.label)
            label.setToolTip(widget.toolTip())
            label.setMinimumHeight(TOUCH_PX)  # as high as its field, its text centred beside it
            label.setAlignment(QtCore.Qt.AlignmentFlag.AlignLeft | QtCore.Qt.AlignmentFlag.AlignVCenter)
            layout.addRow(label, widget)
            for signal_name in ("toggled", "currentTextChanged", "valueChanged", "editingFinished"):
                signal = getattr(widget, signal_name, None)
                if signal is not None:
                    signal.connect(self._emit)
                    break
        self._value = validated(value if value is not None else cls())
        self.set_value(self._value)

    def value(self) -> Any:
        """The form's current settings (the last valid ones if a field is invalid)."""
        data = {spec.name: widget_value(self.widgets[spec.name]) for spec in self.specs}
        with contextlib.suppress(SettingError):  # an invalid field keeps the last valid value
            self._value = validated(dataclasses.replace(self._value, **data))
        return self._value

    def set_value(self, instance: Any) -> None:
        """Show ``instance`` without emitting ``changed``."""
        self._value = validated(instance)
        for spec in self.specs:
            set_widget_value(self.widgets[spec.name], spec, getattr(self._value, spec.name))

    def _emit(self, *_: object) -> None:
        self.changed.emit(self.value())
