"""The sections of app.json, in file order: each one settings class and its command-line prefix."""

from __future__ import annotations

from dataclasses import dataclass

from qrfield.methods import IPPE, NUMERICAL
from qrfield.runconfig.run_settings import RunSettings


@dataclass(frozen=True)
class Section:
    """One section of the file: its settings class and the prefix of its command-line options."""

    name: str
    cls: type
    prefix: str
    title: str


def sections() -> dict[str, Section]:
    """The run configuration's sections, in file order (imports the settings' modules)."""
    from qrfield.detect import DetectorSettings
    from qrfield.handeye.settings import HandEyeSettings
    from qrfield.serial.link import SerialLinkSettings
    from qrfield.solvers import settings_classes
    from qrfield.sources import Picamera2Settings, UsbCameraSettings, VirtualBenchSettings
    from qrfield.stream import StreamSettings

    solvers = settings_classes()
    table = [
        Section("run", RunSettings, "", "source, camera, QR side, methods"),
        Section("detector", DetectorSettings, "detect_", "QR detection and code selection"),
        Section(NUMERICAL, solvers[NUMERICAL], "numerical_", "the thesis' numerical model"),
        Section(IPPE, solvers[IPPE], "ippe_", "OpenCV IPPE"),
        Section("virtual", VirtualBenchSettings, "virtual_", "the virtual bench (--source virtual)"),
        Section("picamera", Picamera2Settings, "picamera_", "Raspberry Pi camera (--source picamera2)"),
        Section("usb", UsbCameraSettings, "usb_", "USB camera (--source usb:N)"),
        Section("serial", SerialLinkSettings, "serial_", "serial link to the gripper controller"),
        Section("handeye", HandEyeSettings, "", "the frame poses are reported in (docs/handeye.md)"),
        Section("stream", StreamSettings, "", "the live stream: flips resolved from history, the filter"),
    ]
    return {s.name: s for s in table}
