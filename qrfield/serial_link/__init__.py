"""Serial link to the gripper controller: frames (:mod:`.frames`) and the streaming link (:mod:`.link`).

Named ``serial_link`` so as not to shadow pyserial's ``serial`` module.
"""

from qrfield.serial_link.frames import (
    MAX_LINE_BYTES,
    STATUSES,
    ControllerCommand,
    DecoderCounters,
    FrameDecoder,
    FrameError,
    PoseValueError,
    QrfFrame,
    checksum,
    encode_command,
    encode_frame,
)
from qrfield.serial_link.link import (
    CLOSED,
    CONNECTED,
    CONNECTING,
    DISCONNECTED,
    LOOP_URL,
    LinkStatus,
    PortInfo,
    SerialLink,
    SerialLinkSettings,
    list_ports,
    open_pyserial,
)

__all__ = [
    "CLOSED",
    "CONNECTED",
    "CONNECTING",
    "DISCONNECTED",
    "LOOP_URL",
    "MAX_LINE_BYTES",
    "STATUSES",
    "ControllerCommand",
    "DecoderCounters",
    "FrameDecoder",
    "FrameError",
    "LinkStatus",
    "PortInfo",
    "PoseValueError",
    "QrfFrame",
    "SerialLink",
    "SerialLinkSettings",
    "checksum",
    "encode_command",
    "encode_frame",
    "list_ports",
    "open_pyserial",
]
