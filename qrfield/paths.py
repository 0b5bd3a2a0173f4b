"""Where qrfield keeps the user's files: one home for every folder outside the source checkout.

- config folder: ``$QRFIELD_CONFIG_DIR``, else ``$XDG_CONFIG_HOME/qrfield``, else
  ``~/.config/qrfield``: settings (``app.json``) and the user's camera profiles (``calib/``);
- data folder: ``$QRFIELD_DATA_DIR``, else ``$XDG_DATA_HOME/qrfield``, else
  ``~/.local/share/qrfield``: results the app writes when the user names no folder
  (``simulations/``);
- sessions folder: ``$QRFIELD_SESSIONS_DIR``, else ``<data folder>/sessions``: the one folder of
  experiment sessions the app and ``qrfield session`` share (``session new`` and ``session list``
  use it when no folder is named).

Nothing here creates a folder: the writer creates the one it writes into, when it writes.
"""

from __future__ import annotations

import os
from pathlib import Path


def _from_env(name: str) -> Path | None:
    value = os.environ.get(name, "").strip()
    return Path(value).expanduser() if value else None


def config_dir(override: str | os.PathLike[str] | None = None) -> Path:
    """The config folder: ``override`` (e.g. ``--config-dir``), else the environment's, else the default."""
    if override:
        return Path(override).expanduser()
    env = _from_env("QRFIELD_CONFIG_DIR")
    if env is not None:
        return env
    xdg = _from_env("XDG_CONFIG_HOME")
    return (xdg if xdg is not None else Path.home() / ".config") / "qrfield"


def use_config_dir(directory: str | os.PathLike[str]) -> Path:
    """Make ``directory`` (``--config-dir``, relative to the current folder) this process's config
    folder for everything kept there (app.json, the user's camera profiles in ``calib/``), and for
    the processes it starts: it becomes ``$QRFIELD_CONFIG_DIR``. Returns the absolute folder."""
    folder = Path(directory).expanduser().absolute()
    os.environ["QRFIELD_CONFIG_DIR"] = str(folder)
    return folder


def data_dir() -> Path:
    """The data folder for results written without a named destination."""
    env = _from_env("QRFIELD_DATA_DIR")
    if env is not None:
        return env
    xdg = _from_env("XDG_DATA_HOME")
    return (xdg if xdg is not None else Path.home() / ".local" / "share") / "qrfield"


def user_calib_dir() -> Path:
    """The user's own camera profiles (``<config folder>/calib``); calibrations are saved here."""
    return config_dir() / "calib"


def simulations_dir() -> Path:
    """Default parent folder of simulation study runs (``<data folder>/simulations``)."""
    return data_dir() / "simulations"


def sessions_dir() -> Path:
    """The folder of experiment sessions the app and the command line share:
    ``$QRFIELD_SESSIONS_DIR``, else ``<data folder>/sessions``."""
    env = _from_env("QRFIELD_SESSIONS_DIR")
    return env if env is not None else data_dir() / "sessions"
