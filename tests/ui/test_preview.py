"""The preview draws the image and its overlays in one pixel convention (docs/conventions.md: OpenCV's, the
centre of the top-left pixel is (0, 0))."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore

from ui.preview import PreviewView

pytestmark = pytest.mark.gui


def test_pixel_centres_of_the_image_sit_where_the_overlays_put_them(qtbot) -> None:
    view = PreviewView()
    qtbot.addWidget(view)
    height, width = 48, 64
    view.show_frame(np.zeros((height, width), dtype=np.uint8))
    item = view.image_item
    # The centre of image pixel (row r, column c) is at item coordinates (c + 0.5, r + 0.5).
    for r, c in ((0, 0), (height - 1, width - 1), (10, 33)):
        centre = item.mapToView(QtCore.QPointF(c + 0.5, r + 0.5))
        assert (centre.x(), centre.y()) == pytest.approx((c, r))
    # The image fills exactly the range the view shows: [-0.5, W - 0.5] x [-0.5, H - 0.5].
    shown = item.mapRectToView(item.boundingRect())
    assert (shown.left(), shown.top(), shown.width(), shown.height()) == pytest.approx(
        (-0.5, -0.5, width, height)
    )


@pytest.mark.parametrize("size", [(600, 200), (300, 400), (800, 300)], ids=["wide", "narrow", "very-wide"])
def test_the_status_line_is_never_cut(qtbot, size) -> None:
    """The line over the picture (status, fps, latency, detect and solve times) lies inside the
    picture whatever the preview's shape: wider than the picture, it used to run out of the widget
    ("...(detect 1, sol")."""
    view = PreviewView()
    qtbot.addWidget(view)
    view.resize(*size)
    view.show()
    view.show_frame(np.zeros((480, 640), dtype=np.uint8))
    view.show_info("SIM  19.5 fps  latency 62 ms (detect 41, solve 12.4)  #12345  3 behind")
    qtbot.wait(100)  # the view's range and transform follow the resize
    text = view.info.textItem
    shown = view.mapFromScene(text.mapToScene(text.boundingRect())).boundingRect()
    picture = view.mapFromScene(view.image_item.mapToScene(view.image_item.boundingRect())).boundingRect()
    inside = view.rect().intersected(picture).adjusted(-1, -1, 1, 1)
    assert inside.contains(shown), (shown, inside)


def test_the_status_lines_wrap_width_never_feeds_back_into_itself(qtbot) -> None:
    """Setting the info line's wrap width moves the item; where that changes the view's transform,
    the transform's signal sets the width again. A full suite once spun five minutes in that loop
    (ui.preview resizeEvent -> _fit_info). Here every wrap width set changes the transform at once:
    the loop must end after the width stops changing, and the info line never moves the view's
    range before a picture is shown (the range follows the items then)."""
    view = PreviewView()
    qtbot.addWidget(view)
    view.resize(500, 300)
    view.show()
    qtbot.wait(50)
    before = view.view.viewRange()
    view.show_info("SIM  19.5 fps  latency 62 ms (detect 41, solve 12.4)  #12345  3 behind " * 3)
    qtbot.wait(50)
    assert view.view.viewRange() == before  # the info line does not count in the view's bounds
    text = view.info.textItem
    real = text.setTextWidth
    calls: list[float] = []

    def set_and_move(width: float) -> None:
        calls.append(width)
        assert len(calls) < 50, "the wrap width keeps being set"
        real(width)
        view.view.sigTransformChanged.emit(view.view)  # what a transform that follows would do

    text.setTextWidth = set_and_move
    try:
        view.resize(420, 300)
        qtbot.wait(50)
        view.resize(640, 360)
        qtbot.wait(50)
    finally:
        del text.setTextWidth  # Qt's own again before the widget goes
    assert 1 <= len(calls) < 50
