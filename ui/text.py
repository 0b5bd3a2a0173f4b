"""How the app writes numbers and paths on screen (Qt wraps a long path after its slashes)."""

from __future__ import annotations

import math
import os
from pathlib import Path


def fixed(value: float | None, decimals: int, missing: str = "—") -> str:
    """``value`` with ``decimals`` decimals; never "-0.00" (a value that rounds to zero has no
    sign); ``missing`` for None, NaN or infinity."""
    if value is None or not math.isfinite(value):
        return missing
    text = f"{value:.{decimals}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]
    return text


def short_path(path: str | os.PathLike[str]) -> str:
    """``path`` with the home folder written as ``~``."""
    text = str(path)
    home = str(Path.home())
    if text == home or text.startswith(home + os.sep):
        return "~" + text[len(home) :]
    return text
