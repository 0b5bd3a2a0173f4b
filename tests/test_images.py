"""Image files: sizes from headers (truth: OpenCV's own decode), the pixel limit before decoding,
files/folders/globs, and ``qrfield solve`` over many images in one process."""

from __future__ import annotations

import json
import os
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from qrfield.cli import main
from qrfield.images import ImageError, ImageSettings, expand_image_paths, probe_size, read_image

FORMATS = [".png", ".jpg", ".bmp", ".tif", ".webp", ".pgm", ".ppm", ".pbm"]


@pytest.mark.parametrize("suffix", FORMATS)
@pytest.mark.parametrize("size", [(33, 17), (640, 480), (1001, 3)])
def test_header_size_matches_what_opencv_decodes(tmp_path, suffix, size):
    w, h = size
    rng = np.random.default_rng(w * h)
    image = rng.integers(0, 255, (h, w, 3) if suffix == ".ppm" else (h, w), dtype=np.uint8)
    path = tmp_path / f"x{suffix}"
    assert cv2.imwrite(str(path), image)
    decoded = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert probe_size(path) == (decoded.shape[1], decoded.shape[0]) == (w, h)


@pytest.mark.slow
def test_header_sizes_of_the_real_photos(shared_data):
    photos = sorted((shared_data / "qr-photos").rglob("*.[jp][pn]g"))
    assert len(photos) >= 70
    for photo in photos:  # JPEGs with EXIF before their SOF marker among them
        decoded = cv2.imread(str(photo), cv2.IMREAD_UNCHANGED)
        assert probe_size(photo) == (decoded.shape[1], decoded.shape[0]), photo


def big_png(path: Path, width: int, height: int) -> Path:
    """A valid grey PNG of width x height black pixels, compressed row by row (a few hundred KB)."""
    compressor = zlib.compressobj(9)
    row = b"\x00" * (width + 1)  # filter byte + pixels
    chunks = [compressor.compress(row) for _ in range(height)]
    data = b"".join(chunks) + compressor.flush()

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b""))
    return path


@pytest.mark.slow
def test_an_image_above_the_pixel_limit_is_refused_before_decoding(tmp_path, monkeypatch):
    # The 0.8 MB PNG of 32000 x 24000 took 4.5 GB to decode; its size is in its header.
    # (Time and memory: `qrfield benchmark images`.) Smaller here: the rule is the same.
    path = big_png(tmp_path / "big.png", 12000, 8000)
    assert probe_size(path) == (12000, 8000) and path.stat().st_size < 1_000_000

    def never(*args, **kwargs):
        raise AssertionError("decoded although above the limit")

    monkeypatch.setattr(cv2, "imdecode", never)
    with pytest.raises(ImageError, match=r"12000x8000 is 96.0 MP, above the limit of 50 MP; refused before"):
        read_image(path)
    # The limit is a setting: raised, the same file is decoded.
    monkeypatch.undo()
    image = read_image(path, ImageSettings(max_megapixels=100), mode="grey")
    assert image.shape == (8000, 12000)


@pytest.mark.slow
def test_solve_reports_a_refused_image_and_goes_on(tmp_path, capsys):
    big = big_png(tmp_path / "big.png", 9000, 6000)
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((48, 64), 255, np.uint8))
    assert main(["solve", str(big), str(small), "--focal-px", "500", "--side-mm", "50", "--json"]) == 1
    entries = json.loads(capsys.readouterr().out)
    assert [e["image"] for e in entries] == [str(big), str(small)]
    assert "54.0 MP, above the limit of 50 MP" in entries[0]["status"]
    assert entries[1]["status"] == "no QR code found"
    assert main(["solve", str(big), "--focal-px", "500", "--side-mm", "50", "--max-megapixels", "60"]) == 1
    assert "no QR code found" in capsys.readouterr().out  # decoded (54 MP < 60)


def test_unknown_formats_and_damaged_headers_are_refused_with_a_reason(tmp_path):
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image at all")
    with pytest.raises(ImageError, match="cannot read image: not an image format whose size"):
        read_image(junk)
    lying = tmp_path / "lying.png"  # a PNG header saying 10x10, then garbage
    lying.write_bytes(
        b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + struct.pack(">II", 10, 10) + b"x" * 20
    )
    with pytest.raises(ImageError, match="cannot read image: OpenCV cannot decode it"):
        read_image(lying)


def test_an_empty_file_is_said_to_be_empty(tmp_path, capsys):
    """A 0-byte file (a copy that failed) is empty, not of an unknown format (audit-2)."""
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    with pytest.raises(ImageError, match=r"cannot read image: the file is empty \(0 bytes\)"):
        read_image(empty)
    assert main(["solve", str(empty), "--focal-px", "500", "--side-mm", "50", "--json"]) == 1
    (entry,) = json.loads(capsys.readouterr().out)
    assert entry["status"] == "cannot read image: the file is empty (0 bytes)"


def test_files_folders_and_globs_in_order(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "shots").mkdir()
    (tmp_path / "shots" / "sub").mkdir()
    for name in ("b.png", "a.jpg", "notes.txt", "sub/c.png"):
        (tmp_path / "shots" / name).write_bytes(b"")
    (tmp_path / "empty").mkdir()
    assert expand_image_paths(["shots"]) == ["shots/a.jpg", "shots/b.png"]  # not the .txt, not sub/
    assert expand_image_paths(["shots/*.png", "shots/**/*.png"]) == [
        "shots/b.png",
        "shots/b.png",
        "shots/sub/c.png",
    ]
    assert expand_image_paths(["none/*.png", "empty", "missing.png"]) == [
        "none/*.png",
        "empty",
        "missing.png",
    ]
    with pytest.raises(ImageError, match="no file matches this pattern"):
        read_image("none/*.png")
    with pytest.raises(ImageError, match="a folder without image files"):
        read_image("empty")


@pytest.mark.slow
def test_solve_folder_focal_only_each_image_at_its_own_size(tmp_path, capsys):
    # Must show: `solve FOLDER --focal-px 500 --side-mm 50 --json` over images of mixed sizes gives
    # one entry per image; each solved with f = 500 px at its own size (truth: the rendered pose).
    from qrfield.camera import CameraModel
    from qrfield.geometry import Pose
    from qrfield.render import render_view

    folder = tmp_path / "views"
    folder.mkdir()
    truths = {}
    for i, (w, h) in enumerate([(640, 480), (800, 600), (480, 640), (1024, 576)]):
        pose = Pose([5.0 * i, -3.0, 280.0 + 20 * i], [10.0, -12.0, 5.0 * i])
        view = render_view(CameraModel.from_focal(500.0, w, h), 50.0, pose, text=f"code-{i}")
        path = folder / f"view{i}.png"
        cv2.imwrite(str(path), view.image)
        truths[str(path)] = pose
    argv = ["solve", str(folder), "--focal-px", "500", "--side-mm", "50", "--method", "ippe", "--json"]
    assert main(argv) == 0
    entries = json.loads(capsys.readouterr().out)
    assert sorted(e["image"] for e in entries) == sorted(truths)
    for entry in entries:
        truth = truths[entry["image"]]
        assert entry["status"] == "ok"
        assert np.linalg.norm(np.array(entry["position_mm"]) - truth.position_mm) < 3.0


def test_focal_only_without_images_still_needs_a_size(capsys):
    assert main(["solve", "--corners", "1,2 3,4 5,6 7,8", "--focal-px", "500", "--side-mm", "50"]) == 2
    assert "--focal-px and --size go together" in capsys.readouterr().err


def _png(path: Path, header: bytes, stream: bytes, idat_pieces: int = 1) -> Path:
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    step = -(-len(stream) // idat_pieces)
    idats = b"".join(chunk(b"IDAT", stream[i : i + step]) for i in range(0, len(stream), step))
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"tEXt", b"a\x00b")
        + idats
        + chunk(b"IEND", b"")
    )
    return path


def _idat_size(path: Path) -> int:
    """Bytes the IDAT chunks of a PNG inflate to (the independent truth: zlib on their data)."""
    data, at, stream = path.read_bytes(), 8, b""
    while at < len(data):
        length, kind = struct.unpack(">I4s", data[at : at + 8])
        if kind == b"IDAT":
            stream += data[at + 8 : at + 8 + length]
        at += 12 + length
    return len(zlib.decompress(stream))


@pytest.mark.parametrize(
    ("shape", "dtype"),
    [((37, 19), np.uint8), ((37, 19, 3), np.uint8), ((37, 19, 4), np.uint8), ((5, 3), np.uint16)],
)
def test_png_data_size_is_what_opencvs_encoder_writes(tmp_path, shape, dtype):
    from qrfield.images import png_data_size

    path = tmp_path / "x.png"
    assert cv2.imwrite(str(path), np.arange(np.prod(shape), dtype=dtype).reshape(shape))
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", path.read_bytes()[16:29])
    assert png_data_size(width, height, depth, colour, interlace) == _idat_size(path)


def test_png_data_size_of_an_interlaced_image_by_hand():
    from qrfield.images import png_data_size

    # Adam7 on 3x3 grey: passes 1, 4, 5, 6, 7 hold 1, 1, 2, 1+1, 3 pixels in 1, 1, 1, 2, 1 rows:
    # 9 pixel bytes + 6 filter bytes.
    assert png_data_size(3, 3, 8, 0, 1) == 15
    assert png_data_size(3, 3, 8, 0, 0) == 3 * (1 + 3)
    assert png_data_size(10, 1, 1, 0, 0) == 1 + 2  # 10 one-bit pixels fill two bytes


@pytest.mark.slow
def test_a_png_whose_data_inflates_beyond_its_pixels_is_refused_before_decoding(tmp_path, monkeypatch):
    """Issue 23: a 50 MP PNG whose stream went on to 900 MB cost 23 s of libpng's CPU (and printed
    "libpng warning: IDAT: Too much image data"). Its pixels are within the limit; its data is
    not. Here 100 x 100 grey pixels (10,100 bytes with filter bytes) and 50 MB of zeros more."""
    width = height = 100
    compressor = zlib.compressobj(9)
    stream = compressor.compress(b"\x00" * (height * (width + 1)))
    stream += b"".join(compressor.compress(b"\x00" * (1 << 20)) for _ in range(50)) + compressor.flush()
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    bomb = _png(tmp_path / "bomb.png", header, stream, idat_pieces=3)
    assert bomb.stat().st_size < 100_000
    fine = _png(tmp_path / "fine.png", header, zlib.compress(b"\x00" * (height * (width + 1))), idat_pieces=2)
    assert read_image(fine, mode="grey").shape == (height, width)
    monkeypatch.setattr(cv2, "imdecode", lambda *a: pytest.fail("decoded the bomb"))
    with pytest.raises(ImageError, match=r"inflates to more than the 10100 bytes its 100x100 pixels need"):
        read_image(bomb)


def _noise_png(path: Path, seed: int = 0) -> tuple[Path, np.ndarray]:
    """A 64 x 48 grey PNG of seeded noise written by OpenCV (its deflate stream does not compress
    away, so a cut anywhere lands in the pixel data)."""
    image = np.random.default_rng(seed).integers(0, 256, (48, 64), dtype=np.uint8)
    assert cv2.imwrite(str(path), image)
    return path, image


def _chunks(data: bytes) -> list[tuple[int, bytes]]:
    """(offset, kind) of each chunk of a PNG, by its length fields (the independent reading)."""
    found, at = [], 8
    while at + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[at : at + 8])
        found.append((at, kind))
        at += 12 + length
    return found


def _idat(stream: bytes) -> bytes:
    """An IDAT chunk of ``stream`` with its right CRC."""
    return struct.pack(">I", len(stream)) + b"IDAT" + stream + struct.pack(">I", zlib.crc32(b"IDAT" + stream))


@pytest.mark.parametrize("damage", ["cut in IDAT", "short data", "IDAT CRC", "bad deflate"])
def test_a_damaged_png_is_refused_in_one_line_with_nothing_from_libpng(tmp_path, capfd, damage):
    """Issue 23: a damaged PNG made libpng print "libpng error: Not enough image data" (or "IDAT:
    CRC error") and OpenCV "[ WARN:0@1.2] global grfmt_png.cpp ... incomplete" on stderr, then the
    message said only "OpenCV cannot decode it". It is refused with its cause and stderr stays
    empty (capfd reads the file descriptor, where the C libraries write)."""
    path, _ = _noise_png(tmp_path / "good.png")
    data = path.read_bytes()
    (idat_at, _kind) = next(c for c in _chunks(data) if c[1] == b"IDAT")
    length = struct.unpack(">I", data[idat_at : idat_at + 4])[0]
    body = data[idat_at + 8 : idat_at + 8 + length]
    if damage == "cut in IDAT":
        broken, why = data[: idat_at + 8 + length // 2], "ends inside its 'IDAT' chunk"
    elif damage == "short data":  # a whole, valid zlib stream of fewer rows than the header says
        stream = zlib.compress(zlib.decompress(body)[: 20 * 65])
        broken, why = data[:idat_at] + _idat(stream) + data[idat_at + 12 + length :], "1300 of the 3120 bytes"
    elif damage == "IDAT CRC":
        at = idat_at + 8 + length  # its CRC
        broken, why = data[:at] + bytes([data[at] ^ 1]) + data[at + 1 :], "'IDAT' chunk fails its CRC"
    else:  # the deflate stream's bytes changed and the CRC made to match: only zlib sees it
        stream = body[:2] + bytes([0xFF] * 8) + body[10:]
        broken, why = data[:idat_at] + _idat(stream) + data[idat_at + 12 + length :], "damaged"
    bad = tmp_path / "bad.png"
    bad.write_bytes(broken)
    capfd.readouterr()
    with pytest.raises(ImageError, match="damaged or truncated PNG") as caught:
        read_image(bad, mode="grey")
    assert why in str(caught.value) and "\n" not in str(caught.value)
    assert capfd.readouterr().err == ""


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.floats(0.0, 1.0), flip=st.integers(0, 10_000), bit=st.integers(0, 7))
@example(cut=1.0, flip=8, bit=0)  # IHDR's length field: OpenCV logged "[ERROR] IHDR chunk shall be first"
def test_any_cut_or_flipped_bit_of_a_png_decodes_right_or_is_refused_silently(
    tmp_path, capfd, cut, flip, bit
):
    """A PNG cut anywhere, or with any one bit changed, is either decoded to its own pixels or
    refused with an ImageError; nothing is printed by libpng or OpenCV."""
    path, image = _noise_png(tmp_path / "good.png", seed=flip % 7)
    data = bytearray(path.read_bytes())
    data[flip % len(data)] ^= 1 << bit
    data = bytes(data[: max(1, round(cut * len(data)))])
    bad = tmp_path / "bad.png"
    bad.write_bytes(data)
    capfd.readouterr()
    try:
        decoded = read_image(bad, mode="grey")
    except ImageError as exc:
        assert "\n" not in str(exc)
    else:
        assert np.array_equal(decoded, image)
    assert capfd.readouterr().err == ""


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    suffix=st.sampled_from([".jpg", ".bmp", ".webp", ".tif"]),
    cut=st.floats(0.0, 1.0),
    flip=st.integers(0, 10_000),
    bit=st.integers(0, 7),
)
@example(suffix=".jpg", cut=1.0, flip=419, bit=3)  # libjpeg: "Corrupt JPEG data: ... extraneous bytes"
def test_any_damaged_image_of_another_format_is_read_or_refused_with_nothing_on_stderr(
    tmp_path, capfd, suffix, cut, flip, bit
):
    """Issue 23 (audit): libjpeg printed "Corrupt JPEG data: 303 extraneous bytes before marker
    0xd9" on stderr itself and decoded on (36 of 150 damaged JPEGs); such an image is refused
    with the decoder's words as the reason, and nothing reaches stderr for any format."""
    image = np.random.default_rng(flip % 5).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    good = tmp_path / f"good{suffix}"
    assert cv2.imwrite(str(good), image)
    data = bytearray(good.read_bytes())
    data[flip % len(data)] ^= 1 << bit
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes(bytes(data[: max(1, round(cut * len(data)))]))
    capfd.readouterr()
    try:
        decoded = read_image(bad)
    except ImageError as exc:
        assert "\n" not in str(exc)
    else:
        assert decoded.shape == image.shape
    assert capfd.readouterr().err == ""


def test_words_of_another_thread_during_a_decode_reach_stderr_and_do_not_refuse_the_image(
    tmp_path, capfd, monkeypatch
):
    """stderr is taken off file descriptor 2 while a decoder runs (to catch libjpeg's own lines):
    a line that is not a decoder's, written there in that window (as another thread's log would
    be), is written back to stderr and leaves the image read, not refused."""
    image = np.random.default_rng(3).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    good = tmp_path / "good.png"
    assert cv2.imwrite(str(good), image)
    real = cv2.imdecode

    def decode_while_another_thread_writes(data, flags):
        os.write(2, b"qrfield serial: port /dev/ttyUSB0 gone, retrying\n")
        return real(data, flags)

    monkeypatch.setattr(cv2, "imdecode", decode_while_another_thread_writes)
    capfd.readouterr()
    assert np.array_equal(read_image(good), image)
    assert capfd.readouterr().err == "qrfield serial: port /dev/ttyUSB0 gone, retrying\n"
