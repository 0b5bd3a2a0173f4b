"""``qrfield benchmark handeye`` runs end to end (one small cell per set-up) and prints its verdicts."""

from __future__ import annotations

import pytest

from qrfield.cli import main

pytestmark = pytest.mark.timeout(120)


@pytest.mark.slow
def test_bench_handeye_runs_and_prints_its_figures(capsys):
    assert main(["benchmark", "handeye", "--sets", "1", "--views", "8"]) == 0
    out = capsys.readouterr().out
    assert "eye-in-hand: cell" in out and "eye-to-hand: cell" in out
    assert "(must hold: < 2 mm, < 0.3 deg): met" in out
    assert "degenerate set (turns about the optical axis only): refused: " in out
