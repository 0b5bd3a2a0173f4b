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
