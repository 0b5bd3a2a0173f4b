"""The steep backend (qrfield.detect.steep): small codes compressed by a steep tilt, against the
steep set's truth (segno's symbols, cv2.projectPoints' corners), and frames with no code."""

from __future__ import annotations

import glob
from pathlib import Path

import cv2
import numpy as np
import pytest

segno = pytest.importorskip("segno", reason="segno (a dev dependency) encodes the steep set's symbols")

from view_checks import found_once  # noqa: E402

from qrfield.detect import Detector  # noqa: E402
from qrfield.detect.backends import find_candidates  # noqa: E402
from qrfield.detect.detection import DetectorSettings  # noqa: E402
from qrfield.testing.hardset import steep_view  # noqa: E402

#: Steep-set views (seed 2026) that main's backends (zxing, zxing-x2, finders, small) miss: 169
#: (modules of 1.23 px along the shortest side, compressed 1.7 times, blur 0.86 px, pinhole) and
#: 54 (1.46 px, compressed 2.2 times, blur 1.04 px).
VIEWS = (169, 54)
MAIN_BACKENDS = "zxing,zxing-x2,finders,small"


@pytest.mark.slow
@pytest.mark.parametrize("index", VIEWS)
def test_steep_view_found_where_main_misses(index):
    view = steep_view(index, 2026)
    assert 1.2 <= view.module_px < 1.5
    main = Detector(DetectorSettings(backends=MAIN_BACKENDS), camera=view.camera)
    assert main.detect(view.image) == []
    assert found_once(view).backend == "steep"


#: Steep-set views with modules >= 2 px along the shortest side that main (3ba1100) did not find
#: (issue 26t, diagnosis seeds 2027 and 2031): (seed, index). 2027/137: a 100 mm code at 240 mm
#: near the edge of the distorted lens (2.31 px, blur 1.2 px): curved in the image, its canvas
#: left V1 5 px off; 2031/6: pinhole, in strong perspective (2.44 px, blur 0.8 px): its near
#: finder is 1.5 times its far ones, no template size saw all three.
MISSED_AT_2PX = ((2027, 137), (2031, 6))


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "index"), MISSED_AT_2PX)
def test_steep_view_of_2px_modules_gives_its_pose(seed, index):
    from qrfield.geometry import angle_difference
    from qrfield.solvers import solve

    view = steep_view(index, seed)
    assert view.module_px >= 2.0
    d = found_once(view, label=f"{seed}/{index}")
    # the pose against the rendered one, the thesis' criteria (2 deg, 5 mm)
    pose = solve(d.corners_px, view.camera, view.side_mm, corners_cov=d.corners_cov)
    assert pose.converged and not pose.ambiguous
    assert np.linalg.norm(pose.position_mm - view.pose.position_mm) < 5.0
    assert np.abs(angle_difference(pose.angles_deg, view.pose.angles_deg)).max() < 2.0


def _drawn_symbol(
    text: str, px: int, quiet: int, dark: float, light: float, dtype: type
) -> tuple[np.ndarray, int]:
    """An upright symbol of ``text`` (segno, level M) drawn with square modules of ``px`` pixels
    and a quiet zone of ``quiet`` modules: the image (pixel centres at integers) and the modules
    per side n."""
    matrix = np.array(segno.make(text, error="m", micro=False).matrix, dtype=bool)
    n = matrix.shape[0]
    image = np.full(((n + 2 * quiet) * px,) * 2, light, dtype)
    image[quiet * px : (quiet + n) * px, quiet * px : (quiet + n) * px] = np.where(
        np.kron(matrix, np.ones((px, px), bool)), dark, light
    )
    return image, n


def test_a_symbol_decoded_turned_comes_back_in_its_own_corner_order():
    """decode_rectified from finders taken one place round (V4 given as V1): zxing-cpp reads the
    turned symbol, and the corners come back in the symbol's order (the true ones, drawn here).
    On main they came back as given: steep seed 2037 view 258, the right text with every corner
    one place round."""
    from qrfield.detect.finders import decode_rectified

    text = "qrfield turned"
    px, quiet = 6, 4
    image, n = _drawn_symbol(text, px, quiet, 25, 230, np.uint8)
    lo, hi = quiet * px - 0.5, (quiet + n) * px - 0.5  # pixel centres at integers (OpenCV)
    true = np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]])
    for turn in range(4):
        read, _, corners = decode_rectified(image, np.roll(true, turn, axis=0), n)
        assert read == text, turn
        np.testing.assert_allclose(corners, true)


def test_nothing_on_blank_frames():
    rng = np.random.default_rng(5)
    for level, noise in ((128, 2.0), (60, 6.0), (200, 0.0)):
        frame = np.clip(level + rng.normal(0.0, noise, (480, 640)), 0, 255).astype(np.uint8)
        assert find_candidates(frame, "steep") == []


def _chessboards(folder: Path) -> list[np.ndarray]:
    files = sorted(glob.glob(str(folder / "**" / "*.jpg"), recursive=True))
    return [cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in files]


@pytest.mark.slow
def test_nothing_on_chessboards(shared_data: Path):
    frames = _chessboards(shared_data / "calibration")
    if not frames:
        pytest.skip(f"no chessboard pictures in {shared_data / 'calibration'}")
    detector = Detector()
    for frame in frames:
        assert detector.detect(frame) == []


def test_tilted_chessboard_is_not_taken_for_a_code():
    """A chessboard compressed like a steep code (its busy blob passes the shape test) gives no
    candidate: its corners correlate with no finder triple that holds the fixed patterns."""
    board = np.kron((np.indices((9, 9)).sum(axis=0) % 2) * 200 + 30, np.ones((12, 12))).astype(np.uint8)
    frame = np.full((480, 640), 140, np.uint8)
    warp = np.array([[1.0, 0.0, 260.0], [0.35, 0.45, 180.0]], dtype=np.float32)
    frame = cv2.warpAffine(board, warp, (640, 480), dst=frame, borderMode=cv2.BORDER_TRANSPARENT)
    frame = cv2.GaussianBlur(frame, (0, 0), 0.9)
    assert find_candidates(frame, "steep") == []


#: Steep-set views (seed 2026) whose canvas locates the code from the strongest finder triple
#: (issue-26p2): 169 (distorted lens, 25 modules) and 2 (pinhole, 25 modules), located 1.2-1.8 px
#: from the true corners (unrefined), not decoded in the canvas.
FIRST_TRIO_VIEWS = (169, 2)


@pytest.mark.slow
@pytest.mark.parametrize("index", FIRST_TRIO_VIEWS)
def test_a_canvas_stops_at_the_first_trio_that_locates_the_code(index, monkeypatch):
    """Once a finder triple locates a code in a canvas no further triple is fitted (the trio
    fits were a third of the backend's cost; issue-26p2), and the code located is the view's own:
    its modules, each corner within 2.5 px of cv2.projectPoints' truth. On main every one of the
    TRIOS strongest triples was fitted unless one decoded."""
    import qrfield.detect.finders as finders
    import qrfield.detect.steep as steep
    from qrfield.detect.lens import Lens

    view = steep_view(index, 2026)
    fits: list[list[bool]] = []  # per canvas: for each trio fit, whether it located a code
    fit, locate = finders._candidates_from_finders, steep._locate_in_canvas

    def counted_fit(grey, quads):
        out = fit(grey, quads)
        fits[-1].append(bool(out))
        return out

    def counted_locate(canvas, short_w, scale, decode, candidates):
        fits.append([])
        return locate(canvas, short_w, scale, decode, counted_fit)

    monkeypatch.setattr(steep, "_locate_in_canvas", counted_locate)
    found = steep.locate_steep(view.image, Lens(view.camera if view.camera.has_distortion else None))
    assert any(any(canvas) for canvas in fits), "no trio located a code"
    for canvas in fits:
        if any(canvas):
            assert canvas.index(True) == len(canvas) - 1, f"trios fitted after the first located: {canvas}"
    close = [(c, n) for c, n, _, _ in found if np.linalg.norm(c - view.corners_px, axis=1).max() < 2.5]
    assert len(close) == 1 and close[0][1] == view.modules


def test_large_finder_templates_at_half_resolution_give_the_full_resolution_peaks():
    """A drawn upright symbol of 5 px modules (finder template 45 px, above COARSE_TEMPLATE_PX, so
    correlated at half resolution since issue-26p2): its three finder candidates are the three
    strongest peaks of OpenCV's full-resolution correlation with the same template (place and
    value), centred on the drawn finders (3.5 modules in from the symbol's corners)."""
    import qrfield.detect.steep as steep

    text = "qrfield half resolution"
    px, quiet = 5, 4
    canvas, n = _drawn_symbol(text, px, quiet, 30, 220, np.float32)
    canvas = cv2.GaussianBlur(canvas, (0, 0), 0.8)
    size = 9 * px
    assert size > steep.COARSE_TEMPLATE_PX
    peaks = steep._finder_peaks(canvas, [float(px)])[:3]
    response = cv2.matchTemplate(canvas, steep._finder_template(size), cv2.TM_CCOEFF_NORMED)
    full = []
    r = response.copy()
    for _ in range(3):  # OpenCV's three strongest, each finder's neighbourhood masked after it
        _, value, _, (x, y) = cv2.minMaxLoc(r)
        full.append((value, x + (size - 1) / 2.0, y + (size - 1) / 2.0))
        r[max(y - 4 * px, 0) : y + 4 * px + 1, max(x - 4 * px, 0) : x + 4 * px + 1] = -1.0
    for (value, centre, side), (v, x, y) in zip(peaks, full, strict=True):
        assert side == size
        np.testing.assert_allclose(centre, (x, y))
        assert value == pytest.approx(v, abs=1e-6)
    lo, hi = quiet * px - 0.5 + 3.5 * px, (quiet + n) * px - 0.5 - 3.5 * px  # pixel centres at integers
    drawn = np.array([[lo, lo], [hi, lo], [lo, hi]])
    got = np.array(sorted((tuple(c) for _, c, _ in peaks), key=lambda c: (c[1], c[0])))
    np.testing.assert_allclose(got, drawn, atol=1.0)
