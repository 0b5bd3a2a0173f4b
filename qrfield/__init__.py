"""qrfield: 6-DOF pose of one printed QR code of known size from one camera image.

The core package: never imports Qt, so it runs headless on a Raspberry Pi.
"""

__version__ = "0.1.0"
