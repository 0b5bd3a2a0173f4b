"""``qrfield serial-monitor PORT``: print the lines arriving on a serial port, count what is wrong.

A tool for whoever writes the gripper controller: point it at the line (or at the other end of a
pty / a USB-serial adapter in loopback) and it prints every decoded ``$QRF`` line (protocol 2,
docs/serial.md: the pose, its sigmas, age_ms and the pose's age when the line's last byte arrived,
age_ms + bytes x 10 / baud), ``$QRA`` / ``$QRM`` answer and controller command, one per line
(``--json`` for JSON lines), and at the end (Ctrl-C, SIGTERM, ``--count`` or ``--seconds``) the
counts of bad CRCs, truncated and malformed lines, garbage bytes and seq gaps. Lines go to stdout,
the summary and messages to stderr.

``--send "MEAS,10"`` (repeatable) sends ``$QRC,MEAS,10*<CRC>`` (the CRC computed here) once the port
is open, playing the controller; the monitor then stops once every command sent is answered, or
once the answers are overdue (3 s, plus 2 s + n / 5 s for MEAS,n), or after ``--seconds``.
``--answers-only`` prints the answers, not the frames.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any

from qrfield.commands._signals import restore_sigterm, sigterm_as_interrupt
from qrfield.geometry import ANGLE_NAMES, POSITION_NAMES

HELP = "print decoded pose frames arriving on a serial port and count bad checksums and garbage"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, seconds

    parser.add_argument("port", metavar="PORT", help="device path (/dev/ttyUSB0, COM3, a pty) or URL")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate, 8N1 (default 115200)")
    parser.add_argument(
        "--count", type=count("--count"), default=None, metavar="N", help="stop after N decoded lines"
    )
    parser.add_argument(
        "--seconds", type=seconds("--seconds"), default=None, metavar="S", help="stop after S seconds"
    )
    parser.add_argument("--json", action="store_true", help="one JSON object per line instead of text")
    parser.add_argument(
        "--send",
        action="append",
        default=[],
        metavar="COMMAND",
        help='send a controller command, e.g. "PING", "STREAM,OFF", "MEAS,10" (as $QRC,...*CS); repeatable',
    )
    parser.add_argument("--answers-only", action="store_true", help="print only $QRA and $QRM answers")


def _fmt(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}"


def _triplet(values: tuple[float | None, ...] | None, names: tuple[str, str, str], decimals: int) -> str:
    if values is None:
        return ""
    texts = ("?" if v is None else _fmt(v, decimals) for v in values)
    return " ".join(f"{n}={t}" for n, t in zip(names, texts, strict=True))


XYZ, ANGLES = POSITION_NAMES, ANGLE_NAMES


def arrival_age_ms(item: Any, baud: float) -> float | None:
    """docs/serial.md: a $QRF pose's age when the line's last byte arrived, age_ms + bytes x 10 / baud
    (the line's bytes are those the codec writes for it: one spelling per value)."""
    from qrfield.serial import codec

    if item.age_ms is None:
        return None
    pose = None
    if item.position_mm is not None:
        pose = codec.wire_pose(item.position_mm, item.angles_deg, item.std_position_mm, item.std_angles_deg)
    n_bytes = len(codec.encode_frame(item.seq, item.t_ms, item.age_ms, item.status, pose))
    return item.age_ms + n_bytes * 10_000.0 / baud


def _record(kind: str, item: Any) -> dict:
    record = {"type": kind, **{k: getattr(item, k) for k in item.__dataclass_fields__}}
    return {k: list(v) if isinstance(v, tuple) else v for k, v in record.items()}


def describe(item: object, as_json: bool, baud: float = 115200) -> str:
    """One output line for a decoded frame, answer or command (mm and degrees)."""
    from qrfield.serial.codec import QraAnswer, QrfFrame, QrmMeasurement

    if isinstance(item, QrmMeasurement):
        if as_json:
            return json.dumps(_record("measurement", item))
        if item.position_mm is None:
            return f"measurement seq={item.seq} t={item.t_ms} ms  {item.status}"
        return (
            f"measurement seq={item.seq} t={item.t_ms} ms  "
            f"{_triplet(item.position_mm, XYZ, 1)} mm  {_triplet(item.angles_deg, ANGLES, 2)} deg  "
            f"sigma of the mean {_triplet(item.std_position_mm, XYZ, 1)} mm "
            f"{_triplet(item.std_angles_deg, ANGLES, 2)} deg  n={item.n_used}  {item.status}"
        )
    if isinstance(item, QraAnswer):
        if as_json:
            return json.dumps({"type": "answer", "command": item.command, "fields": list(item.fields)})
        return f"answer {item.command} {','.join(item.fields)}"
    if isinstance(item, QrfFrame):
        arrival = arrival_age_ms(item, baud)
        if as_json:
            return json.dumps({**_record("frame", item), "arrival_age_ms": arrival})
        pose = "(no pose)"
        if item.position_mm is not None:
            pose = (
                f"{_triplet(item.position_mm, XYZ, 1)} mm  {_triplet(item.angles_deg, ANGLES, 2)} deg  "
                f"sigma {_triplet(item.std_position_mm, XYZ, 1)} mm "
                f"{_triplet(item.std_angles_deg, ANGLES, 2)} deg"
            )
        age = "age -" if arrival is None else f"age {item.age_ms} ms (at arrival {arrival:.0f} ms)"
        return f"seq={item.seq:<5} t={item.t_ms} ms  {age}  {pose}  {item.status}"
    talker, fields = item.talker, item.fields  # type: ignore[attr-defined]
    if as_json:
        return json.dumps({"type": "command", "talker": talker, "fields": list(fields)})
    return f"command {talker} {','.join(fields)}"


def run(args: argparse.Namespace) -> int:
    import serial

    from qrfield.serial.codec import FrameDecoder, QraAnswer, QrfFrame, QrmMeasurement, encode_command
    from qrfield.serial.controller import meas_timeout_s
    from qrfield.serial.link import SerialLinkSettings
    from qrfield.settings import specs

    baud_spec = next(s for s in specs(SerialLinkSettings) if s.name == "baud")
    baud = baud_spec.validate(args.baud, where="--")
    if args.count is not None and args.count < 1:
        raise ValueError(f"--count must be at least 1, got {args.count}")
    if args.seconds is not None and not 0 < args.seconds < math.inf:
        raise ValueError(f"--seconds must be a positive number of seconds, got {args.seconds}")
    fields = [text.strip().removeprefix("$QRC,").split("*")[0].split(",") for text in args.send]
    commands = [encode_command(*f) for f in fields]  # the CRC is computed here
    if commands and args.seconds is None and args.count is None:
        # Stop at the latest once every answer is overdue (MEAS,n may take 2 s + n / 5 s).
        args.seconds = 3.0 + max(
            meas_timeout_s(int(f[1])) if f[0].upper() == "MEAS" and len(f) == 2 and f[1].isdigit() else 0.0
            for f in fields
        )
    try:
        port = serial.serial_for_url(args.port, baudrate=baud, timeout=0.1)  # 8N1 is pyserial's default
    except (serial.SerialException, ValueError) as exc:
        raise OSError(f"cannot open serial port {args.port}: {exc}") from None

    previous = sigterm_as_interrupt()
    decoder = FrameDecoder()
    printed = seq_gaps = 0
    last_seq: int | None = None
    ended = "stopped"
    code = 0
    deadline = None if args.seconds is None else time.monotonic() + args.seconds
    banner = f"serial-monitor: listening on {args.port} at {baud} baud 8N1 (Ctrl-C to stop)"
    answers = 0
    try:
        print(banner, file=sys.stderr, flush=True)  # inside the try: a signal right after it is clean
        for line in commands:
            port.write(line)
            print(f"serial-monitor: sent {line.decode('ascii').strip()}", file=sys.stderr, flush=True)
        while args.count is None or printed < args.count:
            if deadline is not None and time.monotonic() >= deadline:
                ended = f"{args.seconds:g} s elapsed"
                break
            if commands and answers >= len(commands):
                ended = f"{answers} answers received"
                break
            for item in decoder.feed(port.read(4096)):
                if isinstance(item, QrfFrame):
                    if last_seq is not None and item.seq != (last_seq + 1) % 65536:
                        seq_gaps += 1
                    last_seq = item.seq
                answer = isinstance(item, (QraAnswer, QrmMeasurement))
                answers += answer
                if args.answers_only and not answer:
                    continue
                print(describe(item, args.json, baud), flush=True)
                printed += 1
                if args.count is not None and printed >= args.count:
                    ended = f"{args.count} lines decoded"
                    break
    except KeyboardInterrupt:
        ended = "interrupted"
    except (serial.SerialException, OSError) as exc:
        ended = f"port lost: {exc}"
        code = 1
    finally:
        port.close()
        restore_sigterm(previous)
    c = decoder.counters
    print(
        f"serial-monitor: {ended}; frames {c.frames}, answers {c.answers}, commands {c.commands}, "
        f"bad CRCs {c.bad_checksum}, "
        f"truncated {c.truncated}, malformed {c.malformed}, overlong {c.overlong}, "
        f"garbage bytes {c.garbage_bytes}, seq gaps {seq_gaps}",
        file=sys.stderr,
        flush=True,
    )
    for note in c.notes[-5:]:
        print(f"serial-monitor: last problems: {note}", file=sys.stderr)
    return code
