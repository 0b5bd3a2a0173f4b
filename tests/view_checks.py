"""Checks shared by the detection tests on views of the hard and steep sets
(qrfield.testing.hardset: segno's symbols, cv2.projectPoints' corners as the truth).

- :func:`found_once`: a view detected end to end gives exactly its one code, read and refined,
  every corner within :data:`CORNER_TOLERANCE_PX` of the true V1..V4;
- :func:`drawn_agreement`: how much of a matrix read is the symbol segno drew.
"""

from __future__ import annotations

import numpy as np

from qrfield.detect import Detector
from qrfield.detect.detection import Detection
from qrfield.testing.hardset import HardView, symbol_matrix

#: How far (px) a detected corner may lie from the true one.
CORNER_TOLERANCE_PX = 0.3


def found_once(view: HardView, detector: Detector | None = None, label: str = "") -> Detection:
    """The one detection of ``view.image`` by ``detector`` (default: ``Detector(camera=view.camera)``),
    asserted to carry the view's text, to be refined and to have each corner within
    CORNER_TOLERANCE_PX of ``view.corners_px`` (4, 2) px; ``label`` names the view in a failure
    (default "view INDEX")."""
    label = label or f"view {view.index}"
    found = (detector or Detector(camera=view.camera)).detect(view.image)
    assert len(found) == 1, f"{label}: {len(found)} codes"
    (d,) = found
    assert d.text == view.text and d.refined, f"{label}: text {d.text!r}, refined {d.refined}"
    error = np.linalg.norm(d.corners_px - view.corners_px, axis=1)
    assert error.max() < CORNER_TOLERANCE_PX, f"{label}: {error.max():.3f} px off"
    return d


def drawn_agreement(matrix: np.ndarray, text: str) -> float:
    """The share (0..1) of the modules of ``matrix`` (n, n) bool that equal segno's symbol of
    ``text`` at the error level (L, M, Q or H) of that size agreeing best: the view's own level
    is not recorded, and the levels' symbols differ in their format and data modules."""
    drawn = [symbol_matrix(text, level)[0] for level in "LMQH"]
    return max(float(np.mean(matrix == d)) for d in drawn if d.shape == matrix.shape)
