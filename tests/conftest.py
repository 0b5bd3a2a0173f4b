"""Shared fixtures: the real photos in ../shared/data, and a standard camera."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from qrfield.camera import CameraModel, resolve_camera

REPO = Path(__file__).resolve().parent.parent


def shared_data_dir() -> Path | None:
    """``../shared/data`` beside the repository (or $QRFIELD_SHARED_DATA), if present."""
    candidates = [os.environ.get("QRFIELD_SHARED_DATA"), REPO.parent / "shared" / "data"]
    for candidate in candidates:
        if candidate and Path(candidate).is_dir():
            return Path(candidate)
    return None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The shared real-photo data; skips the test with a clear reason where it is absent."""
    path = shared_data_dir()
    if path is None:
        pytest.skip("real photos not found: ../shared/data is absent (set QRFIELD_SHARED_DATA to its path)")
    return path


@pytest.fixture(scope="session")
def camera_vga() -> CameraModel:
    """Raspberry Pi Camera v2 scaled to 640x480 (datasheet model, no distortion)."""
    return resolve_camera("picam-v2@640x480")
