"""``qrfield benchmark serial`` runs on a pty, loop:// and the UART relay (tiny sizes, no figures)."""

from __future__ import annotations

import pytest

from qrfield.cli import main

pytestmark = pytest.mark.timeout(60)


@pytest.mark.slow
def test_bench_serial_runs_and_prints_its_figures(capsys):
    args = ["--frames", "200", "--seconds", "0.05", "--latency-frames", "5", "--relay-seconds", "0.6"]
    assert main(["benchmark", "serial", *args, "--baseline-seconds", "0.6"]) == 0
    out = capsys.readouterr().out
    labels = ("encode", "via link to pty", "via link to loop://", "publish -> read", "bare write")
    labels += ("UART 9600 baud, link", "UART 115200 baud, link", "PING answers", "UART 9600 baud, baseline")
    for label in labels:
        assert label in out


def test_serial_monitor_is_a_subcommand(capsys):
    assert main(["serial-monitor", "--help"]) == 0  # argparse's exit is main's return code
    assert "--count" in capsys.readouterr().out
