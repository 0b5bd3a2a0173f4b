"""The app's persistent settings: one JSON file, each group declared once with qrfield.settings.

The file is ``<config dir>/app.json`` where the config dir is ``$QRFIELD_CONFIG_DIR`` or
``~/.config/qrfield``. Its sections: ``app`` (:class:`AppSettings`), ``virtual`` (the virtual
bench), one per pose method (the solvers' settings), ``detector``, ``simulation`` (the simulation
tab's study form, see ui/simulation_tab.py), and ``window`` (geometry).
Unknown keys are ignored and bad values fall back to their defaults with a note, so a damaged or
older file never stops the app.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from qrfield import paths
from qrfield.settings import SettingError, from_dict, setting, to_dict

CONFIG_FILE = "app.json"


@dataclass(frozen=True)
class AppSettings:
    """App-level choices, restored at the next start."""

    source: str = setting(
        "auto", label="source", help="auto, virtual, picamera2, usb:N, or a video file / folder path"
    )
    camera: str = setting(
        "picam-v2@640x480", label="camera model", help="preset NAME[@WxH] or PATH.json[@WxH]"
    )
    side_mm: float = setting(50.0, label="QR side", unit="mm", minimum=1.0, maximum=2000.0, decimals=1)
    method: str = setting("both", label="method", choices=("numerical", "ippe", "both"))
    plot_window_s: float = setting(
        20.0, label="plot window", unit="s", minimum=2.0, maximum=600.0, decimals=0
    )
    select_text: str = setting("", label="select text", help="only a code with this payload (empty = any)")
    loop: bool = setting(True, label="loop files", help="a video file or folder starts again at its end")


def config_dir() -> Path:
    """The config folder (qrfield.paths.config_dir)."""
    return paths.config_dir()


class ConfigStore:
    """Loads and saves the app's settings groups in one JSON file.

    ``problems`` lists what could not be restored (shown in the status bar once).
    """

    def __init__(self, directory: str | os.PathLike[str] | None = None) -> None:
        self.path = Path(directory).expanduser() / CONFIG_FILE if directory else config_dir() / CONFIG_FILE
        self.problems: list[str] = []
        self._data: dict[str, Any] = {}
        self.load()

    def load(self) -> None:
        self._data = {}
        if not self.path.is_file():
            return
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            self.problems.append(f"settings file {self.path} unreadable ({exc}); using defaults")
            return
        if isinstance(data, dict):
            self._data = data
        else:
            self.problems.append(f"settings file {self.path} is not a JSON object; using defaults")

    def group(self, section: str, cls: type) -> Any:
        """The saved settings of ``section`` as ``cls`` (defaults for what is missing or bad)."""
        raw = self._data.get(section)
        if not isinstance(raw, dict):
            return cls()
        try:
            return from_dict(cls, raw, strict=False)
        except SettingError:
            # Keep each good value; drop only the bad ones, and say which.
            good = {}
            for key, value in raw.items():
                try:
                    from_dict(cls, {key: value}, strict=False)
                except SettingError as exc:
                    self.problems.append(f"{section}: {exc}; default used")
                    continue
                good[key] = value
            return from_dict(cls, good, strict=False)

    def set_group(self, section: str, instance: Any) -> None:
        self._data[section] = to_dict(instance)

    def value(self, key: str, default: Any = None) -> Any:
        return self._data.get(key, default)

    def set_value(self, key: str, value: Any) -> None:
        self._data[key] = value

    def save(self) -> None:
        """Write the file atomically (a temporary file renamed over the old one)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(self._data, indent=2, sort_keys=True) + "\n", encoding="utf-8")
        os.replace(tmp, self.path)
