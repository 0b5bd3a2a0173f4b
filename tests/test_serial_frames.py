"""Frame encoding and decoding (qrfield.serial_frames) against hand-computed truth."""

from __future__ import annotations

import numpy as np
import pytest
from serial_truth import parse_frame_line

from qrfield.serial_link import (
    MAX_LINE_BYTES,
    ControllerCommand,
    FrameDecoder,
    FrameError,
    QrfFrame,
    encode_command,
    encode_frame,
)

pytestmark = pytest.mark.timeout(30)


def test_noqr_frame_matches_hand_computed_checksum():
    # Body "QRF,7,100,,,,,,,NOQR", XOR by hand (ASCII hex):
    # Q 51 ^ R 52 = 03; ^ F 46 = 45; ^ ',' 2C = 69; ^ '7' 37 = 5E; ^ ',' 2C = 72;
    # ^ '1' 31 = 43; ^ '0' 30 = 73; ^ '0' 30 = 43; then seven ',' (odd count) ^ 2C = 6F;
    # ^ N 4E = 21; ^ O 4F = 6E; ^ Q 51 = 3F; ^ R 52 = 6D  ->  CS = 6D.
    assert encode_frame(7, 100, None, None, "NOQR") == b"$QRF,7,100,,,,,,,NOQR*6D\r\n"


def test_ok_frame_matches_hand_computed_checksum():
    # Body "QRF,1,2,0.0,0.0,0.0,0.00,0.00,0.00,OK": a character seen an even number of times cancels.
    # Odd counts: Q R F O K once, '1' once, '2' once, ',' 9 times, '0' 15 times ('.' 6 times cancels).
    # Q^R^F = 45; ^ ',' 2C = 69; ^ '0' 30 = 59; ^ '1' 31 = 68; ^ '2' 32 = 5A; ^ O 4F = 15; ^ K 4B = 5E.
    assert encode_frame(1, 2, (0, 0, 0), (0, 0, 0), "OK") == b"$QRF,1,2,0.0,0.0,0.0,0.00,0.00,0.00,OK*5E\r\n"


def test_readme_example_line_matches_hand_computed_checksum():
    # Body "QRF,42,1234,12.5,-3.0,250.0,1.25,-0.50,90.00,OK". Characters seen an even number of times
    # cancel: '4' 2x, '3' 2x, '5' 4x, '0' 8x, '.' 6x, '-' 2x. Odd: Q R F O K, ',' 9x, '2' 5x, '1' 3x, '9' 1x.
    # Q^R^F = 45; ^ O 4F = 0A; ^ K 4B = 41; ^ ',' 2C = 6D; ^ '2' 32 = 5F; ^ '1' 31 = 6E; ^ '9' 39 = 57.
    line = encode_frame(42, 1234, (12.5, -3.0, 250.0), (1.25, -0.5, 90.0), "OK")
    assert line == b"$QRF,42,1234,12.5,-3.0,250.0,1.25,-0.50,90.00,OK*57\r\n"


def test_ok_frame_values_in_mm_and_degrees_with_fixed_decimals():
    line = encode_frame(42, 1234, np.array([12.5, -3.04, 250.0]), [1.25, -0.5, 90.0], "OK")
    assert line.startswith(b"$QRF,42,1234,12.5,-3.0,250.0,1.25,-0.50,90.00,OK*")
    parsed = parse_frame_line(line)
    assert parsed["text"] == ["12.5", "-3.0", "250.0", "1.25", "-0.50", "90.00"]


def test_values_rounding_to_zero_have_no_minus_sign():
    line = encode_frame(0, 0, (-0.04, -0.0, 0.04), (-0.004, -0.0, 0.001), "OK")
    assert parse_frame_line(line)["text"] == ["0.0", "0.0", "0.0", "0.00", "0.00", "0.00"]
    assert b"-" not in line


def test_angle_rounding_to_minus_180_is_written_as_180():
    line = encode_frame(0, 0, (0, 0, 100), (-179.999, -89.999, -180.0), "OK")
    assert parse_frame_line(line)["text"][3:] == ["180.00", "-90.00", "180.00"]


def test_seeded_random_poses_survive_encode_decode_within_rounding():
    rng = np.random.default_rng(8)
    decoder = FrameDecoder()
    for i in range(300):
        position = rng.uniform(-2000, 2000, 3)
        angles = np.array([rng.uniform(-180, 180), rng.uniform(-90, 90), rng.uniform(-180, 180)])
        line = encode_frame(i, 10 * i, position, angles, "OK")
        truth = parse_frame_line(line)  # the independent parser checks framing and checksum
        assert np.all(np.abs(np.array(truth["pose"][:3]) - position) <= 0.05 + 1e-9)
        angle_error = (np.array(truth["pose"][3:]) - angles + 180.0) % 360.0 - 180.0  # 180 == -180
        assert np.all(np.abs(angle_error) <= 0.005 + 1e-9)
        (frame,) = decoder.feed(line)
        assert frame == QrfFrame(i, 10 * i, tuple(truth["pose"][:3]), tuple(truth["pose"][3:]), "OK")
    assert decoder.counters.frames == 300


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"seq": 65536}, "seq must be in 0..65535"),
        ({"seq": -1}, "seq must be in 0..65535"),
        ({"seq": 1.5}, "seq must be a whole number"),
        ({"t_ms": 2**32}, "t_ms must be in"),
        ({"t_ms": 3.0}, "t_ms must be a whole number"),
        ({"status": "GOOD"}, "status must be one of"),
        ({"status": "NOQR"}, "empty pose fields"),
        ({"position_mm": None}, "give both"),
        ({"position_mm": None, "angles_deg": None}, "OK needs position_mm"),
        ({"position_mm": (1, 2)}, "expected shape (3,)"),
        ({"angles_deg": (1, float("nan"), 3)}, "finite"),
        ({"angles_deg": (181, 0, 0)}, "within +-180"),
        ({"position_mm": (0, 0, 1e7)}, "within +-999999.9"),
        ({"position_mm": "abc"}, "expected"),
    ],
)
def test_encode_rejects_bad_input_with_a_clear_message(kwargs, message):
    args = {"seq": 0, "t_ms": 0, "position_mm": (1, 2, 3), "angles_deg": (4, 5, 6), "status": "OK"} | kwargs
    with pytest.raises(FrameError, match=message.replace("(", r"\(").replace(")", r"\)").replace("+", r"\+")):
        encode_frame(**args)
    assert issubclass(FrameError, ValueError)


def test_status_frames_without_pose_have_six_empty_fields():
    for status in ("NOQR", "NOCONV", "STALE"):
        parsed = parse_frame_line(encode_frame(65535, 5, None, None, status))
        assert parsed["text"] == [""] * 6 and parsed["status"] == status and parsed["seq"] == 65535
    stale = parse_frame_line(encode_frame(3, 5, (1, 2, 3), (4, 5, 6), "STALE"))
    assert stale["pose"] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]


def test_decoder_counts_bad_checksum_truncated_and_garbage_and_keeps_good_frames():
    good1 = b"$QRF,7,100,,,,,,,NOQR*6D\r\n"
    good2 = b"$QRF,1,2,0.0,0.0,0.0,0.00,0.00,0.00,OK*5E\r\n"
    bad_cs = b"$QRF,7,100,,,,,,,NOQR*6C\r\n"
    truncated = b"$QRF,7,10"  # cut off: the next '$' starts a new line
    no_cs = b"$QRF,7,100,,,,,,,NOQR\r\n"
    garbage = b"hello\x00\xff"
    decoder = FrameDecoder()
    lower_hex = good1.replace(b"6D", b"6d")  # accepted: the checksum's hex digits in either case
    stream = garbage + good1 + bad_cs + truncated + good2 + no_cs + lower_hex
    items = []
    for i in range(0, len(stream), 5):  # arbitrary chunking must not matter
        items += decoder.feed(stream[i : i + 5])
    noqr = QrfFrame(7, 100, None, None, "NOQR")
    assert items == [noqr, QrfFrame(1, 2, (0, 0, 0), (0, 0, 0), "OK"), noqr]
    c = decoder.counters
    # garbage: 7 bytes; truncated: "$QRF,7,10" and the line without "*CS".
    assert (c.frames, c.bad_checksum, c.truncated, c.garbage_bytes, c.malformed) == (3, 1, 2, 7, 0)


def test_decoder_checks_content_after_checksum():
    def line(body: str) -> bytes:
        cs = 0
        for ch in body.encode():
            cs ^= ch
        return b"$%s*%02X\r\n" % (body.encode(), cs)

    decoder = FrameDecoder()
    bad = [
        "QRF,1,2,,,,,,,OK",  # OK without pose
        "QRF,70000,2,,,,,,,NOQR",  # seq out of range
        "QRF,1,2,1,2,3,4,5,6,NOQR",  # NOQR with pose
        "QRF,1,2,1,2,3,4,5,x,OK",  # not a number
        "QRF,1,2,,,,,,NOQR",  # 9 fields
        "QRF,1,2,1,2,3,4,5,6,BAD",  # unknown status
    ]
    for body in bad:
        assert decoder.feed(line(body)) == [], body
    assert decoder.counters.malformed == len(bad) and decoder.counters.frames == 0


def test_decoder_reads_controller_commands_in_the_same_framing():
    decoder = FrameDecoder()
    # "QRC,RATE,10": Q^R = 03, ^C 43 = 40, ^',' = 6C, ^R 52 = 3E, ^A 41 = 7F, ^T 54 = 2B,
    # ^E 45 = 6E, ^',' = 42, ^'1' 31 = 73, ^'0' 30 = 43  ->  43.
    assert decoder.feed(b"$QRC,RATE,10*43\r\n") == [ControllerCommand("QRC", ("RATE", "10"))]
    assert encode_command("QRC", "RATE", "10") == b"$QRC,RATE,10*43\r\n"
    assert decoder.feed(encode_command("PING")) == [ControllerCommand("PING", ())]
    with pytest.raises(FrameError, match="talker"):
        encode_command("qrc")
    with pytest.raises(FrameError, match="printable"):
        encode_command("QRC", "a,b")


def test_decoder_survives_seeded_random_bytes_and_recovers():
    rng = np.random.default_rng(1)
    decoder = FrameDecoder()
    for _ in range(50):
        assert isinstance(
            decoder.feed(rng.integers(0, 256, rng.integers(1, 3000)).astype(np.uint8).tobytes()), list
        )
        assert decoder.buffered <= MAX_LINE_BYTES
    decoder.feed(b"\n")  # end whatever line random bytes began
    assert decoder.feed(b"$QRF,7,100,,,,,,,NOQR*6D\r\n") == [QrfFrame(7, 100, None, None, "NOQR")]
    c = decoder.counters
    assert c.garbage_bytes > 0 and c.bad_checksum + c.truncated + c.malformed + c.overlong > 0


def test_decoder_drops_a_one_megabyte_line_with_bounded_memory():
    decoder = FrameDecoder()
    chunk = b"A" * 65536
    assert decoder.feed(b"$QRF," + chunk) == []
    for _ in range(16):  # 1 MB more of the same line, no newline
        assert decoder.feed(chunk) == []
        assert decoder.buffered <= MAX_LINE_BYTES
    assert decoder.feed(b"\r\n$QRF,7,100,,,,,,,NOQR*6D\r\n") == [QrfFrame(7, 100, None, None, "NOQR")]
    assert decoder.counters.overlong == 1
    assert decoder.counters.garbage_bytes == 5 + 17 * 65536
    # A 1 MB line in a single call is bounded too.
    decoder2 = FrameDecoder()
    assert decoder2.feed(b"$" + b"7" * 2**20 + b"\n") == []
    assert decoder2.buffered == 0 and decoder2.counters.overlong == 1


def test_decoder_never_raises_on_non_bytes():
    decoder = FrameDecoder()
    assert decoder.feed(None) == []  # type: ignore[arg-type]
    assert decoder.feed("text") == []  # type: ignore[arg-type]
    assert decoder.feed(10**12) == []  # type: ignore[arg-type]  # bytes(10**12) would allocate 1 TB
