"""Where experiment sessions are kept: the folder setting the app saves, and the one rule by which
the app and ``qrfield session`` find the same folder.

The folder is the ``session_folder`` section's ``root`` of app.json when set (the app's Session
tab sets it), else ``$QRFIELD_SESSIONS_DIR``, else :func:`qrfield.paths.sessions_dir`
(``~/.local/share/qrfield/sessions``). ``session new`` and ``session list`` use it when no folder
is named, so a session made on the command line is listed in the app, and the other way round.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from qrfield import paths
from qrfield.settings import setting

#: The environment variable naming the sessions folder.
ENV_ROOT = "QRFIELD_SESSIONS_DIR"
#: The section of app.json that holds :class:`SessionFolderSettings`.
SECTION = "session_folder"


@dataclass(frozen=True)
class SessionFolderSettings:
    """Where the app makes new sessions."""

    root: str = setting(
        "",
        label="sessions folder",
        help=f"new sessions are made in this folder (empty = ${ENV_ROOT}, else the data folder's sessions/)",
    )


def sessions_root(settings: SessionFolderSettings | None = None) -> Path:
    """The folder of sessions: the setting, else $QRFIELD_SESSIONS_DIR, else
    :func:`qrfield.paths.sessions_dir` (``~/.local/share/qrfield/sessions``)."""
    text = (settings.root if settings is not None else "").strip() or os.environ.get(ENV_ROOT, "").strip()
    return Path(text).expanduser() if text else paths.sessions_dir()


def configured_root(store: Any) -> Path:
    """:func:`sessions_root` with the setting saved in app.json (``store``: a
    :class:`qrfield.runconfig.ConfigStore`), as the app would use it."""
    return sessions_root(store.group(SECTION, SessionFolderSettings))
