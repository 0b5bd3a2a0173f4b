"""Deprecated alias of :mod:`qrfield.serial.codec` (the line format: encode, decode, CRC-16).

The serial modules moved into the package :mod:`qrfield.serial` with protocol 2 (docs/serial.md);
import from there. This alias goes away in a later release.
"""

import warnings

from qrfield.serial.codec import *  # noqa: F403

warnings.warn(
    "qrfield.serial_frames is deprecated: use qrfield.serial.codec", DeprecationWarning, stacklevel=2
)
