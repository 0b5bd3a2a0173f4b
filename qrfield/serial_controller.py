"""Deprecated alias of :mod:`qrfield.serial.controller` (the commands and GripperLink).

The serial modules moved into the package :mod:`qrfield.serial` with protocol 2 (docs/serial.md);
import from there. This alias goes away in a later release.
"""

import warnings

from qrfield.serial.controller import *  # noqa: F403

warnings.warn(
    "qrfield.serial_controller is deprecated: use qrfield.serial.controller", DeprecationWarning, stacklevel=2
)
