"""The line format, protocol 2 (qrfield.serial.codec), against tests/serial_truth.py and hand values.

serial_truth.py shares no code with the codec (its CRC-16 is computed bit by bit and checked
against the conventions' check value 29B1); the example lines below are written out by hand from
docs/conventions.md, their CRCs from that independent CRC.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from serial_truth import command_line, crc16, parse_answer_line, parse_frame_line

from qrfield.serial.codec import (
    MAX_LINE_BYTES,
    ControllerCommand,
    FrameDecoder,
    FrameError,
    PoseValueError,
    QraAnswer,
    QrfFrame,
    QrmMeasurement,
    RejectedLine,
    answer_command,
    encode_answer,
    encode_command,
    encode_error,
    encode_frame,
    encode_measurement,
    encode_ok,
    field_text,
    wire_pose,
)
from qrfield.serial.codec import crc16 as codec_crc16


def line(body: str) -> bytes:
    """A line with the independent CRC."""
    return b"$%s*%04X\r\n" % (body.encode(), crc16(body.encode()))


EXAMPLE_BODY = "QRF,42,1234,17,12.5,-3.0,250.0,1.25,-0.50,90.00,0.1,0.2,0.5,0.05,0.10,0.20,OK"


def test_crc_is_ccitt_false_with_the_conventions_check_value():
    assert codec_crc16(b"123456789") == 0x29B1
    assert codec_crc16(b"") == 0xFFFF  # the initial value, no final XOR
    rng = np.random.default_rng(3)
    for _ in range(200):
        data = rng.integers(0, 256, rng.integers(0, 160)).astype(np.uint8).tobytes()
        assert codec_crc16(data) == crc16(data)


def test_ok_line_is_the_one_written_out_by_hand():
    pose = wire_pose((12.5, -3.0, 250.0), (1.25, -0.5, 90.0), (0.1, 0.2, 0.5), (0.05, 0.1, 0.2))
    assert encode_frame(42, 1234, 17, "OK", pose) == line(EXAMPLE_BODY)
    # The worked example of docs/serial.md, CRC by the independent implementation.
    assert line(EXAMPLE_BODY).endswith(b"*%04X\r\n" % crc16(EXAMPLE_BODY.encode()))


def test_empty_statuses_have_eleven_empty_number_fields_and_ageless_nosrc():
    assert encode_frame(7, 100, 3, "NOQR") == line("QRF,7,100,3,,,,,,,,,,,,,NOQR")
    assert encode_frame(8, 100, None, "NOSRC") == line("QRF,8,100,,,,,,,,,,,,,,NOSRC")
    for status in ("NOQR", "NOCONV", "STALE", "NOSRC"):
        parsed = parse_frame_line(encode_frame(65535, 5, 9, status))
        assert parsed["pose"] is None and parsed["status"] == status and parsed["age_ms"] == 9


def test_values_round_to_the_lines_decimals_without_minus_zero_and_180_not_minus_180():
    pose = wire_pose((-0.04, 0.05, -1e-9), (-179.996, -0.001, 180.0), None, None)
    assert pose.texts[:6] == ("0.0", "0.1", "0.0", "180.00", "0.00", "180.00")
    assert pose.texts[6:] == ("",) * 6  # unknown sigmas are empty
    assert wire_pose((0, 0, 1), (0, 90.004, 0)).texts[4] == "90.00"


def test_sigmas_unknown_negative_or_huge():
    pose = wire_pose((0, 0, 1), (0, 0, 0), (float("nan"), -1.0, 5e7), (None, 0.004, float("inf")))
    assert pose.texts[6:] == ("", "", "999999.9", "", "0.00", "999.99")


@pytest.mark.parametrize(
    ("position", "angles", "message"),
    [
        ((0, 0, 1e7), (0, 0, 0), "within"),
        ((0, 0, 1), (0, 90.01, 0), "beta must lie in"),
        ((0, 0, 1), (180.006, 0, 0), "alpha must lie in"),
        ((0, 0, 1), (0, 0, -180.006), "gamma must lie in"),
        ((0, 0, math.nan), (0, 0, 0), "finite"),
    ],
)
def test_out_of_range_poses_are_pose_value_errors(position, angles, message):
    with pytest.raises(PoseValueError, match=message):
        wire_pose(position, angles)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"seq": 65536}, "seq must be in 0..65535"),
        ({"seq": 1.5}, "seq must be a whole number"),
        ({"t_ms": 2**32}, "t_ms must be in"),
        ({"age_ms": None}, "needs age_ms"),
        ({"age_ms": -1}, "age_ms must be in"),
        ({"status": "GOOD"}, "status must be one of"),
        ({"status": "NOQR"}, "empty pose fields"),
        ({"pose": None}, "needs a pose"),
    ],
)
def test_encode_rejects_bad_input_with_a_clear_message(kwargs, message):
    args = {
        "seq": 0,
        "t_ms": 0,
        "age_ms": 0,
        "status": "OK",
        "pose": wire_pose((1, 2, 3), (4, 5, 6)),
    } | kwargs
    with pytest.raises(FrameError, match=message):
        encode_frame(**args)
    with pytest.raises(FrameError, match=r"expected shape \(3,\)"):
        wire_pose((1, 2), (0, 0, 0))


finite = st.floats(allow_nan=False, allow_infinity=False)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(
    st.tuples(*[finite.filter(lambda v: abs(v) < 999999.9)] * 3),
    st.tuples(st.floats(-179.99, 180.0), st.floats(-90.0, 90.0), st.floats(-179.99, 180.0)),
    st.tuples(*[st.one_of(st.none(), st.floats(0, 1e6))] * 6),
    st.sampled_from(["OK", "AMBIG", "SIM"]),
    st.integers(0, 65535),
    st.integers(0, 2**32 - 1),
    st.integers(0, 2**32 - 1),
)
def test_every_pose_encodes_to_a_line_the_truth_reads_back_within_rounding(
    position, angles, sigmas, status, seq, t_ms, age
):
    line_ = encode_frame(seq, t_ms, age, status, wire_pose(position, angles, sigmas[:3], sigmas[3:]))
    truth = parse_frame_line(line_)
    assert len(line_) <= MAX_LINE_BYTES and (truth["seq"], truth["t_ms"], truth["age_ms"]) == (seq, t_ms, age)
    for got, want, tol in zip(truth["pose"], [*position, *angles], [0.05] * 3 + [0.005] * 3, strict=True):
        assert abs(got - want) <= tol + 1e-9 or (abs(want) >= 179.995 and abs(got) == 180.0)
    decoded = FrameDecoder().feed(line_)
    assert decoded == [
        QrfFrame(
            seq, t_ms, age, tuple(truth["pose"][:3]), tuple(truth["pose"][3:]), *_sig(truth["sigma"]), status
        )
    ]


def _sig(sigma):
    return tuple(sigma[:3]), tuple(sigma[3:])


def test_measurement_and_answers_match_the_truth():
    pose = wire_pose((10, -5, 300), (15.04, -20.01, 10), (0.31, 0.3, 1.2), (0.05, 0.05, None))
    qrm = parse_answer_line(encode_measurement(3, 5321, "AMBIG", pose, 10))
    assert qrm["pose"] == [10.0, -5.0, 300.0, 15.04, -20.01, 10.0] and qrm["std"][5] is None
    assert qrm["n_used"] == 10 and qrm["status"] == "AMBIG"
    assert encode_measurement(1, 9012, "TIMEOUT") == line("QRM,1,9012,,,,,,,,,,,,,,TIMEOUT")
    assert encode_ok("PING") == line("QRA,PING,OK")
    assert encode_ok("RATE", "15") == line("QRA,RATE,OK,15")
    assert encode_error("?", "OVERFLOW", "3") == line("QRA,?,ERR,OVERFLOW,3")
    long = encode_error("MEAS", "a, very long reason that goes on and on past forty bytes")
    assert parse_answer_line(long)["reason"] == "a very long reason that goes on and on p"
    assert encode_answer("HELLO", "QRF2", "0.1.0", "50.0", field_text("my,cam*era"), "camera") == line(
        "QRA,HELLO,QRF2,0.1.0,50.0,my_cam_era,camera"
    )
    assert answer_command(" ping ") == "PING" and answer_command("P$NG") == "?"
    with pytest.raises(FrameError):
        encode_answer("PING", "a,b")
    with pytest.raises(FrameError, match="needs the mean pose"):
        encode_measurement(0, 0, "OK")


def test_decoder_reads_every_kind_and_accepts_cr_or_lf_alone():
    decoder = FrameDecoder()
    stream = (
        line("QRC,PING")[:-1]  # CR only
        + line("QRC,MEAS,10").replace(b"\r\n", b"\n")  # LF only
        + line("QRA,PING,OK")
        + line("QRM,1,9012,,,,,,,,,,,,,,TIMEOUT")
        + line("QRF,8,100,,,,,,,,,,,,,,NOSRC")
    )
    items = []
    for i in range(0, len(stream), 7):  # chunking must not matter
        items += decoder.feed(stream[i : i + 7])
    assert items == [
        ControllerCommand("QRC", ("PING",)),
        ControllerCommand("QRC", ("MEAS", "10")),
        QraAnswer("PING", ("OK",)),
        QrmMeasurement(1, 9012, None, None, None, None, None, "TIMEOUT"),
        QrfFrame(8, 100, None, None, None, None, None, "NOSRC"),
    ]
    assert decoder.feed(command_line("PING").replace(b"F075", b"f075")) == [
        ControllerCommand("QRC", ("PING",))
    ]
    assert encode_command("MEAS", "10") == command_line("MEAS", "10")


@pytest.mark.parametrize(
    "body",
    [
        "QRF,1,2,3,+1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",  # '+'
        "QRF,1,2,3, 1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",  # a space
        "QRF,1,2,3,1.e5,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",  # exponent
        "QRF,1,2,3,01.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",  # leading zero
        "QRF,1,2,3,-0.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",  # minus zero
        "QRF,1,2,3,1.00,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",  # two decimals for mm
        "QRF,1,2,3,1.0,0.0,1.0,-180.00,0.00,0.00,,,,,,,OK",  # alpha -180
        "QRF,1,2,3,1.0,0.0,1.0,0.00,90.01,0.00,,,,,,,OK",  # beta > 90
        "QRF,1,2,3,1.0,0.0,1.0,0.00,0.00,0.00,-0.1,,,,,,OK",  # negative sigma
        "QRF,1,2,,1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,OK",  # no age on a pose
        "QRF,1,2,3,,,,,,,,,,,,,OK",  # OK without pose
        "QRF,1,2,3,1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,NOQR",  # NOQR with pose
        "QRF,70000,2,3,,,,,,,,,,,,,NOQR",  # seq out of range
        "QRF,01,2,3,,,,,,,,,,,,,NOQR",  # seq with a leading zero
        "QRF,1,2,3,,,,,,,,,,,,NOQR",  # 16 fields
        "QRF,1,2,3,\x01,,,,,,,,,,,,NOQR",  # not printable
        "QRM,1,2,1.0,0.0,1.0,0.00,0.00,0.00,,,,,,,0,OK",  # n_used 0
        "QRA,PING",  # no result
        "QRA,PING,ERR",  # ERR without reason
        "QRA,ping,OK",  # lower-case command
    ],
)
def test_decoder_rejects_every_number_and_field_outside_the_grammar(body):
    decoder = FrameDecoder(report_rejected=True)
    items = decoder.feed(line(body))
    assert len(items) == 1 and isinstance(items[0], RejectedLine) and items[0].reason == "FORMAT", body
    assert decoder.counters.malformed == 1


def test_decoder_counts_and_reports_bad_lines_and_keeps_good_ones():
    good = line("QRF,7,100,3,,,,,,,,,,,,,NOQR")
    crc = good[-6:-2]
    bad_crc = good.replace(crc, b"%04X" % (int(crc, 16) ^ 1))
    stream = (
        b"hello\x00\xff"
        + good
        + bad_crc
        + b"$QRF,7,10"
        + good
        + b"$QRF,no crc\r\n"
        + b"$"
        + b"7" * 200
        + b"\n"
    )
    decoder = FrameDecoder(report_rejected=True)
    items = decoder.feed(stream)
    reasons = [i.reason for i in items if isinstance(i, RejectedLine)]
    assert [i for i in items if isinstance(i, QrfFrame)] == [
        QrfFrame(7, 100, 3, None, None, None, None, "NOQR")
    ] * 2
    assert reasons == ["CRC", "CRC", "CRC", "LENGTH"]
    c = decoder.counters
    assert (c.frames, c.bad_checksum, c.truncated, c.overlong, c.malformed) == (2, 1, 2, 1, 0)


def test_decoder_survives_random_bytes_with_bounded_memory_and_recovers():
    rng = np.random.default_rng(1)
    decoder = FrameDecoder()
    for _ in range(50):
        assert isinstance(
            decoder.feed(rng.integers(0, 256, rng.integers(1, 3000)).astype(np.uint8).tobytes()), list
        )
        assert decoder.buffered < MAX_LINE_BYTES
    decoder.feed(b"\n")
    good = line("QRF,7,100,3,,,,,,,,,,,,,NOQR")
    assert decoder.feed(good) == [QrfFrame(7, 100, 3, None, None, None, None, "NOQR")]
    big = FrameDecoder()
    assert big.feed(b"$" + b"7" * 2**20 + b"\n") == [] and big.buffered == 0 and big.counters.overlong == 1
    assert big.feed(None) == [] and big.feed("text") == [] and big.feed(10**12) == []  # type: ignore[arg-type]
