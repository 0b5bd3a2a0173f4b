"""``qrfield benchmark memory``: peak memory and CPU of the commands on the largest inputs they accept.

Each command runs in a fresh process; its peak resident memory (``ru_maxrss`` of that process, as
``/usr/bin/time -v`` reports it) and CPU time (user + system) are printed beside the same command
on a small input, measured in the same run, with the load average:

1. images at the pixel limit (50 MP): ``calibrate`` and ``solve`` on an 8100 x 6050 (49 MP) PNG
   of noise, where no board and no code is found so every detector runs its whole search (the
   worst case: ``calibrate`` peaked at 2.6 GB on it before it searched at a working resolution),
   and on a 49 MP board and a 49 MP code; baseline: the same commands on a 640 x 480 view;
2. a PNG behind the same 49 MP header whose data inflates to ``--bomb-mb`` MB (libpng inflated it
   all: 23 s): ``solve``'s CPU beside the plain 49 MP PNG;
3. a session at rows.csv's limit (``--rows-mib``, default 256 MiB, some 970,000 rows): ``session
   list``, ``show``, ``export``, ``undo`` and ``log`` (one frame of the virtual bench) beside the
   same commands on a session of one row.

Targets (docs/benchmarks.md, "memory"): images under 600 MB; sessions under 100 MB (``session
log``, whose frame loop alone takes some 115 MB: no more than 15 MB over its one-row baseline); the
inflating PNG no more CPU than the plain one. The baseline's peak is mostly the interpreter with
numpy and OpenCV loaded (some 85 MB): the figures to compare are the peaks and the differences.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from qrfield.methods import NUMERICAL

HELP = "peak memory and CPU of calibrate, solve and the session commands at their input limits"
PARTS = ("images", "png", "sessions")
#: The image of part 1: 8100 x 6050 = 49.0 MP, under the 50 MP default limit.
BIG = (8100, 6050)
IMAGE_TARGET_MB = 600.0
SESSION_TARGET_MB = 100.0
#: What a session at the rows.csv limit may add to a command whose one-row baseline is above the
#: target already (``session log``: the frame loop).
SESSION_EXTRA_MB = 15.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import whole_number

    parser.add_argument(
        "--part", choices=(*PARTS, "all"), default="all", help="which inputs to measure (default all)"
    )
    parser.add_argument(
        "--rows-mib",
        type=whole_number("--rows-mib", 1, 256),
        default=256,
        help="size of the large rows.csv, MiB (default 256, the limit)",
    )
    parser.add_argument(
        "--bomb-mb",
        type=whole_number("--bomb-mb", 1, 4000),
        default=900,
        help="what the crafted PNG's data inflates to, MB (default 900)",
    )


def _noise_png(path: Path, size: tuple[int, int]) -> None:
    import cv2
    import numpy as np

    rng = np.random.default_rng(1)
    small = (rng.random((size[1] // 10, size[0] // 10)) * 255).astype(np.uint8)
    cv2.imwrite(str(path), cv2.resize(small, size, interpolation=cv2.INTER_LINEAR))


def _board_png(path: Path, size: tuple[int, int], squares: tuple[int, int] = (10, 7)) -> None:
    """A flat chessboard of ``squares`` (9 x 6 inner corners) filling most of the image."""
    import cv2
    import numpy as np

    side = min(size[0] // (squares[0] + 2), size[1] // (squares[1] + 2))
    image = np.full((size[1], size[0]), 255, np.uint8)
    x0, y0 = (size[0] - squares[0] * side) // 2, (size[1] - squares[1] * side) // 2
    for j in range(squares[1]):
        for i in range(squares[0]):
            if (i + j) % 2 == 0:
                image[y0 + j * side : y0 + (j + 1) * side, x0 + i * side : x0 + (i + 1) * side] = 0
    cv2.imwrite(str(path), image)


def _code_png(path: Path, size: tuple[int, int]) -> None:
    from qrfield.camera import CameraModel
    from qrfield.geometry import Pose
    from qrfield.images import write_image
    from qrfield.render import render_view

    focal = 500.0 * size[0] / 640.0
    view = render_view(
        CameraModel.from_focal(focal, *size), 50.0, Pose([0, 0, 300], [10, 0, 0]), supersample=1
    )
    write_image(path, view.image)


def _inflating_png(path: Path, size: tuple[int, int], extra_mb: int) -> None:
    """A valid 8-bit grey PNG of ``size`` whose data goes on with ``extra_mb`` MB of zeros."""
    import struct
    import zlib

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    compressor = zlib.compressobj(9)
    row = b"\x00" * (size[0] + 1)
    parts = [compressor.compress(row) for _ in range(size[1])]
    block = b"\x00" * (1 << 20)
    parts += [compressor.compress(block) for _ in range(int(extra_mb * 1e6) >> 20)]
    parts.append(compressor.flush())
    header = struct.pack(">IIBBBBB", size[0], size[1], 8, 0, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", b"".join(parts)) + chunk(b"IEND", b"")
    )


def _session(root: Path, name: str, rows_mib: float) -> Path:
    """A session of one logged row, its line repeated (renumbered) up to ``rows_mib`` MiB."""
    from qrfield.camera import resolve_camera
    from qrfield.sessions import GroundTruth, Session, measure

    session = Session.create(
        root, name, camera=resolve_camera("picam-v2@640x480"), side_mm=50.0, solver=NUMERICAL
    )
    truth = GroundTruth(10.0, -5.0, 300.0, 15.0, -20.0, 10.0, "alpha+beta-gamma+")
    frame = {"position_mm": [10.2, -5.1, 300.4], "angles_deg": [15.1, -19.8, 10.0], "converged": True}
    assert session.log(measure([frame] * 10, truth, note="a note, as typed")).ok
    session.close()
    target = int(rows_mib * (1 << 20))
    line = session.rows_path.read_bytes().splitlines(keepends=True)[-1]
    rest = line[line.index(b",") :]
    with open(session.rows_path, "ab") as handle:
        size, number, batch = session.rows_path.stat().st_size, 1, []
        while True:
            number += 1
            record = b"%d" % number + rest
            if size + len(record) > target:
                break
            batch.append(record)
            size += len(record)
            if len(batch) >= 20_000:
                handle.write(b"".join(batch))
                batch = []
        handle.write(b"".join(batch))
    return session.path


#: Run in the child: the command, then its own peak (VmHWM) written where the benchmark reads it.
#: ``ru_maxrss`` would not do: Linux keeps a process's peak across exec, so a child of this
#: (large) process would report at least this process's size.
_CHILD = (
    "import atexit, os, runpy, sys\n"
    "def _peak():\n"
    "    with open('/proc/self/status') as s, open(os.environ['QRFIELD_PEAK_FILE'], 'w') as out:\n"
    "        out.write(next(line.split()[1] for line in s if line.startswith('VmHWM:')))\n"
    "atexit.register(_peak)\n"
    "sys.argv = ['qrfield', *sys.argv[1:]]\n"
    "runpy.run_module('qrfield', run_name='__main__')\n"
)


def run_measured(argv: list[str], folder: Path) -> Any:
    """:func:`qrfield.benchmarks.images.measure_child` of ``qrfield ARGV``, its peak the child's own
    (``VmHWM`` of /proc/self/status at exit, in MB)."""
    import dataclasses

    from qrfield.benchmarks.images import measure_child

    peak_file = folder / "peak.txt"
    peak_file.unlink(missing_ok=True)
    os.environ["QRFIELD_PEAK_FILE"] = str(peak_file)
    run = measure_child([sys.executable, "-c", _CHILD, *argv])
    try:
        peak = int(peak_file.read_text()) / 1024.0
    except (OSError, ValueError):
        peak = float("nan")
    return dataclasses.replace(run, peak_mb=peak)


def _row(
    label: str, command: str, run: Any, base: Any, target_mb: float | None, extra_mb: float = 0.0
) -> str:
    """One line of the table; ``extra_mb`` > 0: the target is the baseline's peak plus that (a
    command whose baseline alone is above the target)."""
    verdict = ""
    if target_mb is not None:
        limit = max(target_mb, base.peak_mb + extra_mb) if extra_mb else target_mb
        verdict = "met" if run.peak_mb < limit and run.code in (0, 1, 2) else "NOT met"
        verdict += f" (< {limit:.0f} MB)"
    return (
        f"{label:<34}{command:<16}{run.peak_mb:>9.0f}{run.cpu_s:>8.1f}{base.peak_mb:>10.0f}{base.cpu_s:>8.1f}"
        f"{run.peak_mb - base.peak_mb:>+9.0f}{run.code:>5}  {verdict}"
    )


def run(args: argparse.Namespace) -> int:
    import tempfile

    parts = PARTS if args.part == "all" else (args.part,)
    qrfield: list[str] = []
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(
        f"qrfield benchmark memory: peak RSS (MB) and CPU (s) of each command in a fresh process; load {load}"
    )
    print(
        f"{'input':<34}{'command':<16}{'peak MB':>9}{'CPU s':>8}{'base MB':>10}{'base s':>8}{'+MB':>9}"
        f"{'exit':>5}  target"
    )
    lines: list[str] = []
    with tempfile.TemporaryDirectory(prefix="qrfield-bench-memory-") as tmp:
        folder = Path(tmp)
        env_cfg = ["--config-dir", str(folder / "config")]
        if "images" in parts or "png" in parts:
            small, big_noise = folder / "view.png", folder / "noise49.png"
            _code_png(small, (640, 480))
            _noise_png(big_noise, BIG)
        if "images" in parts:
            board_small, board_big, code_big = (
                folder / "board.png",
                folder / "board49.png",
                folder / "code49.png",
            )
            _board_png(board_small, (640, 480))
            _board_png(board_big, BIG)
            _code_png(code_big, BIG)
            calibrate = [*qrfield, "calibrate", "--board", "9x6", "--square-mm", "25", "--force"]
            solve = [*qrfield, "solve", "--side-mm", "50", "--json"]
            cases = (
                ("49 MP noise (no board)", "calibrate", big_noise, board_small, calibrate),
                ("49 MP board", "calibrate", board_big, board_small, calibrate),
                ("49 MP noise (no code)", "solve", big_noise, small, solve),
                ("49 MP code", "solve", code_big, small, solve),
            )
            for label, name, big, base_image, argv in cases:
                extra = ["--out", str(folder / "c.json")] if name == "calibrate" else ["--focal-px", "6328"]
                base_extra = (
                    ["--out", str(folder / "c.json")] if name == "calibrate" else ["--focal-px", "500"]
                )
                run_big = run_measured([*argv, str(big), *extra], folder)
                run_base = run_measured([*argv, str(base_image), *base_extra], folder)
                lines.append(_row(label, name, run_big, run_base, IMAGE_TARGET_MB))
                print(lines[-1], flush=True)
        if "png" in parts:
            bomb = folder / "inflating.png"
            _inflating_png(bomb, BIG, args.bomb_mb)
            plain = folder / "plain49.png"
            _inflating_png(plain, BIG, 0)
            solve = [*qrfield, "solve", "--side-mm", "50", "--focal-px", "6328"]
            run_bomb, run_plain = (
                run_measured([*solve, str(bomb)], folder),
                run_measured([*solve, str(plain)], folder),
            )
            label = f"49 MP PNG inflating to +{args.bomb_mb} MB"
            lines.append(_row(label, "solve", run_bomb, run_plain, IMAGE_TARGET_MB))
            print(lines[-1], flush=True)
            ratio = run_bomb.cpu_s / run_plain.cpu_s if run_plain.cpu_s else float("inf")
            verdict = "met" if ratio <= 1.5 else "NOT met"
            print(
                f"  CPU of the inflating PNG / the plain one: {ratio:.2f} (target <= 1.5: {verdict})",
                flush=True,
            )
        if "sessions" in parts:
            roots = folder / "large", folder / "small"
            large = _session(roots[0], "large", args.rows_mib)
            small_session = _session(roots[1], "small", 0)
            size = (large / "rows.csv").stat().st_size
            label = f"rows.csv of {size / (1 << 20):.0f} MiB"
            session = [*qrfield, "session"]
            log = [
                "--truth",
                "virtual",
                "--combo",
                "alpha+beta-gamma+",
                "--source",
                "virtual",
                "--frames",
                "1",
            ]
            commands = (
                ("list", lambda f, r: [*session, "list", str(r)]),
                ("show", lambda f, r: [*session, "show", str(f)]),
                ("export", lambda f, r: [*session, "export", str(f), "--force"]),
                ("undo", lambda f, r: [*session, "undo", str(f)]),
                ("log", lambda f, r: [*session, "log", str(f), *log, *env_cfg]),
            )
            for name, argv in commands:
                run_large = run_measured(argv(large, roots[0]), folder)
                run_small = run_measured(argv(small_session, roots[1]), folder)
                # `log` runs the frame loop (the virtual bench, the detector, the solvers): some 115 MB
                # with a one-row session; what the large file may add to it is SESSION_EXTRA_MB.
                extra = SESSION_EXTRA_MB if name == "log" else 0.0
                lines.append(_row(label, f"session {name}", run_large, run_small, SESSION_TARGET_MB, extra))
                print(lines[-1], flush=True)
    print(
        f"targets: images under {IMAGE_TARGET_MB:.0f} MB, sessions under {SESSION_TARGET_MB:.0f} MB "
        f"({sum('NOT met' in line for line in lines)} of {len(lines)} not met)"
    )
    return 0
