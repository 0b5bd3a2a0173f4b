"""``qrfield serial-monitor PORT``: print the frames arriving on a serial port, count what is wrong.

A tool for whoever writes the gripper controller: point it at the line (or at the other end of a
pty / a USB-serial adapter in loopback) and it prints every decoded ``$QRF`` frame, ``$QRA`` /
``$QRM`` answer and controller command, one per line (``--json`` for JSON lines), and at the end
(Ctrl-C, SIGTERM, ``--count`` or ``--seconds``) the counts of bad checksums, truncated and malformed
lines, garbage bytes and seq gaps. Frames go to stdout, the summary and messages to stderr.

``--send "MEAS,10"`` (repeatable) sends ``$QRC,MEAS,10*CS`` once the port is open, playing the
controller (docs/conventions.md); the monitor then stops once every command sent is answered, or
once the answers are overdue (3 s, plus 2 s + n / 5 s for MEAS,n), or after ``--seconds``.
``--answers-only`` prints the answers, not the frames.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import time

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


def _triplet(values: tuple[float, ...] | None, names: tuple[str, str, str], decimals: int) -> str:
    if values is None:
        return ""
    return " ".join(f"{n}={_fmt(v, decimals)}" for n, v in zip(names, values, strict=True))


def describe(item: object, as_json: bool) -> str:
    """One output line for a decoded frame, answer or command (mm and degrees)."""
    from qrfield.serial_link import QraAnswer, QrfFrame, QrmMeasurement

    if isinstance(item, QrmMeasurement):
        if as_json:
            record = {"type": "measurement", **{k: getattr(item, k) for k in item.__dataclass_fields__}}
            return json.dumps({k: list(v) if isinstance(v, tuple) else v for k, v in record.items()})
        if item.position_mm is None:
            return f"measurement seq={item.seq} t={item.t_ms} ms  {item.status}"
        return (
            f"measurement seq={item.seq} t={item.t_ms} ms  "
            f"{_triplet(item.position_mm, ('x', 'y', 'z'), 1)} mm  "
            f"{_triplet(item.angles_deg, ('alpha', 'beta', 'gamma'), 2)} deg  "
            f"std {_triplet(item.std_position_mm, ('x', 'y', 'z'), 1)} mm "
            f"{_triplet(item.std_angles_deg, ('alpha', 'beta', 'gamma'), 2)} deg  "
            f"n={item.n_used}  {item.status}"
        )
    if isinstance(item, QraAnswer):
        if as_json:
            return json.dumps(
                {"type": "answer", "command": item.command, "result": item.result, "reason": item.reason}
            )
        return f"answer {item.command} {item.result}" + (f" ({item.reason})" if item.reason else "")
    if isinstance(item, QrfFrame):
        pos, ang = item.position_mm, item.angles_deg
        if as_json:
            record: dict = {"type": "frame", "seq": item.seq, "t_ms": item.t_ms, "status": item.status}
            record["position_mm"] = list(pos) if pos is not None else None
            record["angles_deg"] = list(ang) if ang is not None else None
            return json.dumps(record)
        pose = "(no pose)"
        if pos is not None and ang is not None:
            pose = (
                f"x={_fmt(pos[0], 1)} y={_fmt(pos[1], 1)} z={_fmt(pos[2], 1)} mm  "
                f"alpha={_fmt(ang[0], 2)} beta={_fmt(ang[1], 2)} gamma={_fmt(ang[2], 2)} deg"
            )
        return f"seq={item.seq:<5} t={item.t_ms} ms  {pose}  {item.status}"
    talker, fields = item.talker, item.fields  # type: ignore[attr-defined]
    if as_json:
        return json.dumps({"type": "command", "talker": talker, "fields": list(fields)})
    return f"command {talker} {','.join(fields)}"


def run(args: argparse.Namespace) -> int:
    import serial

    from qrfield.serial_controller import meas_timeout_s
    from qrfield.serial_link import (
        FrameDecoder,
        QraAnswer,
        QrfFrame,
        QrmMeasurement,
        SerialLinkSettings,
        encode_command,
    )
    from qrfield.settings import specs

    baud_spec = next(s for s in specs(SerialLinkSettings) if s.name == "baud")
    baud = baud_spec.validate(args.baud, where="--")
    if args.count is not None and args.count < 1:
        raise ValueError(f"--count must be at least 1, got {args.count}")
    if args.seconds is not None and not 0 < args.seconds < math.inf:
        raise ValueError(f"--seconds must be a positive number of seconds, got {args.seconds}")
    fields = [text.strip().removeprefix("$QRC,").split(",") for text in args.send]
    commands = [encode_command("QRC", *f) for f in fields]
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

    def on_sigterm(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:  # not the main thread: Ctrl-C only
        previous = None
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
                print(describe(item, args.json), flush=True)
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
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    c = decoder.counters
    print(
        f"serial-monitor: {ended}; frames {c.frames}, answers {c.answers}, commands {c.commands}, "
        f"bad checksums {c.bad_checksum}, "
        f"truncated {c.truncated}, malformed {c.malformed}, overlong {c.overlong}, "
        f"garbage bytes {c.garbage_bytes}, seq gaps {seq_gaps}",
        file=sys.stderr,
        flush=True,
    )
    for note in c.notes[-5:]:
        print(f"serial-monitor: last problems: {note}", file=sys.stderr)
    return code
