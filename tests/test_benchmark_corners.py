"""The corner calibration that ``qrfield benchmark detect`` prints (qrfield/benchmarks/_corners.py),
by module size band, against whitened errors computed by hand."""

from __future__ import annotations

import numpy as np

from qrfield.benchmarks._corners import CornerResult, print_calibration


def _result(module_px: float, error_px: float, std_px: float) -> CornerResult:
    diff = np.full((4, 2), error_px)
    cov = np.repeat((std_px**2 * np.eye(2))[None], 4, axis=0)
    return CornerResult(0, False, "", module_px, np.linalg.norm(diff, axis=1), diff, cov, True, True, False)


def test_the_calibration_is_printed_by_the_finer_module_bands(capsys) -> None:
    # e / std = 1 at 1.2 px (z RMS 1, all within 2), 3 at 1.7 px (none within 2), 0.5 at 4 px.
    print_calibration([_result(1.2, 0.01, 0.01), _result(1.7, 0.03, 0.01), _result(4.0, 0.005, 0.01)])
    lines = {
        line.split()[0] + " " + line.split()[1]: line for line in capsys.readouterr().out.splitlines()[1:]
    }
    assert "z RMS 1.00, 100.0 % within 2" in lines["< 1.5"]
    assert "z RMS 3.00, 0.0 % within 2" in lines["1.5-2 px"]
    assert "no covariance" in lines["2-3 px"]
    assert "z RMS 0.50, 100.0 % within 2" in lines[">= 3"]
    assert "z RMS 1.85, 66.7 % within 2" in lines["all 12"]  # sqrt((1 + 9 + 0.25) / 3)
