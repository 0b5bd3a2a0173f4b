"""Deprecated alias of :mod:`qrfield.serial.link` (the link thread, its settings) and the port helpers.

The serial modules moved into the package :mod:`qrfield.serial` with protocol 2 (docs/serial.md);
import from there. This alias goes away in a later release.
"""

import warnings

from qrfield.serial.link import *  # noqa: F403
from qrfield.serial.port import LOOP_URL, PortInfo, list_ports, open_pyserial  # noqa: F401

warnings.warn("qrfield.serial_link is deprecated: use qrfield.serial.link", DeprecationWarning, stacklevel=2)
