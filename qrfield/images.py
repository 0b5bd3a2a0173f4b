"""Image files: which paths are images, their size read from the header, and a decode that refuses
an image above the pixel limit *before* decoding it.

A 0.8 MB PNG can hold 32000 x 24000 pixels, which OpenCV would decode into 2.3 GB (and a Raspberry
Pi would be killed). So the width and height are read from the file's header first: PNG (IHDR),
JPEG (the SOF segment, after any EXIF), BMP, GIF, WebP (VP8, VP8L, VP8X), TIFF (classic and
BigTIFF) and PNM/PAM. An image above :class:`ImageSettings` ``max_megapixels`` (default
:data:`qrfield.limits.DEFAULT_MAX_MEGAPIXELS`) is refused with its size; a file whose size cannot
be read from its header (another format, or a damaged header) is refused too, since only
decoding it would tell its size.

Paths: :func:`expand_image_paths` takes files, folders (their image files, sorted by name) and
glob patterns (``shots/*.png``, ``**`` for subfolders), each relative to the current folder.
"""

from __future__ import annotations

import glob
import os
import re
import struct
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from qrfield.limits import DEFAULT_MAX_MEGAPIXELS
from qrfield.settings import setting
from qrfield.texts import check_path_for_library

#: File name endings taken as images when a folder is given.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm", ".pbm", ".pnm")
#: Formats whose header :func:`probe_size` reads (for messages).
PROBED_FORMATS = "PNG, JPEG, BMP, GIF, WebP, TIFF, PNM"
#: Bytes read from the start of a file to find its size (JPEG segments are followed by seeking).
_HEAD_BYTES = 4096
_GLOB_CHARS = ("*", "?", "[")


@dataclass(frozen=True)
class ImageSettings:
    """Limits on the image files qrfield decodes."""

    max_megapixels: float = setting(
        DEFAULT_MAX_MEGAPIXELS,
        label="image pixel limit",
        unit="MP",
        minimum=0.01,
        maximum=1000.0,
        decimals=1,
        help="larger images are refused before they are decoded (a 50 MP colour image takes 150 MB)",
    )


class ImageError(ValueError):
    """An image file that is refused or cannot be read; the message names the file and why."""


def is_glob(text: str) -> bool:
    """True when ``text`` contains a glob character (``*``, ``?``, ``[``)."""
    return any(ch in text for ch in _GLOB_CHARS)


def expand_image_paths(items: list[str]) -> list[str]:
    """The image paths given: files as they are, each folder replaced by its image files (sorted by
    name), each glob pattern by the files it matches (sorted). A path that exists is never taken for
    a pattern; a pattern that matches nothing, or a folder without images, stays in the list as it is,
    so that the reader reports it (:func:`read_image` says "no file matches" / "no images")."""
    paths: list[str] = []
    for item in items:
        path = Path(item)
        if path.is_dir():
            found = sorted(
                str(p) for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()
            )
            paths.extend(found or [item])
        elif not os.path.lexists(item) and is_glob(item):
            matches = sorted(m for m in glob.glob(item, recursive=True) if os.path.isfile(m))
            paths.extend(matches or [item])
        else:
            paths.append(item)
    return paths


def probe_size(path: str | os.PathLike[str]) -> tuple[int, int] | None:
    """(width, height) from the file's header, or None when the format is not one of
    :data:`PROBED_FORMATS` or the header is damaged. Reads a few KB, never the pixels."""
    with open(path, "rb") as handle:
        head = handle.read(_HEAD_BYTES)
        try:
            if head.startswith(b"\xff\xd8"):
                return _jpeg_size(handle)
            if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
                return _tiff_size(handle, head)
        except (struct.error, ValueError, OverflowError):
            return None
    return _header_size(head)


def _is_png(path: Path) -> bool:
    with open(path, "rb") as handle:
        return handle.read(8) == b"\x89PNG\r\n\x1a\n"


def _header_size(head: bytes) -> tuple[int, int] | None:
    try:
        if head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR":
            return struct.unpack(">II", head[16:24])
        if head.startswith(b"BM") and len(head) >= 26:
            header_size = struct.unpack("<I", head[14:18])[0]
            if header_size == 12:  # OS/2 BITMAPCOREHEADER
                return struct.unpack("<HH", head[18:22])
            width, height = struct.unpack("<ii", head[18:26])
            return abs(width), abs(height)  # height < 0: rows stored top-down
        if head[:6] in (b"GIF87a", b"GIF89a"):
            return struct.unpack("<HH", head[6:10])
        if head.startswith(b"RIFF") and head[8:12] == b"WEBP":
            return _webp_size(head)
        if head[:1] == b"P" and head[1:2] in b"1234567":
            return _pnm_size(head)
    except (struct.error, IndexError, KeyError, ValueError):
        return None
    return None


def _jpeg_size(handle: Any) -> tuple[int, int] | None:
    """Walk the JPEG's segments (seeking over EXIF and other APPn data) to its SOF marker."""
    handle.seek(2)
    for _ in range(10_000):  # a damaged file must not loop forever
        byte = handle.read(1)
        while byte == b"\xff":  # fill bytes before a marker
            marker = handle.read(1)
            if marker != b"\xff":
                break
        else:
            return None
        if not marker:
            return None
        code = marker[0]
        if code in (0x01, *range(0xD0, 0xD8)):  # markers without a length
            continue
        if code in (0xD9, 0xDA):  # end of image, start of scan: no SOF before them
            return None
        length_bytes = handle.read(2)
        if len(length_bytes) != 2:
            return None
        length = struct.unpack(">H", length_bytes)[0]
        if length < 2:
            return None
        if code in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
            data = handle.read(5)
            if len(data) != 5:
                return None
            height, width = struct.unpack(">HH", data[1:5])
            return width, height
        handle.seek(length - 2, os.SEEK_CUR)
    return None


def _webp_size(head: bytes) -> tuple[int, int] | None:
    chunk = head[12:16]
    if chunk == b"VP8 ":  # lossy: the key frame's start code, then 14-bit width and height
        if head[23:26] != b"\x9d\x01\x2a":
            return None
        width, height = struct.unpack("<HH", head[26:30])
        return width & 0x3FFF, height & 0x3FFF
    if chunk == b"VP8L":  # lossless: signature 0x2f, then 14 bits each of width-1 and height-1
        if head[20] != 0x2F:
            return None
        bits = struct.unpack("<I", head[21:25])[0]
        return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    if chunk == b"VP8X":  # extended: 24-bit canvas width-1 and height-1
        width = int.from_bytes(head[24:27], "little") + 1
        height = int.from_bytes(head[27:30], "little") + 1
        return width, height
    return None


def _tiff_size(handle: Any, head: bytes) -> tuple[int, int] | None:
    """ImageWidth (256) and ImageLength (257) of the first IFD, which libtiff (hence OpenCV) often
    writes after the pixels: found by seeking, not by reading the file."""
    order = "<" if head[:2] == b"II" else ">"
    big = head[2:4] in (b"+\x00", b"\x00+")

    def at(offset: int, size: int) -> bytes:
        handle.seek(offset)
        return handle.read(size)

    if big:
        offset = struct.unpack(order + "Q", head[8:16])[0]
        count = struct.unpack(order + "Q", at(offset, 8))[0]
        entry_size, start, value_at = 20, offset + 8, 12
    else:
        offset = struct.unpack(order + "I", head[4:8])[0]
        count = struct.unpack(order + "H", at(offset, 2))[0]
        entry_size, start, value_at = 12, offset + 2, 8
    table = at(start, entry_size * min(count, 500))
    sizes: dict[int, int] = {}
    for k in range(len(table) // entry_size):
        entry = table[k * entry_size : (k + 1) * entry_size]
        tag, kind = struct.unpack(order + "HH", entry[:4])
        if tag in (256, 257):
            if kind == 3:  # SHORT
                sizes[tag] = struct.unpack(order + "H", entry[value_at : value_at + 2])[0]
            elif kind == 4:  # LONG
                sizes[tag] = struct.unpack(order + "I", entry[value_at : value_at + 4])[0]
            elif kind == 16:  # LONG8 (BigTIFF)
                sizes[tag] = struct.unpack(order + "Q", entry[value_at : value_at + 8])[0]
    if 256 in sizes and 257 in sizes:
        return sizes[256], sizes[257]
    return None


def _pnm_size(head: bytes) -> tuple[int, int] | None:
    if head[1:2] == b"7":  # PAM: WIDTH and HEIGHT header lines
        fields = {}
        for line in head.split(b"\n")[1:]:
            words = line.split()
            if words and words[0] == b"ENDHDR":
                break
            if len(words) >= 2:
                fields[words[0]] = words[1]
        return int(fields[b"WIDTH"]), int(fields[b"HEIGHT"])
    tokens: list[bytes] = []
    for line in head[2:].split(b"\n"):
        tokens += line.split(b"#", 1)[0].split()
        if len(tokens) >= 2:
            return int(tokens[0]), int(tokens[1])
    return None


#: Channels per PNG colour type (grey, RGB, palette, grey + alpha, RGBA).
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
#: Adam7 interlacing: (x0, y0, dx, dy) of each of the seven passes.
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))
#: Bytes of compressed PNG data inflated at a time by :func:`check_png_data`.
_INFLATE_STEP = 1 << 22


def png_data_size(width: int, height: int, depth: int, colour: int, interlace: int) -> int:
    """Bytes the PNG's image data inflates to (filter bytes included), from its IHDR fields."""
    bits = _PNG_CHANNELS[colour] * depth

    def rows(w: int, h: int) -> int:
        return h * (1 + (w * bits + 7) // 8) if w > 0 and h > 0 else 0

    if not interlace:
        return rows(width, height)
    return sum(rows((width - x0 + dx - 1) // dx, (height - y0 + dy - 1) // dy) for x0, y0, dx, dy in _ADAM7)


def check_png_data(path: str | os.PathLike[str], where: str) -> None:
    """ImageError when a PNG's data is not what its header's pixels need: more (a crafted stream),
    less, damaged compressed data, or a chunk that fails its CRC.

    The pixel limit bounds what the header declares, not what its IDAT chunks inflate to: a 50 MP
    PNG whose stream goes on to 900 MB of zeros kept libpng inflating for 23 s (and it warns "Too
    much image data" on stderr). So the stream is inflated here first, a few MB at a time and
    discarded, and stopped one byte beyond what the header allows: the CPU spent is at most that
    of decoding a legitimate image of that size. Chunks are read by their headers, the data
    never held whole. A damaged PNG is refused here too, in one line: libpng would print its own
    "libpng error: Not enough image data" or "IDAT: CRC error" on stderr (OpenCV keeps libpng's
    default handlers) before OpenCV gives up on it.
    """
    import zlib

    def damaged(why: str) -> ImageError:
        return ImageError(f"{where}: cannot read image: {why} (a damaged or truncated PNG)")

    with open(path, "rb") as handle:
        head = handle.read(33)
        if len(head) < 33 or head[12:16] != b"IHDR":
            return  # not a PNG with a header where it belongs: OpenCV says it cannot decode it
        width, height, depth, colour, _method, _filter, interlace = struct.unpack(">IIBBBBB", head[16:29])
        if colour not in _PNG_CHANNELS or depth not in (1, 2, 4, 8, 16):
            return  # a damaged header: OpenCV says it cannot decode it
        if head[8:12] != b"\x00\x00\x00\x0d":  # an IHDR is 13 bytes long
            raise damaged(
                f"its IHDR chunk says it is {struct.unpack('>I', head[8:12])[0]} bytes long, not 13"
            )
        if struct.unpack(">I", head[29:33])[0] != zlib.crc32(head[12:29]):
            raise damaged("its IHDR chunk fails its CRC")
        allowed = png_data_size(width, height, depth, colour, interlace)
        inflater = zlib.decompressobj()
        produced = 0
        while True:
            header = handle.read(8)
            if len(header) < 8:
                if produced < allowed:  # libpng: "Not enough image data"
                    raise damaged(
                        f"it ends after {produced} of the {allowed} bytes its {width}x{height} pixels need"
                    )
                return  # all the pixels, no IEND: OpenCV decodes it
            length, kind = struct.unpack(">I4s", header)
            crc = zlib.crc32(kind)
            left = length
            while left > 0:
                data = handle.read(min(left, _INFLATE_STEP))
                if not data:
                    raise damaged(f"it ends inside its {kind.decode('latin-1')!r} chunk")
                left -= len(data)
                crc = zlib.crc32(data, crc)
                if kind != b"IDAT":
                    continue
                try:
                    while data:
                        produced += len(inflater.decompress(data, _INFLATE_STEP))
                        data = inflater.unconsumed_tail
                        if produced > allowed:
                            raise ImageError(
                                f"{where}: cannot read image: its compressed data inflates to more "
                                f"than the {allowed} bytes its {width}x{height} pixels need (a damaged "
                                "or crafted PNG); refused before decoding"
                            )
                except zlib.error:
                    raise damaged("its compressed data is damaged") from None
            stored = handle.read(4)
            if len(stored) < 4:
                raise damaged(f"it ends inside its {kind.decode('latin-1')!r} chunk")
            if struct.unpack(">I", stored)[0] != crc:
                raise damaged(f"its {kind.decode('latin-1')!r} chunk fails its CRC")
            if kind == b"IEND":
                break
        if produced < allowed:
            raise damaged(
                f"its data inflates to {produced} of the {allowed} bytes its {width}x{height} pixels need"
            )


def check_pixels(width: int, height: int, settings: ImageSettings, where: str) -> None:
    """ImageError naming ``where`` when width x height is above ``settings.max_megapixels``."""
    megapixels = width * height / 1e6
    if megapixels > settings.max_megapixels:
        raise ImageError(
            f"{where}: {width}x{height} is {megapixels:.1f} MP, above the limit of "
            f"{settings.max_megapixels:g} MP; refused before decoding (--max-megapixels raises the limit)"
        )


@contextmanager
def opencv_quiet() -> Iterator[None]:
    """OpenCV's own log lines (``[ WARN:0@1.2] global grfmt_png.cpp ...``, ``[ERROR:0@3.3] ...
    IHDR chunk shall be first``) held back while inside: the caller reports the failure once, in
    words. Its errors still raise ``cv2.error``."""
    import cv2

    logging = getattr(getattr(cv2, "utils", None), "logging", None)
    if logging is None:
        yield
        return
    level = logging.getLogLevel()
    logging.setLogLevel(logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        logging.setLogLevel(level)


#: One decode at a time holds the process's stderr (file descriptor 2): see :func:`_decoder_output`.
_STDERR_LOCK = threading.Lock()

#: What libjpeg (jerror.h's messages that a decode may emit and go on) and libpng print on stderr
#: themselves. Only such a line makes an image damaged; any other line written in the decode's
#: window (another thread's) is written back to stderr, so it is neither lost nor taken for the
#: decoder's.
DECODER_LINE = re.compile(
    r"^(Corrupt JPEG data|Premature end of JPEG file|Invalid (JPEG|SOS)|Bogus|Huffman|"
    r"Inconsistent progression|Warning: thumbnail|JPEG datastream|Not a JPEG file|Unsupported JPEG|"
    r"libpng (warning|error)|libjpeg)"
)


@contextmanager
def _decoder_output() -> Iterator[list[str]]:
    """The lines a C decoder writes on stderr while inside, taken off it (libjpeg prints "Corrupt
    JPEG data: 303 extraneous bytes before marker 0xd9" there itself and decodes on, pixels
    damaged). File descriptor 2 is pointed at a temporary file for the decode (milliseconds), one
    decode at a time; where stderr cannot be redirected the decode runs as it is."""
    lines: list[str] = []
    with _STDERR_LOCK, tempfile.TemporaryFile() as sink:
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError, AttributeError):
            yield lines
            return
        os.dup2(sink.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            for line in sink.read().decode("utf-8", "replace").splitlines():
                if DECODER_LINE.match(line):
                    lines.append(line)
                elif line.strip():  # another thread's words in that window: back where they belong
                    try:
                        sys.stderr.write(line + "\n")
                        sys.stderr.flush()
                    except (OSError, ValueError, AttributeError):
                        pass


def read_image(
    path: str | os.PathLike[str], settings: ImageSettings | None = None, *, mode: str = "color"
) -> Any:
    """The image as a uint8 array, ``mode`` "color" (BGR), "grey", or "any" (grey files stay grey);
    ImageError with the reason, never a traceback.

    The size is read from the header and checked against the pixel limit before anything is decoded;
    the file is read whole only then.
    """
    import cv2
    import numpy as np

    settings = settings or ImageSettings()
    text = os.fspath(path)
    file = Path(text)
    if not os.path.lexists(text):
        if is_glob(text):
            raise ImageError(f"{text}: no file matches this pattern")
        raise ImageError(f"{text}: cannot read image: no such file")
    if file.is_dir():
        raise ImageError(
            f"{text}: cannot read image: a folder without image files ({', '.join(IMAGE_SUFFIXES)})"
        )
    if not file.is_file():
        raise ImageError(f"{text}: cannot read image: not a regular file")
    try:
        if file.stat().st_size == 0:  # a copy that failed, a file just created: not a wrong format
            raise ImageError(f"{text}: cannot read image: the file is empty (0 bytes)")
        size = probe_size(file)
    except OSError as exc:
        raise ImageError(f"{text}: cannot read image: {exc.strerror or exc}") from None
    if size is None:
        raise ImageError(
            f"{text}: cannot read image: not an image format whose size qrfield can read before "
            f"decoding ({PROBED_FORMATS})"
        )
    width, height = size
    if width <= 0 or height <= 0:
        raise ImageError(f"{text}: cannot read image: its header says {width}x{height} pixels")
    check_pixels(width, height, settings, text)
    # The whole file is read only after these checks; it cannot be much larger than its pixels
    # uncompressed.
    limit = int(settings.max_megapixels * 1e6 * 4) + (16 << 20)
    try:
        if file.stat().st_size > limit:
            raise ImageError(
                f"{text}: cannot read image: {file.stat().st_size} bytes is too large "
                f"for {width}x{height} pixels"
            )
        if _is_png(file):
            check_png_data(file, text)  # the pixel limit caps the CPU too
        data = np.fromfile(file, dtype=np.uint8)  # also copes with non-ASCII paths
    except OSError as exc:
        raise ImageError(f"{text}: cannot read image: {exc.strerror or exc}") from None
    flags = {"color": cv2.IMREAD_COLOR, "grey": cv2.IMREAD_GRAYSCALE, "any": cv2.IMREAD_ANYCOLOR}[mode]
    try:
        with opencv_quiet(), _decoder_output() as said:  # the errors below say it, once
            image = cv2.imdecode(data, flags) if data.size else None
    except cv2.error as exc:
        raise ImageError(
            f"{text}: cannot read image: OpenCV cannot decode it ({(exc.err or str(exc)).strip()})"
        ) from None
    if said:  # a decoder that complains has decoded damaged data: its pixels are not the photo's
        raise ImageError(f"{text}: cannot read image: the decoder says {said[0].strip()!r} (a damaged file)")
    if image is None:
        raise ImageError(
            f"{text}: cannot read image: OpenCV cannot decode it (damaged, or a format OpenCV cannot decode)"
        )
    if image.shape[1] != width or image.shape[0] != height:  # the header lied: trust the pixels
        check_pixels(image.shape[1], image.shape[0], settings, text)
    return image


def write_image(path: str | os.PathLike[str], image: Any, *, overwrite: bool = True) -> Path:
    """Encode ``image`` by the file's extension (.png, .jpg, ...) and write it all or nothing
    (:func:`qrfield.files.atomic_write`); OSError saying why not. Returns the path."""
    import cv2

    from qrfield.files import atomic_write, check_target

    target = check_target(path)
    suffix = target.suffix.lower()
    if not suffix:
        raise OSError(f"cannot write {target}: no file extension to tell the image format (.png, .jpg, ...)")
    check_path_for_library(suffix, f"cannot write {target}: its extension")
    try:
        ok, encoded = cv2.imencode(suffix, image)
    except cv2.error as exc:
        raise OSError(f"cannot write {target}: {(exc.err or str(exc)).strip()}") from None
    if not ok:
        raise OSError(f"cannot write {target}: OpenCV cannot encode {suffix} images")
    return atomic_write(target, encoded.tobytes(), overwrite=overwrite)
