"""The ground-truth form on its own: the combination follows the angles' signs, a label the
operator picks is kept while it agrees, and fields turn red only once typed into."""

from __future__ import annotations

import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from qrfield.sessions import known_combinations
from qrfield.sessions.combo_signs import sign_table
from ui.groundtruth_form import BAD_STYLE, GroundTruthForm

pytestmark = pytest.mark.gui


@pytest.fixture
def form(qtbot) -> GroundTruthForm:
    form = GroundTruthForm(known_combinations(), signs=sign_table())
    qtbot.addWidget(form)
    form.show()
    return form


def type_into(qtbot, form: GroundTruthForm, name: str, text: str) -> None:
    edit = form.edits[name]
    edit.selectAll()
    qtbot.keyClicks(edit, text)


def type_angles(qtbot, form, alpha: str, beta: str, gamma: str) -> None:
    for name, text in (("alpha", alpha), ("beta", beta), ("gamma", gamma)):
        type_into(qtbot, form, name, text)


def test_the_combination_follows_the_signs_of_the_angles(form, qtbot) -> None:
    assert form.combo.currentText() == ""  # nothing typed, nothing chosen
    type_angles(qtbot, form, "15", "-20", "10")
    assert form.combo.currentText() == "alpha+beta-gamma+" and "signs" in form.combo_note.text()
    # The pose changes to (0, 40, 0): the old label disagrees and is replaced (the row).
    type_angles(qtbot, form, "0", "40", "0")
    assert form.combo.currentText() == "beta" and form.mismatch() == ""


def test_a_label_picked_by_the_operator_is_kept_while_it_agrees(form, qtbot) -> None:
    type_angles(qtbot, form, "20", "0", "0")
    assert form.combo.currentText() == "alpha"
    # The operator picks another label: kept, and the line beside it says what the angles fit.
    form.combo.setCurrentText("alpha+beta+")
    form.combo.activated.emit(form.combo.currentIndex())
    assert form.combo.currentText() == "alpha+beta+"
    assert "fit 'alpha'" in form.combo_note.text() and "'alpha+beta+' means α+ β+ γ0" in form.mismatch()
    # A tilt that agrees with the label picked keeps it.
    type_into(qtbot, form, "beta", "20")
    assert form.combo.currentText() == "alpha+beta+" and form.mismatch() == ""
    assert form.combo_note.text() == ""


def test_signs_no_combination_has_leave_the_label_and_say_so(form, qtbot) -> None:
    type_angles(qtbot, form, "20", "0", "0")
    type_into(qtbot, form, "alpha", "-20")  # no combination sweeps alpha below 0
    assert form.combo.currentText() == "alpha" and form.suggestion() is None
    assert "fit no combination" in form.combo_note.text() and "no combination of the list" in form.mismatch()


def test_fields_turn_red_only_after_input_or_a_failed_attempt(form, qtbot) -> None:
    assert not form.valid and set(form.errors) == {"x", "y", "z", "alpha", "beta", "gamma", "combo"}
    assert all(edit.styleSheet() == "" for edit in form.edits.values()) and not form.problems.isVisible()
    assert form.shown_errors() == {} and form.untouched_errors()[:3] == ["x", "y", "z"]
    type_into(qtbot, form, "z", "-5")
    assert form.edits["z"].styleSheet() == BAD_STYLE and form.edits["x"].styleSheet() == ""
    assert list(form.shown_errors()) == ["z"] and "z must be > 0" in form.problems.text()
    form.reveal_errors()  # what a press of "Log row" does with a bad form
    assert all(edit.styleSheet() == BAD_STYLE for edit in form.edits.values())
    type_into(qtbot, form, "z", "300")
    assert form.edits["z"].styleSheet() == "" and "z" not in form.shown_errors()


def test_enter_submits(form, qtbot) -> None:
    with qtbot.waitSignal(form.submitted, timeout=1000):
        qtbot.keyClick(form.edits["y"], QtCore.Qt.Key.Key_Return)


def test_follow_the_bench_is_offered_only_while_frames_carry_a_true_pose(form) -> None:
    assert not form.follow_box.isVisible() and not form.following  # not the virtual bench (yet)
    form.follow((10.0, -5.0, 300.0), (0.0, 40.0, 0.0))
    assert form.follow_box.isVisible() and form.following
    assert form.fields()["beta"] == "40" and form.combo.currentText() == "beta"
    form.bench_gone()  # a camera instead: nothing to follow
    assert not form.follow_box.isVisible() and not form.following


def type_keys(form: GroundTruthForm, name: str, text: str) -> None:
    """Type ``text`` into field ``name`` as a keyboard sends it, one key event per character
    (QTest's keyClicks aborts on characters beyond Latin-1, such as the minus sign U+2212)."""
    edit = form.edits[name]
    edit.setFocus()
    edit.selectAll()
    for char in text:
        for kind in (QtCore.QEvent.Type.KeyPress, QtCore.QEvent.Type.KeyRelease):
            event = QtGui.QKeyEvent(
                kind, QtCore.Qt.Key.Key_unknown, QtCore.Qt.KeyboardModifier.NoModifier, char
            )
            QtWidgets.QApplication.sendEvent(edit, event)


def test_a_minus_sign_from_an_on_screen_keyboard_is_a_minus(form, qtbot) -> None:
    """(audit-ui) "−10" typed with the minus sign U+2212 (an on-screen keyboard's, or copied
    from a document) was refused as "'−10' is not a number" beside a field that reads like -10;
    it is -10, as the full-width "－５" is -5. A dash between numbers is still refused."""
    type_angles(qtbot, form, "15", "0", "10")
    type_keys(form, "beta", "\u221220")
    type_keys(form, "x", "\uff0d\uff15")
    for name, text in (("y", "-5"), ("z", "300 mm")):
        type_into(qtbot, form, name, text)
    assert form.valid and not form.shown_errors(), form.shown_errors()
    truth = form.truth()
    assert truth is not None
    assert list(truth.position_mm) == [-5.0, -5.0, 300.0] and list(truth.angles_deg) == [15.0, -20.0, 10.0]
    assert form.combo.currentText() == "alpha+beta-gamma+"  # the signs were read as typed
    type_keys(form, "gamma", "10\u221220")
    assert not form.valid and "gamma" in form.shown_errors()
