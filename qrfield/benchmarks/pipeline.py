"""``qrfield benchmark pipeline``: frames per second of the whole measurement on the virtual bench.

For 640x480 and 1280x720, from one run:
  - render only (baseline): the virtual bench producing frames, nothing else;
  - headless: the loop of ``qrfield run`` (read, detect, select, solve), one frame after another;
  - GUI: the bench app offscreen (worker thread processing, window redrawing on its timer):
    frames processed per second by the worker and frames drawn per second by the window.
Also the mean detect and solve times and the capture-to-result latency of the headless loop.
"""

from __future__ import annotations

import argparse
import os
import time

from qrfield.methods import BOTH, METHOD_CHOICES, methods_from_choice
from qrfield.status import ResultStatus

HELP = "time the measurement pipeline on the virtual bench (headless and with the GUI redrawing)"

CAMERAS = ("picam-v2@640x480", "webcam-60@1280x720")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import seconds

    parser.add_argument(
        "--seconds", type=seconds("--seconds"), default=3.0, help="measuring time per figure (default 3)"
    )
    parser.add_argument("--method", choices=METHOD_CHOICES, default=BOTH)
    parser.add_argument("--no-gui", action="store_true", help="skip the GUI figures")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from qrfield.camera import resolve_camera
    from qrfield.pipeline import Pipeline
    from qrfield.sources import VirtualBenchSettings, VirtualBenchSource

    methods = methods_from_choice(args.method)
    bench = VirtualBenchSettings(fps=0.0)  # as fast as it renders
    print(
        f"qrfield benchmark pipeline: virtual bench, 50 mm code at {bench.pose.position_mm.tolist()} mm, "
        f"{bench.pose.angles_deg.tolist()} deg, noise {bench.noise_sigma}, blur {bench.blur_px}; "
        f"method {args.method}; {args.seconds:g} s per figure; {os.cpu_count()} CPUs"
    )
    header = (
        f"{'camera':<22}{'render fps':>11}{'headless fps':>13}{'ratio':>7}{'GUI fps':>9}{'GUI drawn':>10}"
    )
    header += f"{'detect ms':>10}{'solve ms':>9}{'latency ms':>11}"
    print(header)
    for spec in CAMERAS:
        camera = resolve_camera(spec)
        with VirtualBenchSource(camera, 50.0, bench) as source:
            source.read()  # warm the renderer's caches
            pipeline = Pipeline(camera, 50.0, methods)
            results: list = []
            render_fps, headless_fps = _interleaved_rates(
                source.read,
                lambda p=pipeline, out=results, s=source: out.append(p.process(s.read())),
                args.seconds,
            )
        ok = sum(r.status == ResultStatus.OK for r in results)
        detect_ms = float(np.mean([r.detect_ms for r in results]))
        solve_ms = float(np.mean([r.solve_ms for r in results]))
        latency_ms = float(np.mean([r.latency_ms for r in results]))
        gui = (
            ("-", "-")
            if args.no_gui
            else tuple(f"{v:.1f}" for v in _gui_rates(spec, args.method, args.seconds))
        )
        print(
            f"{spec:<22}{render_fps:>11.1f}{headless_fps:>13.1f}{headless_fps / render_fps:>7.2f}"
            f"{gui[0]:>9}{gui[1]:>10}{detect_ms:>10.1f}{solve_ms:>9.2f}{latency_ms:>11.1f}"
            + ("" if ok == len(results) else f"  ({len(results) - ok} of {len(results)} frames not OK)")
        )
    print(
        "ratio = headless / render-only fps, measured in alternating slices (1.0: detection and solving free)"
    )
    print("GUI fps = frames the worker processed per s (rendering overlaps processing on its reader thread);")
    print(
        "GUI drawn = frames the window drew per s (newer results replace undrawn ones: dropped, not queued)"
    )
    return 0


def _interleaved_rates(baseline, step, seconds: float, slice_s: float = 0.25) -> tuple[float, float]:
    """Calls per second of ``baseline`` and of ``step``, measured in alternating slices of
    ``slice_s`` for about ``seconds`` each, so that a change in machine load hits both alike."""
    counts, times = [0, 0], [0.0, 0.0]
    while min(times) < seconds:
        for k, call in enumerate((baseline, step)):
            t0 = time.perf_counter()
            while True:
                call()
                counts[k] += 1
                elapsed = time.perf_counter() - t0
                if elapsed >= slice_s:
                    break
            times[k] += elapsed
    return counts[0] / times[0], counts[1] / times[1]


def _gui_rates(camera: str, method: str, seconds: float) -> tuple[float, float]:
    """The app's rates, measured by ui.gui_rates (the core never imports Qt itself, like ``qrfield gui``)."""
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from ui.gui_rates import gui_rates

    return gui_rates(camera, method, seconds)
