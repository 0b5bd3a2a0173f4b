"""qrfield.paths: the user's folders come from the environment, else the XDG defaults."""

from pathlib import Path

from qrfield import paths


def test_environment_overrides(monkeypatch, tmp_path):
    monkeypatch.setenv("QRFIELD_CONFIG_DIR", str(tmp_path / "cfg"))
    monkeypatch.setenv("QRFIELD_DATA_DIR", str(tmp_path / "data"))
    assert paths.config_dir() == tmp_path / "cfg"
    assert paths.user_calib_dir() == tmp_path / "cfg" / "calib"
    assert paths.simulations_dir() == tmp_path / "data" / "simulations"
    assert paths.config_dir(tmp_path / "other") == tmp_path / "other"  # --config-dir wins
    monkeypatch.delenv("QRFIELD_SESSIONS_DIR", raising=False)
    assert paths.sessions_dir() == tmp_path / "data" / "sessions"
    monkeypatch.setenv("QRFIELD_SESSIONS_DIR", str(tmp_path / "bench"))
    assert paths.sessions_dir() == tmp_path / "bench"  # the app's and the command line's


def test_xdg_then_home(monkeypatch, tmp_path):
    for name in ("QRFIELD_CONFIG_DIR", "QRFIELD_DATA_DIR", "QRFIELD_SESSIONS_DIR"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xc"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xd"))
    assert paths.config_dir() == tmp_path / "xc" / "qrfield"
    assert paths.data_dir() == tmp_path / "xd" / "qrfield"
    monkeypatch.delenv("XDG_CONFIG_HOME")
    monkeypatch.delenv("XDG_DATA_HOME")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert paths.config_dir() == Path(tmp_path) / ".config" / "qrfield"
    assert paths.sessions_dir() == Path(tmp_path) / ".local" / "share" / "qrfield" / "sessions"
    assert not (tmp_path / ".config").exists()  # looking a folder up never creates it
