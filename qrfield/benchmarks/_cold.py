"""Sections 5-7 of ``qrfield benchmark detect``: a cold detection beside zxing-cpp and OpenCV Aruco.

5. Cold detection (``Detector.detect`` on a frame nothing was tracked in) against zxing-cpp's
   QR-only ``read_barcodes`` and OpenCV's ``QRCodeDetectorAruco.detectAndDecodeMulti`` on the same
   frames: the hard set's views (640x480), the benchmark's moving sequence and the real photos.
   CPU time (``time.process_time``) of each call, the three interleaved frame by frame, ``rounds``
   rounds; per set the median over the rounds of the mean per frame, the ratio and its spread over
   the rounds, the machine's load before and after; then where qrfield's time goes (cProfile's
   cumulative time of its steps over one pass, as shares).
6. Several codes in one 1280x720 frame (1, 2, 4 and 8; qrfield.testing.hardset.multi_view):
   CPU ms per frame (the code counts interleaved frame by frame within each round), codes found
   (right text, corners within 0.5 px, reported good), and the cost against one code with the
   spread of the rounds' own ratios.
7. The share found by foreshortened module size (the code's shortest side over its modules) on
   the steep set (qrfield.testing.hardset.steep_view: alpha and beta each up to 55 deg): found
   with the right text and refined, reported good, reported good with a corner more than 0.5 px off;
   zxing-cpp's and OpenCV Aruco's share with the right text.

Not a benchmark of its own (the leading underscore keeps it out of ``qrfield benchmark``).
"""

from __future__ import annotations

import cProfile
import os
import pstats
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

#: Bands of the foreshortened module size, px (section 7).
STEEP_BANDS = ((0.0, 1.2), (1.2, 1.5), (1.5, 2.0), (2.0, 3.0), (3.0, float("inf")))
#: Codes per frame of section 6.
CODE_COUNTS = (1, 2, 4, 8)
#: A corner further off than this, px, is not a code found.
FOUND_PX = 0.5
#: The steps of a cold detection whose cumulative time is reported (function names in qrfield.detect).
STEPS = (
    ("zxing-cpp (the first backend)", "backends.py", "_zxing"),
    ("zxing-cpp on the image upscaled 2x", "backends.py", "_zxing_x2"),
    ("finder patterns by contours", "backends.py", "_finders"),
    ("the small backend", "backends.py", "_small"),
    ("reading located codes (least squares)", "detector.py", "read"),
    ("pattern checks", "patterns.py", "check_patterns"),
    ("cold refinement (inverse composition)", "detector.py", "refine_cold"),
    ("  its coarse template", "symbol_cold.py", "coarse_fit"),
    ("  its pixel-centred template and step", "symbol_cold.py", "fine_fit"),
    ("the edge lines and the full fit (fallback)", "detector.py", "refine"),
)


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.1f} (1 min), {five:.1f} (5 min) on {os.cpu_count()} cores"


def _zxing() -> Callable[[np.ndarray], Any]:
    import zxingcpp

    formats = zxingcpp.BarcodeFormat.QRCode
    return lambda grey: zxingcpp.read_barcodes(grey, formats=formats)


def _aruco() -> Callable[[np.ndarray], Any] | None:
    import cv2

    if not hasattr(cv2, "QRCodeDetectorAruco"):
        return None
    detector = cv2.QRCodeDetectorAruco()
    # The bytes variant where there is one (OpenCV 4.12+): the text one raises on Shift-JIS payloads.
    decode = getattr(detector, "detectAndDecodeBytesMulti", None) or detector.detectAndDecodeMulti

    def run(grey: np.ndarray) -> Any:
        try:
            return decode(grey)
        except cv2.error:  # it raises on some real photos ("mode 13"): nothing found
            return False, (), None, None

    return run


def interleaved(
    frames: Sequence[np.ndarray], methods: dict[str, Callable[[np.ndarray], Any]], rounds: int
) -> dict[str, list[float]]:
    """CPU ms per frame of each method, per round: the methods one after the other on each frame
    (:func:`interleaved_groups` with one group)."""
    return interleaved_groups({0: frames}, methods, rounds)[0]


def interleaved_groups(
    groups: dict[int, Sequence[np.ndarray]], methods: dict[str, Callable[[np.ndarray], Any]], rounds: int
) -> dict[int, dict[str, list[float]]]:
    """CPU ms per frame of each method on each group of frames, per round: within a round frame i of
    every group in turn (the methods one after the other on each), so that a change of the machine's
    load during the run falls on every group alike (section 6: the groups are code counts, whose
    ratio to one code is the figure; timed group after group, two consecutive runs gave 2.99x and
    3.22x for four codes, and each group's frames followed frames of their own count:
    docs/detection.md, "Several codes' cost (issue-26m2)")."""
    out = {key: {name: [] for name in methods} for key in groups}
    longest = max((len(frames) for frames in groups.values()), default=0)
    for _ in range(rounds):
        spent = {key: dict.fromkeys(methods, 0.0) for key in groups}
        for index in range(longest):
            for key, frames in groups.items():
                if index >= len(frames):
                    continue
                for name, method in methods.items():
                    t = time.process_time()
                    method(frames[index])
                    spent[key][name] += time.process_time() - t
        for key, frames in groups.items():
            for name in methods:
                out[key][name].append(1e3 * spent[key][name] / max(len(frames), 1))
    return out


def _ratio_text(ms: dict[str, list[float]], name: str, base: str) -> str:
    per_round = [a / b for a, b in zip(ms[name], ms[base], strict=True) if b > 0]
    ratio = float(np.median(ms[name]) / np.median(ms[base]))
    return f"{ratio:5.1f}x ({min(per_round):.1f}-{max(per_round):.1f})"


def cold(sets: dict[str, tuple[list[np.ndarray], Any]], rounds: int) -> dict[str, float]:
    """Section 5. ``sets``: name -> (grey frames, camera model or None); returns qrfield's ratio
    to zxing-cpp per set."""
    from qrfield.detect import Detector, DetectorSettings

    zxing, aruco = _zxing(), _aruco()
    print(
        f"\n5. cold detection (Detector.detect, nothing tracked) beside zxing-cpp read_barcodes (QR only) "
        f"and OpenCV QRCodeDetectorAruco.detectAndDecodeMulti on the same frames: CPU ms per frame "
        f"(time.process_time), the three interleaved frame by frame, {rounds} rounds, the median round; "
        "x zxing: qrfield's time over zxing-cpp's (spread: round by round)"
    )
    print(f"   {_load()} (before)")
    print(
        f"{'frames':<44}{'n':>5}{'zxing ms':>10}{'aruco ms':>10}{'qrfield ms':>12}   "
        f"{'x zxing':<19}{'x aruco':<8}"
    )
    ratios = {}
    for name, (frames, camera) in sets.items():
        if not frames:
            continue
        detector = Detector(DetectorSettings(), camera=camera)
        methods: dict[str, Callable[[np.ndarray], Any]] = {"zxing": zxing, "qrfield": detector.detect}
        if aruco is not None:
            methods["aruco"] = aruco
        for method in methods.values():
            method(frames[0])  # warm caches (the lens' table, imports)
        ms = interleaved(frames, methods, rounds)
        ratios[name] = float(np.median(ms["qrfield"]) / np.median(ms["zxing"]))
        aruco_ms = f"{np.median(ms['aruco']):10.2f}" if "aruco" in ms else f"{'-':>10}"
        versus_aruco = f"{np.median(ms['qrfield']) / np.median(ms['aruco']):.1f}x" if "aruco" in ms else "-"
        print(
            f"{name:<44}{len(frames):>5}{np.median(ms['zxing']):10.2f}{aruco_ms}{np.median(ms['qrfield']):12.2f}"
            f"   {_ratio_text(ms, 'qrfield', 'zxing'):<19}{versus_aruco}"
        )
    print(f"   {_load()} (after)")
    return ratios


def where_time_goes(frames: Sequence[np.ndarray], camera: Any, label: str) -> None:
    """Section 5's breakdown: cProfile's cumulative time of each step over one pass of ``frames``,
    as a share of the detection's (steps nest: the refinement holds its pattern checks)."""
    from qrfield.detect import Detector, DetectorSettings

    detector = Detector(DetectorSettings(), camera=camera)
    detector.detect(frames[0])
    profile = cProfile.Profile()
    profile.enable()
    for frame in frames:
        detector.detect(frame)
    profile.disable()
    stats = pstats.Stats(profile).stats  # type: ignore[attr-defined]
    total = sum(v[3] for k, v in stats.items() if k[2] == "detect" and k[0].endswith("detector.py"))
    shares = []
    for text, filename, function in STEPS:
        cumulative = sum(v[3] for k, v in stats.items() if k[2] == function and k[0].endswith(filename))
        if cumulative > 0:
            shares.append(f"{text} {100 * cumulative / total:.0f} %")
    print(
        f"   where the time goes ({label}; cProfile, cumulative, share of Detector.detect): "
        + "; ".join(shares)
    )


def several_codes(frames_per_count: int, seed: int, rounds: int) -> dict[int, float]:
    """Section 6; returns the cost of each count's frames over the one-code frames' (qrfield)."""
    from qrfield.detect import Detector, DetectorSettings
    from qrfield.detect.detection import GOOD_QUALITY
    from qrfield.testing.hardset import multi_view

    zxing, aruco = _zxing(), _aruco()
    t0 = time.perf_counter()
    views = {k: [multi_view(i, k, seed) for i in range(frames_per_count)] for k in CODE_COUNTS}
    camera = views[1][0].camera
    print(
        f"\n6. several codes in one {camera.width}x{camera.height} frame "
        f"({frames_per_count} frames per count, "
        f"seed {seed}; qrfield.testing.hardset.multi_view, made in {time.perf_counter() - t0:.0f} s): "
        f"CPU ms per frame, the median of {rounds} rounds, the methods and the code counts interleaved "
        f"frame by frame; x one code: the ratio of the medians (the rounds' own ratios); found: right "
        f"text, corners within {FOUND_PX:g} px, reported good"
    )
    print(f"   {_load()}")
    detector = Detector(DetectorSettings(), camera=camera)
    print(
        f"{'codes':>6}{'zxing ms':>10}{'aruco ms':>10}{'qrfield ms':>12}{'x zxing':>9}{'found':>11}"
        f"{'x one code':>12}  rounds"
    )
    methods: dict[str, Callable[[np.ndarray], Any]] = {"zxing": zxing, "qrfield": detector.detect}
    if aruco is not None:
        methods["aruco"] = aruco
    timed = interleaved_groups({k: [v.image for v in frames] for k, frames in views.items()}, methods, rounds)
    cost: dict[int, float] = {}
    for count, frames in views.items():
        ms = timed[count]
        found = total = 0
        for view in frames:
            detections = detector.detect(view.image)
            for corners, text in zip(view.corners_px, view.texts, strict=True):
                total += 1
                found += any(
                    d.text == text
                    and d.refined
                    and d.quality >= GOOD_QUALITY
                    and float(np.linalg.norm(d.corners_px - corners, axis=1).max()) < FOUND_PX
                    for d in detections
                )
        cost[count] = float(np.median(ms["qrfield"]))
        aruco_ms = f"{np.median(ms['aruco']):10.2f}" if "aruco" in ms else f"{'-':>10}"
        per_round = [a / b for a, b in zip(ms["qrfield"], timed[1]["qrfield"], strict=True) if b > 0]
        spread = f"  {min(per_round):.2f}-{max(per_round):.2f}" if per_round else ""
        print(
            f"{count:>6}{np.median(ms['zxing']):10.2f}{aruco_ms}{cost[count]:12.2f}"
            f"{cost[count] / np.median(ms['zxing']):8.1f}x{found:>6}/{total:<4}{cost[count] / cost[1]:11.2f}x"
            f"{spread}"
        )
    return {k: v / cost[1] for k, v in cost.items()}


def by_module_size(views: Sequence[Any]) -> None:
    """Section 7 on ``views`` (HardView, e.g. the steep set)."""
    from qrfield.detect import Detector, DetectorSettings
    from qrfield.detect.detection import GOOD_QUALITY

    zxing, aruco = _zxing(), _aruco()
    detectors: dict[str, Any] = {}
    rows = []
    for view in views:
        detector = detectors.get(view.camera.name)
        if detector is None:
            detector = detectors[view.camera.name] = Detector(DetectorSettings(), camera=view.camera)
        found = [d for d in detector.detect(view.image) if d.text == view.text and d.refined]
        errors = [float(np.linalg.norm(d.corners_px - view.corners_px, axis=1).max()) for d in found]
        good = [e for d, e in zip(found, errors, strict=True) if d.quality >= GOOD_QUALITY]
        wrong_good = any(e > FOUND_PX for e in good)
        by_zxing = any(b.valid and b.text == view.text for b in zxing(view.image))
        by_aruco = False
        if aruco is not None:
            ok, texts, _, _ = aruco(view.image)
            by_aruco = bool(ok) and any(
                (t if isinstance(t, str) else bytes(t).decode("latin-1")) == view.text for t in texts
            )
        right = any(e <= FOUND_PX for e in errors)
        rows.append((view.module_px, right, any(e <= FOUND_PX for e in good), wrong_good, by_zxing, by_aruco))
    data = np.array(rows, dtype=float)
    print(
        "\n7. share found by foreshortened module size (the code's shortest side over its modules) on "
        f"{len(views)} "
        "views of the steep set (qrfield.testing.hardset.steep_view: alpha and beta each up to 55 deg, "
        "z 150-600 mm, pinhole and distorted); found: right text, refined, corners within "
        f"{FOUND_PX:g} px"
    )
    print(
        f"{'module px':<12}{'views':>6}{'qrfield found':>15}{'good':>8}{'good, >0.5 px off':>19}"
        f"{'zxing-cpp':>11}{'aruco':>8}"
    )
    for low, high in STEEP_BANDS:
        band = data[(data[:, 0] >= low) & (data[:, 0] < high)]
        label = f"{low:g}-{high:g}" if np.isfinite(high) else f">= {low:g}"
        if not len(band):
            print(f"{label:<12}{0:>6}")
            continue
        share = band[:, 1:].mean(axis=0) * 100
        print(
            f"{label:<12}{len(band):>6}{share[0]:14.1f}%{share[1]:7.1f}%{int(band[:, 3].sum()):>19}"
            f"{share[3]:10.1f}%{share[4]:7.1f}%"
        )
