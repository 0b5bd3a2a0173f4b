"""``qrfield benchmark detect``: corner accuracy, uncertainty, speed and detection rates, in one run.

0. The hard set (qrfield.testing.hardset: segno symbols of versions 1-10, 30/50/100 mm codes at
   z 150-1000 mm, tilt up to 60 deg, noise 0-4, blur 0.3-1.2 px, lighting gradients, pinhole and
   a distorted lens; its truth does not come from qrfield.render): per corner V1..V4 the median,
   90th percentile and largest error by module size band, pinhole and distorted apart, for the
   default pipeline and for the edge-line refinement alone (``symbol_fit`` off, the previous
   default); views with a corner more than 0.5 px off that were reported good; the calibration of
   the corners' covariance (whitened errors: RMS and share within 2).
1. Corner accuracy on seeded views of qrfield's own renderer (noise sigma 2 grey levels, blur
   0.6 px): RMS corner error for plain OpenCV, each backend's own corners, and the pipeline.
2. Milliseconds per frame (the best of ``--repeats`` rounds, wall clock, with the spread of the
   ratio over the rounds, and the CPU time of this process) on a moving rendered sequence at
   640x480 and 1280x720: the naive ``cv2.QRCodeDetector().detectAndDecode`` (the baseline,
   measured in the same rounds), full-frame detection without refinement, detection +
   refinement, tracking, and the default pipeline (Pipeline.process: tracking + the solve with
   the pose's uncertainty, numerical alone and both methods as the app runs them); the tracked
   corners' error and the calibration of their covariance on that sequence.
3. Detection rate on the real photos in ../shared/data/qr-photos (payload text as label) for each
   backend alone (its own answer, unchecked) and through the pipeline, and false detections on
   photos without any code (the chessboards in ../shared/data/calibration) and blank frames.
4. Detection rate on the rendered views of (1).
5-7. A cold detection beside zxing-cpp (QR only) and OpenCV Aruco, CPU time, interleaved, with the
   machine's load and where the time goes; several codes in one 1280x720 frame; the share found by
   foreshortened module size on the steep set (qrfield/benchmarks/_cold.py).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from qrfield.methods import BOTH, NUMERICAL
from qrfield.status import ResultStatus
from qrfield.testing.shared_data import shared_data_dir

#: Timing rounds per resolution; the fastest round counts (the same rule for the baseline).
REPEATS = 5

HELP = (
    "QR detection: corner accuracy on the hard set and on rendered views, covariance calibration, "
    "ms per frame vs naive OpenCV, detection rates (rendered and real photos)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, limited, seed
    from qrfield.limits import MAX_BENCHMARK_COUNT, SIDE_MM

    parser.add_argument(
        "--views",
        type=count("--views", 0, MAX_BENCHMARK_COUNT),
        default=200,
        help="rendered views for accuracy and rate (default 200)",
    )
    parser.add_argument(
        "--frames",
        type=count("--frames", 0, MAX_BENCHMARK_COUNT),
        default=60,
        help="frames of the moving sequence per resolution (default 60)",
    )
    parser.add_argument(
        "--side-mm",
        type=limited(SIDE_MM, "--side-mm"),
        default=100.0,
        help="QR side of the rendered code, mm (default 100)",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=1)
    parser.add_argument(
        "--hard-views",
        type=count("--hard-views", 0, MAX_BENCHMARK_COUNT),
        default=400,
        help="views of the hard set (default 400; 0 skips it)",
    )
    parser.add_argument(
        "--hard-seed", type=seed("--hard-seed"), default=2024, help="seed of the hard set (default 2024)"
    )
    parser.add_argument(
        "--hard-sequences",
        type=count("--hard-sequences", 0, MAX_BENCHMARK_COUNT),
        default=4,
        help="tracked moving sequences of 60 frames drawn like the hard set (default 4: two a lens; 0 skips)",
    )
    parser.add_argument(
        "--repeats",
        type=count("--repeats", 0, MAX_BENCHMARK_COUNT),
        default=REPEATS,
        help=f"timing rounds per resolution (default {REPEATS})",
    )
    parser.add_argument("--data", type=Path, default=None, help="shared data folder (default ../shared/data)")
    parser.add_argument(
        "--cold-rounds", type=int, default=5, help="interleaved rounds of the cold detection (5; 0 skips 5-6)"
    )
    parser.add_argument(
        "--multi-frames", type=int, default=6, help="frames per code count of section 6 (default 6; 0 skips)"
    )
    parser.add_argument(
        "--steep-views", type=int, default=300, help="views of the steep set (default 300; 0 skips)"
    )
    parser.add_argument("--steep-seed", type=int, default=2026, help="seed of the steep set (default 2026)")
    parser.add_argument(
        "--sections",
        default="0,1,2,2b,3,4,5,6,7",
        help="sections to run, comma-separated (default all: 0,1,2,2b,3,4,5,6,7)",
    )


def _made(make, label: str) -> list:
    """``make()``'s views (a list), or an empty list with a note when segno is missing."""
    try:
        import segno  # noqa: F401
    except ImportError:
        print(f"\n{label}: needs the segno package (pip install segno, or the dev extra); skipped")
        return []
    t0 = time.perf_counter()
    views = list(make())
    print(f"\n({label}: {len(views)} views made in {time.perf_counter() - t0:.0f} s)")
    return views


def _hard_set(views: list, seed: int) -> None:
    """Section 0: the hard set through the default pipeline and through the edge lines alone."""
    from qrfield.benchmarks import _corners
    from qrfield.detect import Detector, DetectorSettings

    print(
        f"\n0. hard set: {len(views)} views (seed {seed}; qrfield benchmark hardset describes it), "
        "per corner error against cv2.projectPoints' truth"
    )
    methods = {
        "default pipeline (whole-symbol fit)": DetectorSettings(),
        "edge lines only (symbol_fit off: the previous default)": DetectorSettings(symbol_fit=False),
    }
    for name, settings in methods.items():
        detectors: dict[str, Detector] = {}

        def detect(view, settings=settings, detectors=detectors):
            det = detectors.get(view.camera.name)
            if det is None:
                det = detectors[view.camera.name] = Detector(settings, camera=view.camera)
            return det.detect(view.image)

        t0 = time.perf_counter()
        results = _corners.evaluate(views, detect)
        ms = (time.perf_counter() - t0) * 1e3 / len(views)
        _corners.print_tables(f"{name}: {ms:.0f} ms a view", results)
        if settings.symbol_fit:
            _corners.print_calibration(results)
    print(
        "good: refined with quality >= 0.85; >0.5px: a corner more than 0.5 px off; "
        "wrong: another text read\n"
        "targets (modules >= 2 px): every corner's 90th pct <= 0.08 px and max <= 0.3 px, pinhole and "
        "distorted; no view with a corner > 0.5 px off reported good"
    )


def _hard_sequences(count: int, seed: int) -> None:
    """Section 2b: the tracker's corners (and a cold detection of every frame) on moving sequences
    drawn by the hard set's rasteriser, against cv2.projectPoints' truth: worst corner per frame,
    and the whitened errors of the reported covariance."""
    import numpy as np

    from qrfield.benchmarks._corners import calibration_text, whiten
    from qrfield.detect import Detector, DetectorSettings, Tracker
    from qrfield.testing.hardset import DISTORTED_CAMERA, _pinhole, hard_sequence

    try:
        import segno  # noqa: F401
    except ImportError:
        print("\n2b. tracked hard sequences: need the segno package; skipped")
        return
    print(
        f"\n2b. tracked corners on {count} moving sequences of 60 frames drawn like the hard set "
        f"(seed {seed}; qrfield.testing.hardset.hard_sequence; even pinhole, odd distorted), "
        "against cv2.projectPoints"
    )
    t0 = time.perf_counter()
    sequences = [list(hard_sequence(i, 60, seed)) for i in range(count)]
    print(f"   made in {time.perf_counter() - t0:.0f} s")
    print(
        f"{'lens':<10}{'method':<26}{'found':>9}   "
        "worst corner per frame: median / 90th pct / max px   covariance"
    )
    for lens, camera in (("pinhole", _pinhole()), ("distorted", DISTORTED_CAMERA)):
        chosen = [seq for i, seq in enumerate(sequences) if (i % 2 == 1) == (lens == "distorted")]
        if not chosen:
            continue
        for name in ("tracker (the pipeline's)", "cold detection per frame"):
            errors, whitened, frames = [], [], 0
            for seq in chosen:
                tracker = Tracker(DetectorSettings(), camera=camera)
                detector = Detector(DetectorSettings(), camera=camera)
                for image, truth in seq:
                    frames += 1
                    found = tracker.update(image) if name.startswith("tracker") else detector.detect(image)
                    if not found:
                        continue
                    diff = found[0].corners_px - truth
                    errors.append(float(np.linalg.norm(diff, axis=1).max()))
                    if found[0].corners_cov is not None:
                        whitened.extend(whiten(diff, found[0].corners_cov))
            e, z = np.array(errors), np.array(whitened)
            figures = f"{np.median(e):.3f} / {np.percentile(e, 90):.3f} / {e.max():.3f}" if e.size else "-"
            calibration = calibration_text(z) if z.size else "-"
            print(f"{lens:<10}{name:<26}{len(e):>5}/{frames:<3}   {figures:<49}{calibration}")


def _sequence(cam, side: float, count: int) -> tuple[list, list]:
    """The moving sequence of section 2 (BGR frames and their true corners)."""
    import numpy as np

    from qrfield.geometry import Pose
    from qrfield.render import render_view

    frames, truth = [], []
    for i in range(count):
        s = i / max(count - 1, 1)
        position = [-70.0 + 140.0 * s, -20.0 + 30.0 * s, 380.0 + 60.0 * np.sin(3 * s)]
        angles = [10.0 * np.sin(5 * s), -15.0 + 20 * s, 30.0 + 90.0 * s]
        view = render_view(
            cam, side, Pose(position, angles), noise_sigma=2.0, blur_px=0.6, seed=i, color=True
        )
        frames.append(view.image)
        truth.append(view.corners_px)
    return frames, truth


def _time_sequence(cam, side: float, count: int, repeats: int) -> bool:
    """Print ms per frame of each method on a seeded moving sequence seen by ``cam``, measured in
    ``repeats`` rounds (each round times every method once, the baseline first, so that each
    round's ratio compares like with like); returns whether the default pipeline is >= 10x."""
    import cv2
    import numpy as np

    from qrfield.benchmarks._corners import calibration_text, whiten
    from qrfield.detect import Detector, DetectorSettings, Tracker
    from qrfield.methods import METHODS
    from qrfield.pipeline import Pipeline
    from qrfield.sources.base import Frame

    frames, truth = _sequence(cam, side, count)
    full = Detector(DetectorSettings(refine=False))
    refined = Detector(DetectorSettings(), camera=cam)
    tracker = Tracker(DetectorSettings(), camera=cam)
    pipelines = {
        NUMERICAL: Pipeline(cam, side, METHODS[:1]),
        BOTH: Pipeline(cam, side, METHODS),
    }

    def naive(frame) -> bool:
        text, _, _ = cv2.QRCodeDetector().detectAndDecode(frame)
        return bool(text)

    def through(pipeline):
        def run(frame, index) -> bool:
            return pipeline.process(Frame(frame, time.monotonic(), index)).status == ResultStatus.OK

        return run

    rows = [
        ("naive cv2 detectAndDecode (baseline)", lambda f, i: naive(f), None),
        ("full-frame detection (no refine)", lambda f, i: bool(full.detect(f)), None),
        ("full-frame detect + refine", lambda f, i: bool(refined.detect(f)), None),
        ("tracked + refine", lambda f, i: bool(tracker.update(f)), tracker.reset),
        (
            "pipeline: tracked + refine + numerical",
            through(pipelines[NUMERICAL]),
            pipelines[NUMERICAL].reset,
        ),
        ("pipeline, both methods (the app's)", through(pipelines[BOTH]), pipelines[BOTH].reset),
    ]
    for _, method, _ in rows:
        method(frames[0], 0)  # warm caches
    wall = {name: [] for name, _, _ in rows}
    cpu = {name: [] for name, _, _ in rows}
    per_frame = {name: [] for name, _, _ in rows}  # each round's ms of every frame
    hits = {}
    for _ in range(repeats):
        for name, method, reset in rows:
            if reset is not None:
                reset()
            found, ms = 0, []
            t0, c0 = time.perf_counter(), time.process_time()
            for i, f in enumerate(frames):
                t = time.perf_counter()
                found += method(f, i)
                ms.append((time.perf_counter() - t) * 1e3)
            wall[name].append((time.perf_counter() - t0) * 1e3 / len(frames))
            cpu[name].append((time.process_time() - c0) * 1e3 / len(frames))
            per_frame[name].append(ms)
            hits[name] = found
    base = rows[0][0]
    ratios = {}
    for name, _, _ in rows:
        per_round = [b / m for b, m in zip(wall[base], wall[name], strict=True)]
        ratios[name] = min(wall[base]) / min(wall[name])
        print(
            f"{cam.name:<22}{name:<40}{min(wall[name]):>9.2f}{hits[name]:>5}/{len(frames):<3}"
            f"{ratios[name]:>7.1f}x {min(per_round):>5.1f}-{max(per_round):<5.1f}"
            f"{min(cpu[name]):>9.2f}{min(cpu[base]) / min(cpu[name]):>7.1f}x"
        )
    # Where a stream's time goes: its first two frames (the full-frame detection with the whole-symbol
    # fit, then the first tracked frame: the template is made and the move measured) and the rest.
    default = "pipeline: tracked + refine + numerical"
    best = min(range(repeats), key=lambda r: wall[default][r])
    ms = per_frame[default][best]
    rest = sum(ms[2:]) / max(len(ms) - 2, 1)
    print(
        f"{cam.name:<22}{default} (its best round): frame 1 {ms[0]:.1f} ms, frame 2 {ms[1]:.1f} ms, "
        f"the other {len(ms) - 2} frames {rest:.2f} ms a frame ({min(wall[base]) / rest:.1f}x naive)"
    )
    tracker.reset()
    errors, whitened = [], []
    for frame, true in zip(frames, truth, strict=True):
        found = tracker.update(frame)
        if found:
            diff = found[0].corners_px - true
            errors.append(float(np.linalg.norm(diff, axis=1).max()))
            if found[0].corners_cov is not None:
                whitened.extend(whiten(diff, found[0].corners_cov))
    if errors:
        e, z = np.array(errors), np.array(whitened)
        calibration = f"; their covariance: {calibration_text(z)}" if z.size else ""
        print(
            f"{cam.name:<22}tracked corners, worst per frame: median {np.median(e):.3f} px, "
            f"90th pct {np.percentile(e, 90):.3f} px, max {e.max():.3f} px ({len(e)} frames){calibration}"
        )
    return ratios["pipeline: tracked + refine + numerical"] >= 10.0


def _rendered(args: argparse.Namespace, show: bool) -> tuple[int, dict]:
    """Sections 1 and 4: views of qrfield's renderer; which method found which (and section 1's
    table of corner errors when ``show``). Returns the view count and the views found per method."""
    import cv2
    import numpy as np

    from qrfield.camera import resolve_camera
    from qrfield.detect import Detector, DetectorSettings
    from qrfield.detect.backends import BACKEND_NAMES, find_candidates
    from qrfield.render import render_view
    from qrfield.sampling import random_visible_poses

    side = args.side_mm
    camera = resolve_camera("picam-v2@640x480")
    poses = random_visible_poses(camera, side, args.views, seed=args.seed)
    views = [
        render_view(camera, side, p, noise_sigma=2.0, blur_px=0.6, seed=args.seed * 100003 + i)
        for i, p in enumerate(poses)
    ]

    def plain_opencv(grey):
        ok, pts = cv2.QRCodeDetector().detect(grey)
        return [pts.reshape(4, 2).astype(float)] if ok and pts is not None else []

    methods = {"plain OpenCV detect": plain_opencv}
    for name in BACKEND_NAMES:
        methods[f"{name} (own corners)"] = lambda g, name=name: [
            c.corners_px for c in find_candidates(g, name)
        ]
    pipeline = Detector(DetectorSettings())
    methods["default pipeline, refined"] = lambda g: [d.corners_px for d in pipeline.detect(g) if d.refined]
    methods["default pipeline, all"] = lambda g: [d.corners_px for d in pipeline.detect(g)]
    errors: dict[str, list[np.ndarray]] = {name: [] for name in methods}
    found_by: dict[str, set[int]] = {name: set() for name in methods}
    for i, view in enumerate(views):
        for name, method in methods.items():
            corners = method(view.image)
            if corners:
                best = min(corners, key=lambda c: np.abs(c - view.corners_px).max())
                errors[name].append(np.linalg.norm(best - view.corners_px, axis=1))
                found_by[name].add(i)
    if not show:
        return len(views), found_by
    print(
        f"\n1. corner accuracy: {len(views)} seeded views, {camera.name}, {side:g} mm code, z 150-800 mm, "
        "tilt <= 50 deg, noise 2, blur 0.6 px"
    )
    refined_idx = sorted(found_by["default pipeline, refined"])
    print(f"{'method':<34}{'found':>9}{'RMS px':>9}{'max px':>9}")
    for name in methods:
        e = np.concatenate(errors[name]) if errors[name] else np.array([np.nan])
        print(
            f"{name:<34}{len(found_by[name]):>5}/{len(views):<3}{np.sqrt(np.nanmean(e**2)):>9.3f}{np.nanmax(e):>9.3f}"
        )
    common = sorted(found_by["plain OpenCV detect"] & set(refined_idx))
    if common:
        ref_lookup = dict(zip(refined_idx, errors["default pipeline, refined"], strict=True))
        cv_lookup = dict(
            zip(sorted(found_by["plain OpenCV detect"]), errors["plain OpenCV detect"], strict=True)
        )
        cv_rms = np.sqrt(np.mean(np.concatenate([cv_lookup[i] for i in common]) ** 2))
        ref_rms = np.sqrt(np.mean(np.concatenate([ref_lookup[i] for i in common]) ** 2))
        print(
            f"on the {len(common)} views both found: plain OpenCV {cv_rms:.3f} px, refined {ref_rms:.3f} px"
        )
        print("target: refined <= 0.15 px")
    return len(views), found_by


def _speed(args: argparse.Namespace) -> None:
    """Section 2."""
    from qrfield.camera import resolve_camera

    side = args.side_mm
    print(
        f"\n2. ms per frame, moving sequence ({args.frames} BGR frames, {side:g} mm code, noise 2, blur 0.6),"
        f" {args.repeats} rounds: the best round's ms (wall clock), its ratio to the best baseline round,"
        " the spread of the ratio over the rounds, and the best CPU time (this process)"
    )
    print(
        "   pipeline = qrfield.pipeline.Pipeline.process per frame: the tracker (whole-symbol fit kept "
        "warm), the camera's lens, the solve with the detection's covariance (pose std, flip test)"
    )
    print(
        f"{'camera':<22}{'method':<40}{'ms/frame':>9}{'found':>9}{'x naive':>8} {'spread':<11}"
        f"{'cpu ms':>9}{'x naive':>8}"
    )
    met = {}
    for spec in ("picam-v2@640x480", "webcam-60@1280x720"):
        met[spec] = _time_sequence(resolve_camera(spec), side, args.frames, args.repeats)
    print(
        "target: the default pipeline (tracked + refine + solve with uncertainty) >= 10x the naive "
        f"throughput at 640x480: {'met' if met['picam-v2@640x480'] else 'NOT met'} (the numerical row)"
    )


def _photo_paths(data: Path | None) -> list[Path]:
    """The real photos in ``data``/qr-photos (each with its label beside it), [] without."""
    if data is None or not (data / "qr-photos").is_dir():
        return []
    return sorted(p for p in (data / "qr-photos").glob("*/*") if p.suffix in (".png", ".jpg"))


def _photos(data: Path | None) -> None:
    """Section 3."""
    import cv2
    import numpy as np

    from qrfield.detect import Detector, DetectorSettings
    from qrfield.detect.backends import BACKEND_NAMES, find_candidates
    from qrfield.detect.detector import as_grey

    photos = _photo_paths(data)
    if not photos:
        print("\n3. real photos: ../shared/data/qr-photos not found (give --data); skipped")
        return
    assert data is not None
    pipeline = Detector(DetectorSettings())
    print(f"\n3. real photos: {len(photos)} in {data / 'qr-photos'} (label = payload text)")
    print(f"{'method':<40}{'right':>7}{'other text':>12}{'none':>6}{'located':>9}")
    # A backend's own answer: the texts it decoded (a code located but not read counts as none).
    runs = {}
    for name in BACKEND_NAMES:
        runs[f"{name} alone, unchecked"] = lambda g, name=name: find_candidates(g, name)
    for name in BACKEND_NAMES:
        det = Detector(DetectorSettings(backends=name))
        runs[f"{name} alone, through the pipeline"] = det.detect
    runs["default pipeline"] = pipeline.detect
    for name, fn in runs.items():
        right = other = none = located = 0
        others = []
        for photo in photos:
            label = photo.with_suffix(".txt").read_bytes().decode("utf-8", errors="replace")
            grey = as_grey(cv2.imread(str(photo), cv2.IMREAD_COLOR))
            found = fn(grey)
            texts = [f.text for f in found if f.text]
            located += bool(found)
            right += label in texts
            if any(t != label for t in texts):
                other += 1
                others.append(photo.name)
            none += not texts
        note = f"  ({', '.join(others[:3])}{', ...' if len(others) > 3 else ''})" if others else ""
        print(f"{name:<40}{right:>4}/{len(photos):<3}{other:>8}{none:>8}{located:>7}{note}")
    print("right: the label's text was read; none: no text read; located: any code reported (read or not)")
    print("other text: qrcode-2/16.png holds two codes (an inner one, the label, inside an outer one);")
    print("  elsewhere a wrong or differently decoded text (OpenCV: Shift-JIS payloads read as bytes)")
    empty = sorted((data / "calibration").glob("*/*.jpg")) if (data / "calibration").is_dir() else []
    blanks = [
        np.zeros((480, 640), np.uint8),
        np.full((480, 640), 255, np.uint8),
        np.random.default_rng(0).integers(0, 256, (480, 640), dtype=np.uint8),
    ]
    false = sum(len(pipeline.detect(cv2.imread(str(p), cv2.IMREAD_COLOR))) for p in empty) + sum(
        len(pipeline.detect(b)) for b in blanks
    )
    print(f"codes reported on {len(empty)} photos without a code (chessboards) + 3 blank frames: {false}")


def _rates(total: int, found_by: dict) -> None:
    """Section 4."""
    from qrfield.detect.backends import BACKEND_NAMES

    print(f"\n4. detection rate on the {total} rendered views of (1):")
    for name in [
        "default pipeline, all",
        "plain OpenCV detect",
        *[f"{b} (own corners)" for b in BACKEND_NAMES],
    ]:
        hits = len(found_by[name])
        print(f"{name:<34}{hits:>5}/{total:<5}{100.0 * hits / total:6.1f} %")
    print("target >= 99 %")


def _cold_sections(args: argparse.Namespace, hard: list, sections: set[str]) -> None:
    """Sections 5-7 (qrfield/benchmarks/_cold.py) and their targets."""
    import cv2

    from qrfield.benchmarks import _cold
    from qrfield.camera import resolve_camera
    from qrfield.detect.detector import as_grey
    from qrfield.testing.hardset import steep_views

    targets = []
    if "5" in sections and args.cold_rounds > 0:
        sets: dict[str, tuple[list, object]] = {}
        for lens in ("pinhole", "distorted"):
            chosen = [v for v in hard if v.distorted == (lens == "distorted")]
            if chosen:
                sets[f"hard set, {lens} (640x480)"] = ([v.image for v in chosen], chosen[0].camera)
        read = []
        zxing = _cold._zxing()
        for v in hard:
            if any(b.valid and b.text == v.text for b in zxing(v.image)):
                read.append(v)
        for lens in ("pinhole", "distorted"):
            chosen = [v for v in read if v.distorted == (lens == "distorted")]
            if chosen:
                sets[f"  the views zxing-cpp reads, {lens}"] = ([v.image for v in chosen], chosen[0].camera)
        camera = resolve_camera("picam-v2@640x480")
        frames, _ = _sequence(camera, args.side_mm, args.frames)
        sets["moving sequence of (2), 640x480"] = ([as_grey(f) for f in frames], camera)
        photos = _photo_paths(shared_data_dir(args.data))
        sets["real photos (qr-photos, their own sizes)"] = (
            [as_grey(cv2.imread(str(p), cv2.IMREAD_COLOR)) for p in photos],
            None,
        )
        ratios = _cold.cold(sets, args.cold_rounds)
        if hard:
            pinhole = [v for v in hard if not v.distorted]
            _cold.where_time_goes([v.image for v in pinhole], pinhole[0].camera, "the hard set, pinhole")
        _cold.where_time_goes(sets["moving sequence of (2), 640x480"][0], camera, "the moving sequence")
        for name, ratio in ratios.items():
            if "640x480" in name or "zxing-cpp reads" in name:
                targets.append(f"cold detection, {name.strip()}: {ratio:.1f}x zxing-cpp (target <= 5x)")
    if "6" in sections and args.multi_frames > 0 and args.cold_rounds > 0:
        try:
            import segno  # noqa: F401
        except ImportError:
            print("\n6. several codes: needs the segno package; skipped")
        else:
            cost = _cold.several_codes(args.multi_frames, args.hard_seed, args.cold_rounds)
            targets.append(f"four codes in one frame: {cost[4]:.2f}x one code (target <= 3x, all four found)")
    if "7" in sections and args.steep_views > 0:
        steep = _made(lambda: steep_views(args.steep_views, args.steep_seed), "the steep set")
        if steep:
            _cold.by_module_size(steep)
    for line in targets:
        print(f"target: {line}")


def run(args: argparse.Namespace) -> int:
    from qrfield.detect import DetectorSettings
    from qrfield.testing.hardset import hard_views

    sections = {s.strip() for s in args.sections.split(",") if s.strip()}
    default = DetectorSettings()
    print(
        f"qrfield benchmark detect: default backends {default.backends!r}, refine {default.refine}, "
        f"whole-symbol fit {default.symbol_fit}; sections {','.join(sorted(sections))}"
    )
    print("(the machine is shared with other work: times are noisy; ratios come from the same run)")
    hard: list = []
    if args.hard_views > 0 and sections & {"0", "5"}:
        hard = _made(lambda: hard_views(args.hard_views, args.hard_seed), "the hard set")
    if "0" in sections and hard:
        _hard_set(hard, args.hard_seed)
    total, found_by = _rendered(args, "1" in sections) if sections & {"1", "4"} else (0, {})
    if "2" in sections:
        _speed(args)
    if "2b" in sections and args.hard_sequences > 0:
        _hard_sequences(args.hard_sequences, args.hard_seed)
    if "3" in sections:
        _photos(shared_data_dir(args.data))
    if "4" in sections:
        _rates(total, found_by)
    _cold_sections(args, hard, sections)
    return 0
