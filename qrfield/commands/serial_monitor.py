"""``qrfield serial-monitor PORT``: print the frames arriving on a serial port, count what is wrong.

A tool for whoever writes the gripper controller: point it at the line (or at the other end of a
pty / a USB-serial adapter in loopback) and it prints every decoded ``$QRF`` frame and controller
command, one per line (``--json`` for JSON lines), and at the end (Ctrl-C, SIGTERM, ``--count`` or
``--seconds``) the counts of bad checksums, truncated and malformed lines, garbage bytes and seq gaps.
Frames go to stdout, the summary and messages to stderr.
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
    parser.add_argument("port", metavar="PORT", help="device path (/dev/ttyUSB0, COM3, a pty) or URL")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate, 8N1 (default 115200)")
    parser.add_argument("--count", type=int, default=None, metavar="N", help="stop after N decoded lines")
    parser.add_argument("--seconds", type=float, default=None, metavar="S", help="stop after S seconds")
    parser.add_argument("--json", action="store_true", help="one JSON object per line instead of text")


def _fmt(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}"


def describe(item: object, as_json: bool) -> str:
    """One output line for a decoded QrfFrame or ControllerCommand (mm and degrees)."""
    from qrfield.serial_link import QrfFrame

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

    from qrfield.serial_link import FrameDecoder, QrfFrame, SerialLinkSettings
    from qrfield.settings import specs

    baud_spec = next(s for s in specs(SerialLinkSettings) if s.name == "baud")
    baud = baud_spec.validate(args.baud, where="--")
    if args.count is not None and args.count < 1:
        raise ValueError(f"--count must be at least 1, got {args.count}")
    if args.seconds is not None and not 0 < args.seconds < math.inf:
        raise ValueError(f"--seconds must be a positive number of seconds, got {args.seconds}")
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
    try:
        print(banner, file=sys.stderr, flush=True)  # inside the try: a signal right after it is clean
        while args.count is None or printed < args.count:
            if deadline is not None and time.monotonic() >= deadline:
                ended = f"{args.seconds:g} s elapsed"
                break
            for item in decoder.feed(port.read(4096)):
                if isinstance(item, QrfFrame):
                    if last_seq is not None and item.seq != (last_seq + 1) % 65536:
                        seq_gaps += 1
                    last_seq = item.seq
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
        f"serial-monitor: {ended}; frames {c.frames}, commands {c.commands}, bad checksums {c.bad_checksum}, "
        f"truncated {c.truncated}, malformed {c.malformed}, overlong {c.overlong}, "
        f"garbage bytes {c.garbage_bytes}, seq gaps {seq_gaps}",
        file=sys.stderr,
        flush=True,
    )
    for note in c.notes[-5:]:
        print(f"serial-monitor: last problems: {note}", file=sys.stderr)
    return code
