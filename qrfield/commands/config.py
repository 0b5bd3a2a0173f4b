"""``qrfield config``: the effective run configuration, and where each value came from.

The settings ``qrfield run`` and ``qrfield session log`` measure with: the file the app saves
(``<config folder>/app.json``), overridden by any option given here exactly as it would be given to
``qrfield run``. Each value is marked ``default``, ``config file`` or ``command line`` (with the
option that sets it). ``--json`` prints the same as one JSON object for programs.
"""

from __future__ import annotations

import argparse
import json
import sys

HELP = "print the effective settings of qrfield run (config file + options) and where each came from"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.runconfig import add_run_arguments

    parser.add_argument("--json", action="store_true", help="one JSON object instead of text")
    add_run_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from qrfield.runconfig import effective_settings

    effective = effective_settings(args)
    path = effective.store.path
    if args.json:
        out: dict = {"config_file": str(path), "exists": path.is_file(), "problems": effective.store.problems}
        for v in effective.values:
            out.setdefault(v.section, {})[v.name] = {"value": v.value, "origin": v.origin, "option": v.option}
        out["camera_model"] = effective.camera.to_dict()
        print(json.dumps(out, indent=2))
        return 0
    print(f"config file: {path} ({'read' if path.is_file() else 'not found: defaults and options only'})")
    for problem in effective.store.problems:
        print(f"  problem: {problem}")
    section = ""
    width = max(len(v.name) for v in effective.values)
    for v in effective.values:
        if v.section != section:
            section = v.section
            print(f"[{section}]")
        value = f"{v.value}{' ' + v.unit if v.unit else ''}"
        print(f"  {v.name:<{width}} = {value:<26} {v.origin:<13} {v.option}")
    cam = effective.camera
    print(
        f"camera model: {cam.name} {cam.width}x{cam.height} px, fx {cam.fx:.1f}, fy {cam.fy:.1f}, "
        f"cx {cam.cx:.1f}, cy {cam.cy:.1f}" + (", with distortion" if cam.has_distortion else "")
    )
    for note in effective.assumed():
        print(f"note: {note}", file=sys.stderr)
    return 0
