"""Shared fixtures: the real photos in ../shared/data, a standard camera, and the user's folders
kept out of the real home (every test sees an empty config and data folder of its own session)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from qrfield.camera import CameraModel, resolve_camera
from qrfield.testing.shared_data import shared_data_dir


@pytest.fixture(autouse=True, scope="session")
def _private_user_folders(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Point qrfield's config, data, calibration and sessions folders at this test session's own
    (subprocesses inherit them): no test reads a profile from, or writes results into, the home
    of whoever runs the suite. Tests that check the lookup order set these themselves."""
    home = tmp_path_factory.mktemp("user-folders")
    for name, sub in (
        ("QRFIELD_CONFIG_DIR", "config"),
        ("QRFIELD_DATA_DIR", "data"),
        ("QRFIELD_SESSIONS_DIR", "sessions"),
    ):
        os.environ[name] = str(home / sub)
    os.environ.pop("QRFIELD_CALIB_DIR", None)


@pytest.fixture(autouse=True)
def _config_dir_restored() -> Iterator[None]:
    """``main([..., "--config-dir", D])`` makes D this process's ``$QRFIELD_CONFIG_DIR``
    (:func:`qrfield.paths.use_config_dir`, for the processes it starts): restored after each test,
    so that a later test's subprocess does not read an earlier test's app.json (audit-1:
    ``pytest tests/test_runconfig.py tests/test_run_cli.py`` failed on a file the first one left)."""
    before = os.environ.get("QRFIELD_CONFIG_DIR")
    yield
    if before is None:
        os.environ.pop("QRFIELD_CONFIG_DIR", None)
    else:
        os.environ["QRFIELD_CONFIG_DIR"] = before


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
