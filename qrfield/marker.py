"""Printable QR markers of exact size: SVG and PDF as vectors, PNG rasterised at a given dpi.

The symbol (the square of the finder patterns' outer edges, quiet zone excluded: the L of
docs/conventions.md) measures exactly ``side_mm`` when printed at 100 %: its n x n modules (OpenCV's
encoder, :func:`qrfield.render.qr_symbol`) have a pitch of L / n mm. Around it: a white quiet zone
of 4 modules, a thin grey cut line just outside it (cut along it and the quiet zone stays whole),
and below, a caption (the text, the size, "print at 100 %") with a check bar of known length.

Page layout (mm, origin at the page's top-left, y down), all numbers from :func:`marker_layout`::

    card      C = L * (n + 8) / n               symbol plus its quiet zone
    content   W = max(C, 90)                    the caption needs 90 mm
    page      (W + 2 * 10)  x  (C + 26 + 2 * 10)
    card      at x = (page width - C) / 2, y = 10; symbol at card + 4 modules
    caption   4 lines of 2.5 mm text, 4 mm apart, first baseline at y = 10 + C + 6, left-aligned
              with the content (x = (page width - W) / 2);
              check bar (100 mm if W >= 100, else 50 mm) 1.5 mm high with 10 mm ticks below.

Modules are drawn in module units under one scale transform (SVG ``scale(L/n)``, PDF ``cm``), so
the pitch is written once, exactly. Black modules on a white page; nothing else touches the quiet zone.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape

import cv2
import numpy as np

from qrfield.render import QUIET_ZONE_MODULES, qr_symbol

MARGIN_MM = 10.0
MIN_CONTENT_MM = 90.0
CAPTION_MM = 26.0
FONT_MM = 2.5
LINE_MM = 4.0
BAR_MM = 1.5
TICK_MM = 1.0
CUT_LINE_MM = 0.2
CUT_GREY = 128
DEFAULT_DPI = 600
#: Allowed --dpi range for the PNG.
DPI_RANGE = (72, 4800)
#: Fewest pixels per module accepted in a PNG (below this, modules smear into each other).
MIN_PX_PER_MODULE = 3.0
FORMATS = (".svg", ".pdf", ".png")
_MM_TO_PT = 72.0 / 25.4


class MarkerError(ValueError):
    """A marker that cannot be made as asked; the message says which input is wrong."""


@dataclass(frozen=True)
class MarkerLayout:
    """Geometry of one marker page, all in mm (page origin top-left, y down).

    Attributes:
        text: the QR payload.
        side_mm: L, the symbol's side without quiet zone.
        modules: (n, n) bool, True = dark.
        page_mm: (width, height) of the page.
        symbol_mm: (x, y) of the symbol's top-left corner (V1) on the page.
        card_mm: (x, y) of the quiet zone's top-left corner; the card is ``card_side_mm`` square.
        bar_mm: length of the check bar.
        caption: the caption's lines, top to bottom.
        caption_xy: (x, y) of the first line's baseline start.
        bar_xy: (x, y) of the check bar's top-left corner.
    """

    text: str
    side_mm: float
    modules: np.ndarray
    page_mm: tuple[float, float]
    symbol_mm: tuple[float, float]
    card_mm: tuple[float, float]
    card_side_mm: float
    bar_mm: float
    caption: tuple[str, ...]
    caption_xy: tuple[float, float]
    bar_xy: tuple[float, float]

    @property
    def n(self) -> int:
        """Modules per side."""
        return int(self.modules.shape[0])

    @property
    def pitch_mm(self) -> float:
        """Module pitch L / n, mm."""
        return self.side_mm / self.n


def marker_layout(text: str, side_mm: float) -> MarkerLayout:
    """Lay out the marker page for ``text`` with a symbol side of ``side_mm`` (see the module docs)."""
    if not isinstance(text, str) or not text:
        raise MarkerError("marker text must not be empty (give --text, e.g. --text qrfield)")
    if isinstance(side_mm, bool) or not isinstance(side_mm, (int, float)) or not math.isfinite(side_mm):
        raise MarkerError(f"marker side must be a length in mm, got {side_mm!r}")
    if side_mm <= 0:
        raise MarkerError(f"marker side must be positive, got {side_mm:g} mm")
    try:
        modules = qr_symbol(text)
    except ValueError as exc:
        raise MarkerError(f"cannot encode {text!r} as a QR code: {exc}") from None
    n = modules.shape[0]
    pitch = side_mm / n
    card = side_mm * (n + 2 * QUIET_ZONE_MODULES) / n
    content = max(card, MIN_CONTENT_MM)
    page = (content + 2 * MARGIN_MM, card + CAPTION_MM + 2 * MARGIN_MM)
    card_xy = ((page[0] - card) / 2.0, MARGIN_MM)
    symbol_xy = (card_xy[0] + QUIET_ZONE_MODULES * pitch, card_xy[1] + QUIET_ZONE_MODULES * pitch)
    left = (page[0] - content) / 2.0
    bar = 100.0 if content >= 100.0 else 50.0
    shown = text if len(text) <= 50 else text[:47] + "..."
    caption = (
        f'"{shown}"',
        f"QR symbol side L = {side_mm:g} mm (quiet zone excluded)",
        f"{n} x {n} modules of {pitch:.4g} mm",
        f"Print at 100 % (no fit to page). Check: this bar = {bar:g} mm",
    )
    first_baseline = MARGIN_MM + card + 6.0
    bar_top = first_baseline + (len(caption) - 1) * LINE_MM + 3.0
    return MarkerLayout(
        text=text,
        side_mm=float(side_mm),
        modules=modules,
        page_mm=page,
        symbol_mm=symbol_xy,
        card_mm=card_xy,
        card_side_mm=card,
        bar_mm=bar,
        caption=caption,
        caption_xy=(left, first_baseline),
        bar_xy=(left, bar_top),
    )


def _module_runs(modules: np.ndarray) -> list[tuple[int, int, int]]:
    """Horizontal runs of dark modules as (row, first column, length)."""
    runs = []
    for row, line in enumerate(modules):
        padded = np.concatenate([[False], line, [False]]).astype(np.int8)
        starts = np.flatnonzero(np.diff(padded) == 1)
        ends = np.flatnonzero(np.diff(padded) == -1)
        runs.extend((row, int(s), int(e - s)) for s, e in zip(starts, ends, strict=True))
    return runs


def _extra_rects(layout: MarkerLayout) -> list[tuple[float, float, float, float, int]]:
    """Filled rectangles other than modules: (x, y, w, h, grey) in page mm: cut line, bar, ticks."""
    x, y = layout.card_mm
    c, t = layout.card_side_mm, CUT_LINE_MM
    rects = [  # cut line: four thin bars just outside the card
        (x - t, y - t, c + 2 * t, t, CUT_GREY),
        (x - t, y + c, c + 2 * t, t, CUT_GREY),
        (x - t, y, t, c, CUT_GREY),
        (x + c, y, t, c, CUT_GREY),
    ]
    bx, by = layout.bar_xy
    rects.append((bx, by, layout.bar_mm, BAR_MM, 0))
    for k in range(round(layout.bar_mm / 10.0) + 1):
        tick_x = bx + min(10.0 * k, layout.bar_mm - 0.2)
        rects.append((tick_x, by + BAR_MM, 0.2, TICK_MM, 0))
    return rects


def _num(value: float) -> str:
    """A number for SVG/PDF text: up to 6 decimals, no trailing zeros."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


# ---------------------------------------------------------------------- SVG


def marker_svg(layout: MarkerLayout) -> str:
    """The marker page as SVG text; 1 user unit = 1 mm, modules under ``scale(L/n)``."""
    w, h = layout.page_mm
    path = "".join(f"M{c} {r}h{length}v1h-{length}z" for r, c, length in _module_runs(layout.modules))
    sx, sy = layout.symbol_mm
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{_num(w)}mm" height="{_num(h)}mm" '
        f'viewBox="0 0 {_num(w)} {_num(h)}">',
        f"<title>qrfield marker: {escape(layout.text)}, {layout.side_mm:g} mm</title>",
        f'<rect x="0" y="0" width="{_num(w)}" height="{_num(h)}" fill="#ffffff"/>',
        f'<g transform="translate({_num(sx)} {_num(sy)}) scale({layout.pitch_mm!r})" fill="#000000">',
        f'<path d="{path}"/>',
        "</g>",
    ]
    for x, y, rw, rh, grey in _extra_rects(layout):
        lines.append(
            f'<rect x="{_num(x)}" y="{_num(y)}" width="{_num(rw)}" height="{_num(rh)}" '
            f'fill="#{grey:02x}{grey:02x}{grey:02x}"/>'
        )
    tx, ty = layout.caption_xy
    for i, line in enumerate(layout.caption):
        lines.append(
            f'<text x="{_num(tx)}" y="{_num(ty + i * LINE_MM)}" font-family="Helvetica, Arial, sans-serif" '
            f'font-size="{_num(FONT_MM)}" fill="#000000">{escape(line)}</text>'
        )
    lines.append("</svg>")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- PDF


def _pdf_text(text: str) -> str:
    """A PDF literal string in WinAnsi (Latin-1 subset); other characters become '?'."""
    data = text.encode("latin-1", errors="replace").decode("latin-1")
    return "(" + data.replace("\\", "\\\\").replace("(", "\\(").replace(")", "\\)") + ")"


def marker_pdf(layout: MarkerLayout) -> bytes:
    """The marker page as a one-page PDF (MediaBox = the page in points; modules in module units).

    Written by hand: catalog, pages, page, content stream, Helvetica (a standard font, not embedded),
    with a cross-reference table of exact byte offsets. ViewerPreferences ask for no print scaling.
    """
    w_pt, h_pt = (v * _MM_TO_PT for v in layout.page_mm)
    k = _MM_TO_PT
    ops = ["1 1 1 rg", f"0 0 {_num(w_pt)} {_num(h_pt)} re f"]
    # Modules: module units, origin at the symbol's top-left, y down (negative d in the matrix).
    sx, sy = layout.symbol_mm
    pitch_pt = layout.pitch_mm * k
    ops += ["q", f"{pitch_pt!r} 0 0 {-pitch_pt!r} {_num(sx * k)} {_num(h_pt - sy * k)} cm", "0 0 0 rg"]
    ops += [f"{c} {r} {length} 1 re" for r, c, length in _module_runs(layout.modules)]
    ops += ["f", "Q"]
    for x, y, rw, rh, grey in _extra_rects(layout):
        g = _num(grey / 255.0)
        ops.append(
            f"{g} {g} {g} rg {_num(x * k)} {_num(h_pt - (y + rh) * k)} {_num(rw * k)} {_num(rh * k)} re f"
        )
    tx, ty = layout.caption_xy
    ops.append(f"0 0 0 rg BT /F1 {_num(FONT_MM * k)} Tf")
    for i, line in enumerate(layout.caption):
        ops.append(f"1 0 0 1 {_num(tx * k)} {_num(h_pt - (ty + i * LINE_MM) * k)} Tm {_pdf_text(line)} Tj")
    ops.append("ET")
    content = ("\n".join(ops) + "\n").encode("latin-1")
    objects = [
        b"<< /Type /Catalog /Pages 2 0 R /ViewerPreferences << /PrintScaling /None >> >>",
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
        (
            f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {_num(w_pt)} {_num(h_pt)}] "
            "/Resources << /Font << /F1 5 0 R >> >> /Contents 4 0 R >>"
        ).encode("ascii"),
        b"<< /Length " + str(len(content)).encode("ascii") + b" >>\nstream\n" + content + b"endstream",
        b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica /Encoding /WinAnsiEncoding >>",
        (f"<< /Title {_pdf_text(f'qrfield marker {layout.side_mm:g} mm')} /Producer (qrfield) >>").encode(
            "latin-1"
        ),
    ]
    out = bytearray(b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n")
    offsets = []
    for number, body in enumerate(objects, start=1):
        offsets.append(len(out))
        out += f"{number} 0 obj\n".encode("ascii") + body + b"\nendobj\n"
    xref = len(out)
    out += f"xref\n0 {len(objects) + 1}\n".encode("ascii") + b"0000000000 65535 f \n"
    out += b"".join(f"{offset:010d} 00000 n \n".encode("ascii") for offset in offsets)
    out += (
        f"trailer\n<< /Size {len(objects) + 1} /Root 1 0 R /Info 6 0 R >>\nstartxref\n{xref}\n%%EOF\n".encode(
            "ascii"
        )
    )
    return bytes(out)


# ---------------------------------------------------------------------- PNG


def _coverage(edges_px: np.ndarray, size: int) -> np.ndarray:
    """(size, len(edges) - 1) overlap of each pixel [p, p+1) with each interval [e_i, e_i+1), px."""
    p = np.arange(size, dtype=float)[:, None]
    lo, hi = edges_px[None, :-1], edges_px[None, 1:]
    return np.clip(np.minimum(p + 1.0, hi) - np.maximum(p, lo), 0.0, None)


def marker_image(layout: MarkerLayout, dpi: float = DEFAULT_DPI) -> np.ndarray:
    """(H, W) uint8 raster of the page at ``dpi``; each pixel is the exact area average of the page.

    Pixel p spans page mm [p, p+1) * 25.4 / dpi; so the symbol's corners fall at their exact
    sub-pixel places and the symbol spans L * dpi / 25.4 px. Caption text is drawn with OpenCV's
    Hershey font (close to, not exactly, the vector files' Helvetica).
    """
    if isinstance(dpi, bool) or not isinstance(dpi, (int, float)) or not math.isfinite(dpi):
        raise MarkerError(f"dpi must be a number, got {dpi!r}")
    if not DPI_RANGE[0] <= dpi <= DPI_RANGE[1]:
        raise MarkerError(f"dpi must be within {DPI_RANGE[0]}..{DPI_RANGE[1]}, got {dpi:g}")
    px_per_mm = dpi / 25.4
    if layout.pitch_mm * px_per_mm < MIN_PX_PER_MODULE:
        raise MarkerError(
            f"a {layout.pitch_mm:.3f} mm module is only {layout.pitch_mm * px_per_mm:.2f} px at {dpi:g} dpi; "
            f"raise --dpi to at least {math.ceil(MIN_PX_PER_MODULE / layout.pitch_mm * 25.4)}"
        )
    width, height = (math.ceil(v * px_per_mm - 1e-9) for v in layout.page_mm)
    if width * height > 400e6:
        raise MarkerError(f"a {width}x{height} px image is too large; lower --dpi")
    darkness = np.zeros((height, width), np.float64)  # 0 = white paper, 1 = black ink
    # Modules: separable exact coverage of the module grid (columns by rows).
    n = layout.n
    sx, sy = layout.symbol_mm
    cols = _coverage((sx + layout.pitch_mm * np.arange(n + 1)) * px_per_mm, width)
    rows = _coverage((sy + layout.pitch_mm * np.arange(n + 1)) * px_per_mm, height)
    darkness += rows @ layout.modules.astype(np.float64) @ cols.T
    for x, y, rw, rh, grey in _extra_rects(layout):
        cx = _coverage(np.array([x, x + rw]) * px_per_mm, width)[:, 0]
        cy = _coverage(np.array([y, y + rh]) * px_per_mm, height)[:, 0]
        darkness += np.outer(cy, cx) * (1.0 - grey / 255.0)
    image = np.clip(255.0 * (1.0 - darkness) + 0.5, 0, 255).astype(np.uint8)
    tx, ty = layout.caption_xy
    scale = FONT_MM * 0.72 * px_per_mm / 22.0  # Hershey simplex: cap height ~22 units at scale 1
    thickness = max(1, round(0.25 * px_per_mm))
    for i, line in enumerate(layout.caption):
        origin = (round(tx * px_per_mm), round((ty + i * LINE_MM) * px_per_mm))
        ascii_line = line.encode("ascii", errors="replace").decode("ascii")
        cv2.putText(image, ascii_line, origin, cv2.FONT_HERSHEY_SIMPLEX, scale, 0, thickness, cv2.LINE_AA)
    return image


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return (
        struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    )


def png_with_dpi(png: bytes, dpi: float) -> bytes:
    """Insert a pHYs chunk (pixels per metre, rounded to whole numbers as PNG requires) after IHDR."""
    if png[:8] != b"\x89PNG\r\n\x1a\n" or png[12:16] != b"IHDR":
        raise ValueError("not a PNG stream starting with IHDR")
    ppm = round(dpi / 0.0254)
    ihdr_end = 8 + 4 + 4 + 13 + 4
    return png[:ihdr_end] + _png_chunk(b"pHYs", struct.pack(">IIB", ppm, ppm, 1)) + png[ihdr_end:]


def marker_png(layout: MarkerLayout, dpi: float = DEFAULT_DPI) -> bytes:
    """The page as PNG bytes at ``dpi``, the resolution recorded in its pHYs chunk."""
    ok, data = cv2.imencode(".png", marker_image(layout, dpi))
    if not ok:
        raise MarkerError("OpenCV could not encode the PNG")
    return png_with_dpi(data.tobytes(), dpi)


# ---------------------------------------------------------------------- files


def write_marker(
    path: str | Path, text: str, side_mm: float, *, dpi: float = DEFAULT_DPI, force: bool = False
) -> MarkerLayout:
    """Write the marker to ``path`` (.svg, .pdf or .png by its extension); returns the layout.

    Raises:
        MarkerError: empty text, side <= 0, unknown extension, bad dpi.
        FileExistsError: ``path`` exists and ``force`` is False.
        OSError: the folder is missing or not writable.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise MarkerError(
            f"unknown marker format {path.suffix or '(no extension)'!r} in {path}: use .svg, .pdf or .png"
        )
    layout = marker_layout(text, side_mm)
    if suffix == ".svg":
        data = marker_svg(layout).encode("utf-8")
    elif suffix == ".pdf":
        data = marker_pdf(layout)
    else:
        data = marker_png(layout, dpi)
    from qrfield.files import atomic_write, check_target

    check_target(path)
    try:
        atomic_write(path, data, overwrite=force)
    except FileExistsError:
        raise FileExistsError(f"{path} exists; choose another name or add --force to overwrite it") from None
    except PermissionError:
        raise PermissionError(f"cannot write {path}: permission denied") from None
    return layout
