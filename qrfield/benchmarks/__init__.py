"""Benchmarks run by ``qrfield benchmark NAME``, one module each (discovered like the commands).

Each module defines ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; it prints its
figures, each beside a baseline measured in the same run, so that ratios are comparable across
machines. No benchmark is a timed test.
"""
