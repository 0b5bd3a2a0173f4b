"""``qrfield benchmark NAME`` (also ``qrfield bench NAME``): figures beside a baseline of the same run."""

from __future__ import annotations

import argparse
import importlib
import pkgutil

#: Other names the command answers to: ``bench`` was its name before, and users' scripts type it.
ALIASES = ("bench",)

HELP = "run a benchmark (render, solvers, detect, pipeline, serial, ...) and print its figures"


def _benchmark_modules() -> dict[str, str]:
    from qrfield import benchmarks

    return {
        m.name.replace("_", "-"): f"qrfield.benchmarks.{m.name}"
        for m in pkgutil.iter_modules(benchmarks.__path__)
        if not m.name.startswith("_")
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="benchmark", metavar="NAME", required=True)
    for name, path in sorted(_benchmark_modules().items()):
        module = importlib.import_module(path)
        sp = sub.add_parser(name, help=module.HELP, description=getattr(module, "DESCRIPTION", module.HELP))
        module.add_arguments(sp)
        sp.set_defaults(_benchmark_run=module.run)


def run(args: argparse.Namespace) -> int:
    return int(args._benchmark_run(args) or 0)
