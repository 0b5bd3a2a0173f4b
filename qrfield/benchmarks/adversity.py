"""``qrfield benchmark adversity``: the detector and the pose on the adversity set
(:mod:`qrfield.testing.adversity`: motion blur, JPEG, versions 11-25, inverted and mirrored codes,
occlusion, glare, two codes alike, a neighbouring code), against the drawn truth.

Per condition: the share of views whose code was found and found good (``Detection.quality`` >=
GOOD_QUALITY and refined), the 90th percentile of the worst corner's error of the good ones (px),
and above all what was wrong but not said so:

- ``bad good``: a detection reported good whose worst corner is more than BAD_CORNER_PX off its
  code's truth, or whose text is not its code's, or that lies on no code;
- ``>4 sd``: a detection reported good with a corner outside FAR_SIGMA of its own covariance
  (Mahalanobis distance) and more than FAR_MIN_PX off;
- ``bad pose``: a converged pose (``qrfield.solvers.solve`` with the detection's corners and
  ``Detection.pose_cov``, the pipeline's way; unrefined detections give none, as in the pipeline)
  off by more than 2 degrees on an angle or 5 mm in position and, on that component, more than
  FAR_SIGMA of its own std, while neither ``ambiguous`` nor ``misfit``;
- ``crash``: an exception from the detector (the solver's SolverError is a refusal, counted apart).

A miss, or a wrong answer with a clear flag, is not a defect; a confident wrong answer is.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

HELP = (
    "the detector and pose on the adversity set (motion blur, JPEG, versions 11-25, inverted, "
    "mirrored, occlusion, glare, twin and neighbouring codes): found, good, confident wrong answers"
)

#: A corner further off than this (px) must not be reported good (as the hard set's rule).
BAD_CORNER_PX = 0.5
#: A good corner outside this many of its own std, and further off than FAR_MIN_PX, is counted.
FAR_SIGMA = 4.0
FAR_MIN_PX = 0.1
#: The seed's acceptance criteria (docs/conventions.md): the pose is wrong beyond these.
ANGLE_LIMIT_DEG = 2.0
POSITION_LIMIT_MM = 5.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import count, seed
    from qrfield.limits import MAX_BENCHMARK_COUNT
    from qrfield.testing.adversity import CONDITIONS

    parser.add_argument(
        "--views",
        type=count("--views", 0, MAX_BENCHMARK_COUNT),
        default=40,
        help="views per condition (default 40; even pinhole, odd distorted)",
    )
    parser.add_argument("--seed", type=seed("--seed"), default=3031, help="seed of the set (default 3031)")
    parser.add_argument(
        "--conditions",
        default=",".join(CONDITIONS),
        help=f"conditions to run, comma-separated (default all: {','.join(CONDITIONS)})",
    )
    parser.add_argument("--list", action="store_true", help="print every defect's view (condition, index)")


def _nearest(detection, codes) -> tuple[int, float]:
    """Index of the code whose centre is nearest the detection's, and the worst corner's error (px)
    against it; (-1, inf) when no code's centre lies within a quarter of its size."""
    centre = detection.corners_px.mean(axis=0)
    best, best_d = -1, np.inf
    for k, code in enumerate(codes):
        size = float(np.linalg.norm(code.corners_px[2] - code.corners_px[0]))
        d = float(np.linalg.norm(centre - code.corners_px.mean(axis=0)))
        if d < 0.25 * size and d < best_d:
            best, best_d = k, d
    if best < 0:
        return -1, np.inf
    return best, float(np.linalg.norm(detection.corners_px - codes[best].corners_px, axis=1).max())


def _mahalanobis(diff: np.ndarray, cov: np.ndarray | None) -> float:
    """Largest Mahalanobis distance of the four corners' errors ``diff`` (4, 2) under ``cov``."""
    if cov is None:
        return np.nan
    out = 0.0
    for k in range(4):
        try:
            out = max(out, float(np.sqrt(diff[k] @ np.linalg.solve(cov[k], diff[k]))))
        except np.linalg.LinAlgError:
            return np.inf
    return out


def _pose_wrong(pose, code) -> bool:
    """A converged, unflagged pose off by more than the criteria and FAR_SIGMA of its std."""
    from qrfield.geometry import angle_difference

    if not pose.converged or pose.ambiguous or pose.misfit:
        return False
    angle_err = np.abs(angle_difference(pose.angles_deg, code.pose.angles_deg))
    pos_err = np.abs(pose.position_mm - code.pose.position_mm)
    off = bool(angle_err.max() > ANGLE_LIMIT_DEG or np.linalg.norm(pos_err) > POSITION_LIMIT_MM)
    if not off:
        return False
    std = np.concatenate([pose.position_std_mm, pose.angles_std_deg])
    err = np.concatenate([pos_err, angle_err])
    with np.errstate(invalid="ignore", divide="ignore"):
        beyond = np.where(np.isfinite(std) & (std > 0), err / std, np.inf)
    return bool(np.any(beyond > FAR_SIGMA))


def evaluate(view, detector) -> dict:
    """One view's outcome: found/good (the first code), its worst corner error when good, and the
    defects (counts) over every detection."""
    from qrfield.detect.detection import GOOD_QUALITY
    from qrfield.solvers import SolverError, solve

    out = {"found": False, "good": False, "error": np.nan, "bad_good": 0, "far": 0, "bad_pose": 0}
    out.update({"crash": 0, "refused": 0, "both": False, "notes": []})
    try:
        detections = detector.detect(view.image)
    except Exception as exc:  # a crash is a defect; the report says which
        out["crash"] = 1
        out["notes"].append(f"crash {type(exc).__name__}: {exc}")
        return out
    on: set[int] = set()
    for d in detections:
        k, err = _nearest(d, view.codes)
        good = bool(d.refined and d.quality >= GOOD_QUALITY)
        if k < 0:
            out["bad_good"] += good
            if good:
                out["notes"].append("good detection on no code")
            continue
        code = view.codes[k]
        text_ok = d.text == code.text
        on.add(k)
        if k == 0 or view.condition == "twins":  # twins: either is the code
            out["found"] = True
            if good and not (out["good"] and out["error"] <= err):
                out["good"], out["error"] = True, err
        if good and (err > BAD_CORNER_PX or (d.text is not None and not text_ok)):
            out["bad_good"] += 1
            out["notes"].append(f"good, corners {err:.2f} px off, text {'ok' if text_ok else 'WRONG'}")
        if (
            good
            and err > FAR_MIN_PX
            and _mahalanobis(d.corners_px - code.corners_px, d.corners_cov) > FAR_SIGMA
        ):
            out["far"] += 1
            out["notes"].append(f"good, corners {err:.2f} px off, outside {FAR_SIGMA:g} sd")
        if not d.refined:
            continue  # untrusted: the pipeline gives no pose from it
        try:
            pose = solve(d.corners_px, view.camera, code.side_mm, corners_cov=d.pose_cov)
        except SolverError as exc:
            out["refused"] += 1
            out["notes"].append(f"solve refused: {exc}"[:120])
            continue
        if _pose_wrong(pose, code):
            out["bad_pose"] += 1
            angle_err = np.abs((pose.angles_deg - code.pose.angles_deg + 180.0) % 360.0 - 180.0).max()
            pos_err = float(np.linalg.norm(pose.position_mm - code.pose.position_mm))
            out["notes"].append(
                f"pose off {angle_err:.1f} deg / {pos_err:.1f} mm unflagged "
                f"(corners {err:.2f} px, q {d.quality:.2f})"
            )
    out["both"] = on >= set(range(len(view.codes)))
    return out


def run(args: argparse.Namespace) -> int:
    from qrfield.detect import Detector
    from qrfield.testing.adversity import CONDITIONS, adversity_views

    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    unknown = [c for c in conditions if c not in CONDITIONS]
    if unknown:
        print(f"unknown condition(s) {', '.join(unknown)}; choose from {', '.join(CONDITIONS)}")
        return 2
    try:
        import segno  # noqa: F401
    except ImportError:
        print("the adversity set needs the segno package (the dev extra); skipped")
        return 0
    print(
        f"qrfield benchmark adversity: {args.views} views per condition, seed {args.seed} "
        "(qrfield.testing.adversity; even views pinhole, odd distorted), default detector"
    )
    print(
        f"{'condition':<11}{'found':>7}{'good':>7}{'p90 px':>8}{'bad good':>10}{'>4 sd':>7}"
        f"{'bad pose':>10}{'crash':>7}{'refused':>9}{'all codes':>11}{'s/view':>8}"
    )
    detectors: dict[str, Detector] = {}
    listed = []
    totals = np.zeros(4, int)
    for condition in conditions:
        rows = []
        t_make = t_detect = 0.0
        for view in _timed_views(adversity_views(condition, args.views, args.seed)):
            t_make += view[1]
            view = view[0]
            detector = detectors.get(view.camera.name)
            if detector is None:
                detector = detectors[view.camera.name] = Detector(camera=view.camera)
            t0 = time.perf_counter()
            result = evaluate(view, detector)
            t_detect += time.perf_counter() - t0
            rows.append(result)
            if result["notes"]:
                listed.append((condition, view.index, view.detail, result["notes"]))
        n = max(len(rows), 1)
        found = sum(r["found"] for r in rows)
        good = sum(r["good"] for r in rows)
        errors = np.array([r["error"] for r in rows if r["good"]])
        p90 = f"{np.percentile(errors, 90):.3f}" if errors.size else "-"
        counts = [sum(r[k] for r in rows) for k in ("bad_good", "far", "bad_pose", "crash")]
        totals += counts
        refused = sum(r["refused"] for r in rows)
        both = sum(r["both"] for r in rows)
        print(
            f"{condition:<11}{100 * found / n:>6.0f}%{100 * good / n:>6.0f}%{p90:>8}{counts[0]:>10}"
            f"{counts[1]:>7}{counts[2]:>10}{counts[3]:>7}{refused:>9}{both:>7}/{len(rows):<3}"
            f"{(t_make + t_detect) / n:>8.2f}"
        )
    print(
        "found/good: the (first; twins: either) code found / found with quality >= 0.85 (refined); "
        "p90: 90th pct of "
        "the good ones' worst corner error; bad good: good but a corner > 0.5 px off or another "
        "text; >4 sd: good, a corner > 0.1 px off and outside 4 sd of its covariance; bad pose: a "
        "converged pose > 2 deg / 5 mm and > 4 sd off, neither ambiguous nor misfit; refused: "
        "SolverError; all codes: views where every code in view was found (twins, neighbour: both)"
    )
    print(
        "target: bad good, bad pose and crash 0 in every condition "
        f"(now {totals[0]}, {totals[2]}, {totals[3]})"
    )
    if args.list:
        for condition, index, detail, notes in listed:
            print(f"  {condition} {index} ({detail}): " + "; ".join(notes))
    return 0


def _timed_views(views):
    """(view, seconds to make it) for each view of the iterator ``views``."""
    while True:
        t0 = time.perf_counter()
        try:
            view = next(views)
        except StopIteration:
            return
        yield view, time.perf_counter() - t0
