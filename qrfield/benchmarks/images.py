"""``qrfield benchmark images``: time and peak memory of refusing an image above the pixel limit.

A 0.75 MB PNG of 32000 x 24000 black pixels (768 MP; OpenCV would decode it into 768 MB grey or
2.3 GB colour) is given to ``qrfield solve`` in a fresh process; its wall time and peak resident
memory (``ru_maxrss`` of that process, what ``/usr/bin/time -v`` reports as "Maximum resident set
size") are printed beside the same command on a 640 x 480 view with a code, measured in the same
run: the refusal should cost no more than an ordinary solve.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

HELP = "time and peak memory of refusing a 32000x24000 PNG before decoding (target < 2 s, < 300 MB)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, whole_number
    from qrfield.limits import MAX_BENCHMARK_COUNT

    parser.add_argument(
        "--width",
        type=whole_number("--width", 8, 65535),
        default=32000,
        help="width of the large PNG (default 32000)",
    )
    parser.add_argument(
        "--height",
        type=whole_number("--height", 8, 65535),
        default=24000,
        help="height of the large PNG (default 24000)",
    )
    parser.add_argument(
        "--repeat",
        type=count("--repeat", 0, MAX_BENCHMARK_COUNT),
        default=3,
        help="runs of each command; the best is shown",
    )


def write_black_png(path: str, width: int, height: int) -> None:
    """A valid 8-bit grey PNG of black pixels, deflated row by row (never held whole in memory)."""
    import struct
    import zlib

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    compressor = zlib.compressobj(9)
    row = b"\x00" * (width + 1)  # filter byte 0, then the pixels
    data = b"".join(compressor.compress(row) for _ in range(height)) + compressor.flush()
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    with open(path, "wb") as handle:
        handle.write(
            b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", data) + chunk(b"IEND", b"")
        )


@dataclass(frozen=True)
class ChildRun:
    """One command run in a fresh process: wall and CPU seconds, peak resident memory (MB, that
    process's own ``ru_maxrss`` from ``os.wait4``, as ``/usr/bin/time -v`` reports it), exit code
    and the last line of its stdout."""

    seconds: float
    peak_mb: float
    cpu_s: float
    code: int
    last: str


def measure_child(argv: list[str], cwd: str | None = None) -> ChildRun:
    """Run ``argv`` in a child process (stdout read, stderr dropped) and measure it."""
    import os
    import subprocess
    import time

    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, cwd=cwd)
    assert proc.stdout is not None
    last = b""
    for line in proc.stdout:  # kept line by line: `session show` of a large session prints a lot
        if line.strip():
            last = line
    proc.stdout.close()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    seconds = time.perf_counter() - t0
    return ChildRun(
        seconds,
        usage.ru_maxrss / 1024.0,
        usage.ru_utime + usage.ru_stime,
        proc.returncode,
        last.decode("utf-8", "replace").strip(),
    )


def run(args: argparse.Namespace) -> int:
    import os
    import sys
    import tempfile

    from qrfield.camera import CameraModel
    from qrfield.geometry import Pose
    from qrfield.images import write_image
    from qrfield.render import render_view

    with tempfile.TemporaryDirectory(prefix="qrfield-bench-") as folder:
        big = os.path.join(folder, "big.png")
        write_black_png(big, args.width, args.height)
        small = os.path.join(folder, "view.png")
        view = render_view(CameraModel.from_focal(500.0, 640, 480), 50.0, Pose([0, 0, 300], [10, 0, 0]))
        write_image(small, view.image)
        base = [sys.executable, "-m", "qrfield", "solve", "--focal-px", "500", "--side-mm", "50", "--json"]
        print(
            f"qrfield benchmark images: {args.width}x{args.height} PNG of "
            f"{os.path.getsize(big) / 1e6:.2f} MB "
            f"({args.width * args.height / 1e6:.0f} MP) against a 640x480 view; best of {args.repeat} "
            "(machine shared with other work: figures vary)"
        )
        print(f"{'image':<28}{'wall s':>9}{'peak MB':>10}{'exit':>6}  result")
        rows = {}
        for label, path in ((f"{args.width}x{args.height} (refused)", big), ("640x480 (baseline)", small)):
            runs = [measure_child([*base, path]) for _ in range(max(1, args.repeat))]
            seconds = min(r.seconds for r in runs)
            peak = min(r.peak_mb for r in runs)
            code, last = runs[-1].code, runs[-1].last
            rows[label] = (seconds, peak)
            status = last[:60].replace("\n", " ")
            print(f"{label:<28}{seconds:>9.2f}{peak:>10.0f}{code:>6}  {status}")
        (big_s, big_mb), (base_s, base_mb) = rows.values()
        print(f"ratio refused / baseline: time {big_s / base_s:.2f}, memory {big_mb / base_mb:.2f}")
        met = "met" if big_s < 2 and big_mb < 300 else "NOT met"
        print(f"target: refused in under 2 s with under 300 MB peak: {met}")
    return 0
