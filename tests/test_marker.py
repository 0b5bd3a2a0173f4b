"""Printable markers: the symbol measures L mm at the stated resolution, decodes to its text, and
the vector files declare the documented page and module pitch (hand-computed numbers)."""

from __future__ import annotations

import re
import shutil
import struct
import subprocess
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import zxingcpp

from qrfield.cli import main
from qrfield.marker import MarkerError, marker_layout, marker_pdf, marker_png, marker_svg, write_marker

MM_TO_PT = 72.0 / 25.4
# Hand-computed for --text qrfield (a 21 x 21 symbol, version 1) with the documented layout:
# card C = L * 29 / 21; content W = max(C, 90); page = (W + 20) x (C + 26 + 20); symbol at
# ((page_w - C) / 2 + 4 L / 21, 10 + 4 L / 21).
L50 = {"page": (110.0, 115.047619048), "symbol": (30.0, 19.523809524), "pitch": 50 / 21}
L100 = {"page": (158.095238095, 184.095238095), "symbol": (29.047619048, 29.047619048), "pitch": 100 / 21}


# ---------------------------------------------------------------------- measuring a raster


def _symbol_edges_px(image: np.ndarray, approx: np.ndarray, pitch_px: float) -> dict[str, float]:
    """Sub-pixel left, right, top, bottom edges of the symbol (pixel-edge coordinates).

    Along scanlines through the finder patterns (whose outer ring is dark on every line from module
    0 to 6), the ink of a window that straddles an edge (white quiet zone on one side, a dark
    module on the other) equals the dark part of the window, so the edge is found exactly for an
    area-sampled image. ``approx``: (4, 2) corners V1..V4 from a detector, good to a third of a module.
    """
    dark = 1.0 - image.astype(float) / 255.0
    left, top = approx[0]
    right, bottom = approx[2]
    half = pitch_px / 2.0
    lines = np.arange(round(top + 0.8 * pitch_px), round(top + 6.2 * pitch_px))  # top finders' rows
    cols = np.arange(round(left + 0.8 * pitch_px), round(left + 6.2 * pitch_px))  # left finders' columns
    a, b = round(left - half), round(left + half)
    lefts = b - dark[lines, a:b].sum(axis=1)
    a, b = round(right - half), round(right + half)
    rights = a + dark[lines, a:b].sum(axis=1)
    a, b = round(top - half), round(top + half)
    tops = b - dark[a:b, cols].sum(axis=0)
    a, b = round(bottom - half), round(bottom + half)
    bottoms = a + dark[a:b, cols].sum(axis=0)
    return {
        k: float(np.mean(v))
        for k, v in (("left", lefts), ("right", rights), ("top", tops), ("bottom", bottoms))
    }


def _detect(image: np.ndarray) -> tuple[str, np.ndarray]:
    text, points, _ = cv2.QRCodeDetector().detectAndDecode(image)
    assert points is not None, "OpenCV found no QR code"
    return text, points.reshape(4, 2)


def _check_raster(
    image: np.ndarray, dpi: float, side_mm: float, symbol_mm: tuple[float, float], text: str
) -> None:
    px_per_mm = dpi / 25.4
    decoded, corners = _detect(image)
    assert decoded == text
    edges = _symbol_edges_px(image, corners + 0.5, side_mm / 21 * px_per_mm)
    width, height = edges["right"] - edges["left"], edges["bottom"] - edges["top"]
    assert abs(width - side_mm * px_per_mm) < 0.5, (
        f"symbol {width:.2f} px wide, {side_mm * px_per_mm:.2f} expected"
    )
    assert abs(height - side_mm * px_per_mm) < 0.5, f"symbol {height:.2f} px high"
    assert abs(edges["left"] - symbol_mm[0] * px_per_mm) < 0.5
    assert abs(edges["top"] - symbol_mm[1] * px_per_mm) < 0.5
    zx = zxingcpp.read_barcodes(image)
    assert [r.text for r in zx] == [text]


# ---------------------------------------------------------------------- PNG


@pytest.mark.slow
@pytest.mark.parametrize(("side_mm", "dpi", "expected"), [(50.0, 600, L50), (50.0, 254, L50)])
def test_png_symbol_measures_l_at_its_dpi(side_mm: float, dpi: float, expected: dict, tmp_path: Path) -> None:
    path = tmp_path / "m.png"
    write_marker(path, "qrfield", side_mm, dpi=dpi)
    data = path.read_bytes()
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    page_px = [int(np.ceil(v * dpi / 25.4 - 1e-9)) for v in expected["page"]]
    assert (image.shape[1], image.shape[0]) == tuple(page_px)
    _check_raster(image, dpi, side_mm, expected["symbol"], "qrfield")
    # pHYs right after IHDR: pixels per metre (600 dpi -> 23622, 254 dpi -> 10000), unit = metre.
    assert data[33 + 4 : 33 + 8] == b"pHYs"
    ppm_x, ppm_y, unit = struct.unpack(">IIB", data[41:50])
    assert (ppm_x, ppm_y, unit) == ({600: 23622, 254: 10000}[dpi],) * 2 + (1,)
    assert struct.unpack(">I", data[50:54])[0] == zlib.crc32(data[37:50])


@pytest.mark.slow
def test_png_other_text_and_size() -> None:
    layout = marker_layout("https://example.org/qrfield/bench-7", 30.0)
    assert layout.n == 29 and layout.pitch_mm == pytest.approx(30 / 29)
    image = cv2.imdecode(np.frombuffer(marker_png(layout, 400), np.uint8), cv2.IMREAD_GRAYSCALE)
    text, corners = _detect(image)
    assert text == "https://example.org/qrfield/bench-7"
    side_px = 30.0 * 400 / 25.4
    assert np.linalg.norm(corners[1] - corners[0]) == pytest.approx(side_px, abs=6.0)


# ---------------------------------------------------------------------- vector files


def _svg_modules(svg: str) -> tuple[np.ndarray, float, tuple[float, float]]:
    transform = re.search(r'<g transform="translate\(([-0-9.]+) ([-0-9.]+)\) scale\(([0-9.e-]+)\)"', svg)
    path = re.search(r'<path d="([^"]+)"', svg).group(1)
    runs = [tuple(map(int, m)) for m in re.findall(r"M(\d+) (\d+)h(\d+)v1h-\d+z", path)]
    return (
        _runs_to_modules([(r, c, n) for c, r, n in runs]),
        float(transform.group(3)),
        (
            float(transform.group(1)),
            float(transform.group(2)),
        ),
    )


def _runs_to_modules(runs: list[tuple[int, int, int]]) -> np.ndarray:
    size = max(c + n for _, c, n in runs)
    modules = np.zeros((size, size), bool)
    for r, c, n in runs:
        modules[r, c : c + n] = True
    return modules


def _decode_modules(modules: np.ndarray) -> str:
    """Decode a module matrix with zxing (independent of OpenCV's encoder)."""
    image = np.where(np.pad(modules, 4), 0, 255).astype(np.uint8)
    image = cv2.resize(image, None, fx=8, fy=8, interpolation=cv2.INTER_NEAREST)
    results = zxingcpp.read_barcodes(image)
    return results[0].text if results else ""


@pytest.mark.parametrize(("side_mm", "expected"), [(50.0, L50), (100.0, L100)])
def test_svg_declares_page_and_pitch(side_mm: float, expected: dict) -> None:
    svg = marker_svg(marker_layout("qrfield", side_mm))
    w, h = expected["page"]
    head = re.search(
        r'<svg [^>]*width="([0-9.]+)mm" height="([0-9.]+)mm" viewBox="0 0 ([0-9.]+) ([0-9.]+)"', svg
    )
    assert head, "the SVG must declare its size in mm and a viewBox in mm"
    assert [float(v) for v in head.groups()] == pytest.approx([w, h, w, h], abs=1e-6)
    modules, scale, origin = _svg_modules(svg)
    assert scale == pytest.approx(expected["pitch"], rel=1e-12)
    assert origin == pytest.approx(expected["symbol"], abs=1e-6)
    # The dark modules span the whole 21 x 21 grid, so the symbol is 21 * pitch = L mm.
    assert modules.shape == (21, 21) and modules[0].any() and modules[:, 0].any()
    assert _decode_modules(modules) == "qrfield"


@pytest.mark.parametrize(("side_mm", "expected"), [(50.0, L50), (100.0, L100)])
def test_pdf_declares_page_and_pitch(side_mm: float, expected: dict) -> None:
    pdf = marker_pdf(marker_layout("qrfield", side_mm))
    w, h = expected["page"]
    box = re.search(rb"/MediaBox \[0 0 ([0-9.]+) ([0-9.]+)\]", pdf)
    assert [float(v) for v in box.groups()] == pytest.approx([w * MM_TO_PT, h * MM_TO_PT], abs=1e-5)
    cm = re.search(rb"\n([0-9.]+) 0 0 -([0-9.]+) ([0-9.]+) ([0-9.]+) cm\n", pdf)
    pitch_pt = expected["pitch"] * MM_TO_PT
    assert float(cm.group(1)) == pytest.approx(pitch_pt, rel=1e-12)
    assert float(cm.group(2)) == pytest.approx(pitch_pt, rel=1e-12)
    sx, sy = expected["symbol"]
    assert float(cm.group(3)) == pytest.approx(sx * MM_TO_PT, abs=1e-5)
    assert float(cm.group(4)) == pytest.approx((h - sy) * MM_TO_PT, abs=1e-5)
    runs = [tuple(map(int, m)) for m in re.findall(rb"\n(\d+) (\d+) (\d+) 1 re", pdf)]
    modules = _runs_to_modules([(r, c, n) for c, r, n in runs])
    assert modules.shape == (21, 21)
    assert _decode_modules(modules) == "qrfield"


def test_pdf_cross_reference_is_exact() -> None:
    pdf = marker_pdf(marker_layout("qrfield", 50.0))
    assert pdf.startswith(b"%PDF-1.") and pdf.endswith(b"%%EOF\n")
    startxref = int(re.search(rb"startxref\n(\d+)\n%%EOF", pdf).group(1))
    assert pdf[startxref:].startswith(b"xref\n0 7\n")
    entries = re.findall(rb"(\d{10}) (\d{5}) ([nf]) \n", pdf[startxref:])
    assert len(entries) == 7 and entries[0][2] == b"f"
    for number, (offset, _gen, _kind) in enumerate(entries[1:], start=1):
        assert pdf[int(offset) :].startswith(f"{number} 0 obj".encode())
    length = int(re.search(rb"/Length (\d+) >>\nstream\n", pdf).group(1))
    stream_start = pdf.index(b"stream\n") + len(b"stream\n")
    assert pdf[stream_start + length :].startswith(b"endstream")


# Independent renderers, where installed (apt: poppler-utils, librsvg2-bin).
@pytest.mark.slow
@pytest.mark.skipif(shutil.which("pdftoppm") is None, reason="pdftoppm (poppler-utils) is not installed")
def test_pdf_rasterised_by_poppler(tmp_path: Path) -> None:
    write_marker(tmp_path / "m.pdf", "qrfield", 50.0)
    subprocess.run(
        ["pdftoppm", "-r", "300", "-gray", "-png", str(tmp_path / "m.pdf"), str(tmp_path / "p")], check=True
    )
    image = cv2.imread(str(tmp_path / "p-1.png"), cv2.IMREAD_GRAYSCALE)
    _check_raster(image, 300, 50.0, L50["symbol"], "qrfield")


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("rsvg-convert") is None, reason="rsvg-convert (librsvg2-bin) is not installed"
)
def test_svg_rasterised_by_librsvg(tmp_path: Path) -> None:
    write_marker(tmp_path / "m.svg", "qrfield", 50.0)
    out = tmp_path / "s.png"
    subprocess.run(
        ["rsvg-convert", "-d", "300", "-p", "300", str(tmp_path / "m.svg"), "-o", str(out)], check=True
    )
    image = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    _check_raster(image, 300, 50.0, L50["symbol"], "qrfield")


# ---------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("text", "side", "name", "message"),
    [
        ("", 50.0, "m.svg", "text must not be empty"),
        ("qrfield", 0.0, "m.svg", "must be positive"),
        ("qrfield", -5.0, "m.pdf", "must be positive"),
        ("qrfield", float("nan"), "m.pdf", "length in mm"),
        ("qrfield", 50.0, "m.jpg", "unknown marker format '.jpg'"),
        ("qrfield", 50.0, "m", "no extension"),
    ],
)
def test_bad_input(text: str, side: float, name: str, message: str, tmp_path: Path) -> None:
    with pytest.raises(MarkerError, match=re.escape(message)):
        write_marker(tmp_path / name, text, side)
    assert list(tmp_path.iterdir()) == []


def test_bad_dpi_and_paths(tmp_path: Path) -> None:
    with pytest.raises(MarkerError, match="dpi must be within"):
        write_marker(tmp_path / "m.png", "qrfield", 50.0, dpi=10)
    with pytest.raises(MarkerError, match="raise --dpi to at least 161"):
        write_marker(tmp_path / "m.png", "qrfield", 10.0, dpi=100)  # 3 px / (10/21 mm) = 160.02 dpi
    with pytest.raises(FileNotFoundError, match="does not exist"):
        write_marker(tmp_path / "no" / "m.svg", "qrfield", 50.0)
    (tmp_path / "d.svg").mkdir()
    with pytest.raises(IsADirectoryError, match="is a folder"):
        write_marker(tmp_path / "d.svg", "qrfield", 50.0)
    write_marker(tmp_path / "m.svg", "qrfield", 50.0)
    before = (tmp_path / "m.svg").read_bytes()
    with pytest.raises(FileExistsError, match="--force"):
        write_marker(tmp_path / "m.svg", "other", 20.0)
    assert (tmp_path / "m.svg").read_bytes() == before
    write_marker(tmp_path / "m.svg", "other", 20.0, force=True)
    assert (tmp_path / "m.svg").read_bytes() != before


@pytest.mark.slow
def test_cli(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "card.pdf"
    assert main(["marker", "--text", "qrfield", "--side-mm", "50", "--out", str(out)]) == 0
    assert "21 x 21 modules of 2.3810 mm" in capsys.readouterr().out
    assert out.read_bytes() == marker_pdf(marker_layout("qrfield", 50.0))
    for argv, message in [
        (["--text", "", "--side-mm", "50", "--out", str(tmp_path / "a.svg")], "empty"),
        (["--text", "x", "--side-mm", "-1", "--out", str(tmp_path / "a.svg")], "below the smallest"),
        (["--text", "x", "--side-mm", "50", "--out", str(tmp_path / "a.gif")], ".gif"),
        (
            ["--text", "x", "--side-mm", "50", "--out", str(tmp_path / "a.svg"), "--dpi", "300"],
            "--dpi applies",
        ),
        (["--text", "x", "--side-mm", "50", "--out", str(out)], "exists"),
    ]:
        assert main(["marker", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err


@pytest.mark.parametrize("side_mm", [50, 100])
def test_assets_are_what_the_command_writes(side_mm: int) -> None:
    """assets/qrfield-Lmm.svg|pdf: regenerate with `qrfield marker --text qrfield --side-mm L --out ...`."""
    assets = Path(__file__).resolve().parent.parent / "assets"
    layout = marker_layout("qrfield", float(side_mm))
    assert (assets / f"qrfield-{side_mm}mm.svg").read_text(encoding="utf-8") == marker_svg(layout)
    assert (assets / f"qrfield-{side_mm}mm.pdf").read_bytes() == marker_pdf(layout)
