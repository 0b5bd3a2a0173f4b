"""``qrfield bench NAME``: print speed figures against a baseline measured in the same run."""

from __future__ import annotations

import argparse
import importlib
import pkgutil

HELP = "run a benchmark (render, solvers, detect, pipeline, serial, ...) and print its figures"


def _bench_modules() -> dict[str, str]:
    from qrfield import bench

    return {
        m.name.replace("_", "-"): f"qrfield.bench.{m.name}"
        for m in pkgutil.iter_modules(bench.__path__)
        if not m.name.startswith("_")
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bench", metavar="NAME", required=True)
    for name, path in sorted(_bench_modules().items()):
        module = importlib.import_module(path)
        sp = sub.add_parser(name, help=module.HELP, description=getattr(module, "DESCRIPTION", module.HELP))
        module.add_arguments(sp)
        sp.set_defaults(_bench_run=module.run)


def run(args: argparse.Namespace) -> int:
    return int(args._bench_run(args) or 0)
