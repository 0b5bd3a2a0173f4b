"""app.json itself: where it is, reading it (a damaged file set aside), its sections, saving it."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from qrfield import paths
from qrfield.files import atomic_write_json, make_folder, read_json_or_set_aside
from qrfield.settings import SettingError, from_dict, to_dict

#: The one file of settings in the config folder.
CONFIG_FILE = "app.json"


class ConfigStore:
    """Loads and saves the settings groups of one JSON file (the app's and the run configuration's).

    ``problems`` lists what could not be restored (shown once by the app, on stderr by commands).
    """

    def __init__(self, directory: str | os.PathLike[str] | None = None) -> None:
        self.path = paths.config_dir(directory) / CONFIG_FILE
        self.problems: list[str] = []
        self._data: dict[str, Any] = {}
        self.dropped: dict[str, str] = {}
        self._can_save = True
        self.load()

    def load(self) -> None:
        """Read the file (qrfield.files' limits: size, nesting, a BOM accepted). A damaged file
        (not UTF-8, not JSON, too deep, not an object) is kept as ``app.json.bad-<time>`` beside
        itself and one line in ``problems`` says so; the defaults are used. A value that breaks a
        file limit (an integer of 500 digits, a text too long) is left out, its default used, with a
        line of its own; the rest is kept."""
        loaded = read_json_or_set_aside(self.path, "settings file")
        self._data = {}
        # False only while a damaged file is still in place (it could not be moved): never save over it.
        self._can_save = loaded.safe_to_overwrite
        if loaded.problem:
            self.problems.append(loaded.problem)
        # Dotted keys ("run.side_mm") whose value broke a file limit and was left out: a strict
        # reader (qrfield run) refuses to start on one it would use.
        self.dropped = dict(loaded.dropped)
        self.problems.extend(self.dropped.values())
        data = loaded.data
        if data is None:
            return
        old = data.get("app")
        if "run" not in data and isinstance(old, dict):
            # Written before the run configuration had its own section: same fields, and the code
            # selection that now lives in the detector's section.
            data["run"] = old
            if "select_text" in old and isinstance(data.get("detector", {}), dict):
                data.setdefault("detector", {}).setdefault("select_text", old["select_text"])
        self._data = data

    def saved_keys(self, section: str) -> set[str]:
        """The keys of ``section`` present in the file (whether or not their values are good)."""
        raw = self._data.get(section)
        return set(raw) if isinstance(raw, dict) else set()

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
        """Write the file all or nothing (:func:`qrfield.files.atomic_write_json`: a random
        temporary file in the folder, renamed over the old one). Not while a damaged file that
        could not be set aside is still in place (``problems`` said so at load)."""
        if not self._can_save:
            return
        make_folder(self.path.parent, "config folder")  # qrfield's own folder: made with its parents
        data = {k: v for k, v in self._data.items() if k != "app"}  # "app" was renamed "run"
        atomic_write_json(self.path, data, sort_keys=True)


def config_file(directory: Any = None) -> Path:
    """The path of the settings file for ``--config-dir`` ``directory`` (None: the default folder)."""
    return paths.config_dir(directory) / CONFIG_FILE
