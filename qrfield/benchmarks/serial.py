"""``qrfield benchmark serial``: the line format's cost, and what a controller gets over a real baud rate.

1. Encoding: lines per second of :func:`~qrfield.serial.codec.encode_frame` (checks, rounding,
   CRC-16) beside a bare f-string of the same numbers with no checks and no CRC.
2. Throughput: lines per second through :class:`~qrfield.serial.link.SerialLink` (4,000,000 baud,
   no rate limit, so the code is the limit) to a pty and to ``loop://``, beside bare
   ``port.write`` calls of a pre-encoded line.
3. Latency: ``publish()`` to the line's last byte read at the pty's other end, beside a bare write.
4. A UART: the link on a pty behind :class:`~qrfield.serial.relay.UartRelay` passing 960 B/s
   (9600 baud) and 11,520 B/s (115200 baud) for ``--relay-seconds`` each, a frame loop publishing
   ``--relay-fps`` poses a second (no rate limit: the port is the limit) and the controller sending
   PING every 0.5 s. Printed: the lag of arriving poses (the line's last byte minus the capture)
   over the first and the last 5 s, the share of lines that carried the newest pose published one
   line time before they arrived, and the PING answer times (from the PING's last byte reaching
   qrfield to the answer's last byte at the controller). Baseline, same relay and frame loop: every
   pose written as it comes (what the link did before protocol 2), for ``--baseline-seconds``.
"""

from __future__ import annotations

import argparse
import os
import threading
import time

from qrfield.status import WireStatus

HELP = "serial line format cost, link throughput, and pose lag and PING answers over a 9600 / 115200 UART"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=20000, help="lines encoded (default 20000)")
    parser.add_argument("--seconds", type=float, default=1.0, help="seconds per throughput run (default 1)")
    parser.add_argument(
        "--latency-frames", type=int, default=300, help="lines timed for latency (default 300)"
    )
    parser.add_argument("--relay-seconds", type=float, default=30.0, help="seconds per UART run (default 30)")
    parser.add_argument(
        "--baseline-seconds", type=float, default=10.0, help="seconds of the baseline (default 10)"
    )
    parser.add_argument(
        "--relay-fps", type=float, default=60.0, help="poses published per second (default 60)"
    )
    parser.add_argument("--seed", type=int, default=1)


class _PtyReader:
    """Reads the master end of a pty in a thread; notes when each complete line arrived."""

    def __init__(self, master: int) -> None:
        self.master = master
        self.arrivals: dict[bytes, float] = {}  # the line's t_ms field -> perf_counter at arrival
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        buffer = b""
        while not self._stop:
            try:
                data = os.read(self.master, 65536)
            except OSError:
                return
            now = time.perf_counter()
            if not data:
                return
            buffer += data
            *lines, buffer = buffer.split(b"\n")
            for line in lines:
                fields = line.split(b",")
                if len(fields) > 2:
                    self.arrivals[fields[2]] = now  # keyed by t_ms, unique per published line

    def stop(self) -> None:
        self._stop = True


def _stats(values_ms: list[float]) -> str:
    import numpy as np

    if not values_ms:
        return "(none)"
    a = np.asarray(values_ms)
    return f"mean {a.mean():.1f} ms, p95 {np.percentile(a, 95):.1f} ms, max {a.max():.1f} ms (n={a.size})"


def _pose(poses, i):
    return poses[0][i % len(poses[0])], poses[1][i % len(poses[1])]


def _uart_run(bytes_per_s: float, seconds: float, fps: float, poses, *, paced: bool) -> dict:
    """One run over the relay: the link (``paced``) or bare writes of every pose (the baseline)."""
    import numpy as np
    import serial

    from qrfield.serial import codec
    from qrfield.serial.controller import GripperLink
    from qrfield.serial.link import CONNECTED, SerialLinkSettings, line_time_s
    from qrfield.serial.relay import UartRelay

    baud = bytes_per_s * 10
    relay = UartRelay(bytes_per_s)
    published: list[tuple[float, int]] = []  # (time.monotonic() at publish = capture, t_ms)
    pings: list[float] = []
    link = port = None
    try:
        if paced:
            link = GripperLink(
                SerialLinkSettings(port=relay.device, baud=int(baud), max_rate_hz=0, stale_after_s=0)
            )
            link.start()
            if not link.wait_for_state(CONNECTED, 5):
                raise OSError(f"cannot open the relay's pty: {link.status().last_error}")
        else:
            port = serial.serial_for_url(relay.device, baudrate=int(baud), timeout=0)
        t0 = time.monotonic()
        i, next_ping = 0, t0 + 0.25
        while (now := time.monotonic()) - t0 < seconds:
            t_ms = round((now - t0) * 1000)
            position, angles = _pose(poses, i)
            published.append((now, t_ms))
            if link is not None:
                link.link.publish(
                    t_ms, position, angles, WireStatus.OK, std_position_mm=(0.2, 0.2, 1.0), captured_at=now
                )
            else:
                pose = codec.wire_pose(position, angles, (0.2, 0.2, 1.0))
                port.write(codec.encode_frame(i % 65536, t_ms, 0, WireStatus.OK, pose))
            if now >= next_ping:
                relay.send(codec.encode_command("PING"))
                pings.append(now)
                next_ping += 0.5
            i += 1
            time.sleep(max(0.0, t0 + i / fps - time.monotonic()))
        time.sleep(0.3)
    finally:
        if link is not None:
            link.close()
        if port is not None:
            port.close()
        relay.close()
    capture = dict((t_ms, at) for at, t_ms in published)
    times = np.array([at for at, _ in published])
    decoder = codec.FrameDecoder()
    lags, starts, newest, within, answers, line_times = [], [], [], [], [], []
    for arrived, line in relay.lines:
        for item in decoder.feed(line):
            if isinstance(item, codec.QrfFrame) and item.status == WireStatus.OK and item.t_ms in capture:
                at = capture[item.t_ms]
                lags.append((arrived - at) * 1000)
                starts.append(arrived - t0)
                line_time = line_time_s(len(line), baud)
                line_times.append(line_time)
                # The newest pose published one line time before the line's last byte arrived.
                k = int(np.searchsorted(times, arrived - line_time, side="right")) - 1
                newest.append(k < 0 or times[k] <= at + 1e-9)
                within.append(k < 0 or times[k] - at <= line_time)
            elif isinstance(item, codec.QraAnswer) and item.command == "PING":
                answers.append(arrived)
    ping_ms = [(a - d) * 1000 for a, d in zip(answers, relay.sent_done, strict=False)]
    lag, start = np.array(lags), np.array(starts)
    first = lag[start < 5] if lag.size else lag
    last = lag[start > seconds - 5] if lag.size else lag
    return {
        "lines": len(lags),
        "seconds": seconds,
        "first": float(first.mean()) if first.size else float("nan"),
        "last": float(last.mean()) if last.size else float("nan"),
        "max": float(lag.max()) if lag.size else float("nan"),
        "newest": float(np.mean(newest)) if newest else float("nan"),
        "within": float(np.mean(within)) if within else float("nan"),
        "line_ms": 1000 * float(np.mean(line_times)) if line_times else float("nan"),
        "pings": len(pings),
        "ping_ms": ping_ms,
    }


def run(args: argparse.Namespace) -> int:
    import numpy as np
    import serial

    from qrfield.serial.codec import encode_frame, wire_pose
    from qrfield.serial.link import CONNECTED, SerialLink, SerialLinkSettings

    if args.frames < 1 or args.seconds <= 0 or args.latency_frames < 2 or args.relay_seconds < 0:
        raise ValueError(
            "--frames and --latency-frames must be positive, --seconds > 0, --relay-seconds >= 0"
        )
    rng = np.random.default_rng(args.seed)
    positions = rng.uniform([-300, -300, 100], [300, 300, 2000], (args.frames, 3))
    angles = rng.uniform([-180, -90, -180], [180, 90, 180], (args.frames, 3))
    pos_list, ang_list = positions.tolist(), angles.tolist()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"qrfield benchmark serial: {args.frames} seeded poses (seed {args.seed}); load average {load:.1f}")
    # 1. Encoding.
    t0 = time.perf_counter()
    for i in range(args.frames):
        encode_frame(i % 65536, i, 3, WireStatus.OK, wire_pose(pos_list[i], ang_list[i], (0.2, 0.2, 1.0)))
    encode_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    for i in range(args.frames):
        (x, y, z), (a, b, g) = pos_list[i], ang_list[i]
        pose = f"{x:.1f},{y:.1f},{z:.1f},{a:.2f},{b:.2f},{g:.2f}"
        f"$QRF,{i % 65536},{i},3,{pose},0.2,0.2,1.0,,,,OK\r\n".encode()
    base_s = time.perf_counter() - t0
    print(
        f"{'encode':<34}{args.frames / encode_s:>12.0f} lines/s   baseline f-string "
        f"{args.frames / base_s:>10.0f} lines/s   ratio {encode_s / base_s:.1f}x slower"
    )

    # 2. Throughput through the link vs bare writes, pty and loop://.
    line = encode_frame(0, 0, 3, WireStatus.OK, wire_pose(pos_list[0], ang_list[0]))
    for kind in ("pty", "loop://"):
        master = slave = -1
        reader = None
        if kind == "pty":
            master, slave = os.openpty()
            port_name = os.ttyname(slave)
            reader = _PtyReader(master)
        else:
            port_name = "loop://"
        settings = SerialLinkSettings(port=port_name, baud=4_000_000, max_rate_hz=0, stale_after_s=0)
        with SerialLink(settings) as link:
            if not link.wait_for_state(CONNECTED, 5):
                raise OSError(f"cannot open {port_name}: {link.status().last_error}")
            i = 0
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < args.seconds:
                link.publish(i, pos_list[i % args.frames], ang_list[i % args.frames])
                i += 1
                if i % 16 == 0:
                    time.sleep(0)  # let the link's thread run, as a real frame loop does between frames
            elapsed = time.perf_counter() - t0
            sent = link.status().frames_sent
        port = serial.serial_for_url(port_name, baudrate=115200, timeout=0, write_timeout=1)
        n = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < args.seconds:
            port.write(line)
            if kind == "loop://":
                port.read(4096)  # drain the loop so its 4 kB buffer never fills
            n += 1
        bare_elapsed = time.perf_counter() - t0
        port.close()
        print(
            f"{'written via link to ' + kind:<34}{sent / elapsed:>12.0f} lines/s   bare port.write "
            f"{n / bare_elapsed:>12.0f} lines/s   ({i} published, no rate limit, 4,000,000 baud)"
        )
        if reader is not None:
            reader.stop()
            os.close(slave)
            os.close(master)

    # 3. Latency: publish() to the last byte at the pty's other end.
    master, slave = os.openpty()
    reader = _PtyReader(master)
    settings = SerialLinkSettings(port=os.ttyname(slave), baud=4_000_000, max_rate_hz=0, stale_after_s=0)
    with SerialLink(settings) as link:
        if not link.wait_for_state(CONNECTED, 5):
            raise OSError(f"cannot open the pty: {link.status().last_error}")
        published: dict[bytes, float] = {}
        for i in range(args.latency_frames):
            t_ms = 1_000_000 + i
            published[str(t_ms).encode()] = time.perf_counter()
            link.publish(t_ms, pos_list[i % args.frames], ang_list[i % args.frames])
            time.sleep(0.004)  # a 250 Hz frame loop: nothing is superseded
        time.sleep(0.1)
        link_ms = [(reader.arrivals[k] - t) * 1e3 for k, t in published.items() if k in reader.arrivals]
    port = serial.serial_for_url(os.ttyname(slave), baudrate=115200, timeout=0, write_timeout=1)
    bare_ms: list[float] = []
    for i in range(args.latency_frames):
        t_ms = 2_000_000 + i
        pose = wire_pose(pos_list[i % args.frames], ang_list[i % args.frames])
        data = encode_frame(i % 65536, t_ms, 0, WireStatus.OK, pose)
        t0 = time.perf_counter()
        port.write(data)
        key = str(t_ms).encode()
        deadline = t0 + 1.0
        while key not in reader.arrivals and time.perf_counter() < deadline:
            time.sleep(0)
        if key in reader.arrivals:
            bare_ms.append((reader.arrivals[key] - t0) * 1e3)
        time.sleep(0.004)
    port.close()
    reader.stop()
    os.close(slave)
    os.close(master)
    print(f"{'publish -> read at pty other end':<34}{_stats(link_ms)}")
    print(f"{'bare write -> read (baseline)':<34}{_stats(bare_ms)}")

    # 4. Over a UART's pace.
    if args.relay_seconds > 0:
        poses = (pos_list, ang_list)
        for baud in (9600, 115200):
            got = _uart_run(baud / 10, args.relay_seconds, args.relay_fps, poses, paced=True)
            line_ms = got["line_ms"]
            print(
                f"{f'UART {baud} baud, link':<34}{got['lines'] / got['seconds']:>6.1f} pose lines/s of "
                f"{line_ms:.1f} ms; lag first 5 s {got['first']:.0f} ms, last 5 s {got['last']:.0f} ms, "
                f"max {got['max']:.0f} ms"
            )
            print(
                f"{'':<34}lines carrying the newest pose published one line time before arrival: "
                f"{100 * got['newest']:.1f} %; a pose at most one line time older than it: "
                f"{100 * got['within']:.1f} %"
            )
            worst = max(got["ping_ms"] or [0]) / line_ms
            print(
                f"{'':<34}PING answers: {_stats(got['ping_ms'])} = max {worst:.2f} line times; "
                f"{len(got['ping_ms'])} of {got['pings']} PINGs answered"
            )
        if args.baseline_seconds > 0:
            base = _uart_run(960, args.baseline_seconds, args.relay_fps, poses, paced=False)
            print(
                f"{'UART 9600 baud, baseline':<34}every pose written as it comes: lag first 5 s "
                f"{base['first']:.0f} ms, last 5 s {base['last']:.0f} ms, max {base['max']:.0f} ms after "
                f"{base['seconds']:g} s (a backlog: the OS buffer holds what the wire cannot carry)"
            )
    return 0
