"""The live stream's settings: branch continuity and the filter's time constant (docs/conventions.md)."""

from __future__ import annotations

from dataclasses import dataclass

from qrfield.settings import setting


@dataclass(frozen=True)
class StreamSettings:
    """How a frame loop uses the frames before each one (section ``stream`` of app.json; on the
    command line ``--continuity`` and ``--filter-s``)."""

    continuity: bool = setting(
        True,
        label="resolve flips from history",
        help="an ambiguous frame takes the branch nearest the stream's recent resolved pose "
        "(at most 0.5 s old); false: every frame is decided alone",
    )
    filter_s: float = setting(
        0.0,
        label="filter time constant",
        unit="s",
        minimum=0.0,
        maximum=5.0,
        decimals=2,
        help="smooth position and rotation over time with each frame's covariance as its noise "
        "(0 = off): steadier and more precise, but it trails a moving card; resets after a jump or "
        "a gap of 0.5 s",
    )
