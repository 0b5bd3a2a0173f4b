"""``qrfield benchmark serial`` runs end to end on a pty and loop:// (tiny sizes; asserts no figures)."""

from __future__ import annotations

import pytest

from qrfield.cli import main

pytestmark = pytest.mark.timeout(60)


def test_bench_serial_runs_and_prints_its_figures(capsys):
    assert main(["benchmark", "serial", "--frames", "200", "--seconds", "0.05", "--latency-frames", "5"]) == 0
    out = capsys.readouterr().out
    labels = ("encode", "via link to pty", "via link to loop://", "publish -> read", "bare write")
    for label in labels:
        assert label in out


def test_serial_monitor_is_a_subcommand(capsys):
    assert main(["serial-monitor", "--help"]) == 0  # argparse's exit is main's return code
    assert "--count" in capsys.readouterr().out
