"""Where the shared real data lives (photos of QR codes, chessboard calibrations): the folder the
tests' ``shared_data`` fixture and the benchmarks' ``--data`` default to."""

from __future__ import annotations

import os
from pathlib import Path

#: The environment variable naming the shared data folder, when it is not beside the repository.
SHARED_DATA_ENV = "QRFIELD_SHARED_DATA"


def shared_data_dir(given: Path | str | None = None) -> Path | None:
    """The shared data folder: ``given`` (a benchmark's ``--data``), else ``$QRFIELD_SHARED_DATA``,
    else ``../shared/data`` beside the repository; the first that is a folder, or None."""
    candidates = [
        given,
        os.environ.get(SHARED_DATA_ENV),
        Path(__file__).resolve().parents[2].parent / "shared" / "data",
    ]
    for candidate in candidates:
        if candidate and Path(candidate).is_dir():
            return Path(candidate)
    return None
