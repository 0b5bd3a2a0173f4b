"""One run configuration for the bench app, ``qrfield run`` and ``qrfield session log``.

What a frame loop measures with is declared once here, as settings groups (:mod:`qrfield.settings`),
each one section of one JSON file, ``<config folder>/app.json`` (:func:`qrfield.paths.config_dir`:
``--config-dir``, else ``$QRFIELD_CONFIG_DIR``, else ``~/.config/qrfield``):

=========== ============================ ======================================================
section     settings                     command-line options (override the file)
=========== ============================ ======================================================
run         :class:`RunSettings`         ``--source --camera --side-mm --method --loop --pace
                                         --retry-s`` (and ``--focal-px/--size`` for the camera)
detector    DetectorSettings             ``--detect-NAME`` (``--select-text``, ``--max-codes``: short forms)
numerical   NumericalSettings            ``--numerical-NAME``
ippe        IppeSettings                 ``--ippe-NAME``
virtual     VirtualBenchSettings         ``--virtual-NAME``
picamera    Picamera2Settings            ``--picamera-NAME``
usb         UsbCameraSettings            ``--usb-NAME``
serial      SerialLinkSettings           ``--serial-NAME`` (``--serial [PORT]`` turns the link on)
handeye     HandEyeSettings              ``--frame --handeye-file`` (poses in the tool or base frame)
stream      StreamSettings               ``--continuity --filter-s`` (the live stream: flips from
                                         history, the filter; docs/conventions.md)
=========== ============================ ======================================================

The app writes the file when it closes (with sections of its own: window, simulation, session
folder, ...); the commands read it and never write it. Unknown keys are ignored and bad values fall
back to their defaults with a note (:attr:`ConfigStore.problems`), so a damaged or older file never
stops the app (``qrfield run`` is strict: a bad value it would use stops it at start, naming the
file and the key, ``effective_settings(strict=True)``); a file that cannot be read as a JSON object
at all is kept as ``app.json.bad-<time>`` (whoever reads it first moves it aside, so the app never
saves defaults over it), with one line saying so. :func:`effective_settings` says where each value came from
(``qrfield config``).

The package, one job a module: :mod:`~qrfield.runconfig.run_settings` (the run section),
:mod:`~qrfield.runconfig.sections` (the table above), :mod:`~qrfield.runconfig.store` (the file),
:mod:`~qrfield.runconfig.config` (:class:`RunConfig`), :mod:`~qrfield.runconfig.options` (the
command-line options), :mod:`~qrfield.runconfig.effective` (which value wins, and from where).
Every name is importable from ``qrfield.runconfig``.
"""

from __future__ import annotations

from qrfield.runconfig.config import RunConfig
from qrfield.runconfig.effective import (
    FROM_COMMAND_LINE,
    FROM_DEFAULT,
    FROM_FILE,
    Effective,
    Value,
    effective_settings,
)
from qrfield.runconfig.options import add_config_dir_argument, add_run_arguments
from qrfield.runconfig.run_settings import RunSettings
from qrfield.runconfig.sections import Section, sections
from qrfield.runconfig.store import CONFIG_FILE, ConfigStore, config_file

__all__ = [
    "CONFIG_FILE",
    "FROM_COMMAND_LINE",
    "FROM_DEFAULT",
    "FROM_FILE",
    "ConfigStore",
    "Effective",
    "RunConfig",
    "RunSettings",
    "Section",
    "Value",
    "add_config_dir_argument",
    "add_run_arguments",
    "config_file",
    "effective_settings",
    "sections",
]
