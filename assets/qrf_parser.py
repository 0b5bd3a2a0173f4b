"""qrf_parser.py: read qrfield's serial pose frames on a MicroPython board (or CPython).

    $QRF,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<status>*<CS>\\r\\n

x, y, z in mm (1 decimal), alpha, beta, gamma in degrees (2 decimals); status OK, NOQR, NOCONV or
STALE; CS = XOR of the bytes between '$' and '*', two hex digits. Uses only bytes, int and float
(no imports), so it runs on MicroPython. Example on a Raspberry Pi Pico::

    from machine import UART
    from qrf_parser import Reader
    uart = UART(0, baudrate=115200)
    reader = Reader()
    while True:
        data = uart.read()
        if data:
            for seq, t_ms, status, pose in reader.feed(data):
                if status == "OK":
                    x, y, z, alpha, beta, gamma = pose
"""

STATUSES = ("OK", "NOQR", "NOCONV", "STALE")
MAX_LINE = 96


def parse_line(line):
    """One line (bytes, from '$', CR/LF optional) -> (seq, t_ms, status, pose or None), or None if bad."""
    line = line.rstrip(b"\r\n")
    star = line.rfind(b"*")
    if not line.startswith(b"$QRF,") or star < 0 or len(line) - star != 3:
        return None
    cs = 0
    for byte in line[1:star]:
        cs ^= byte
    try:
        if cs != int(line[star + 1 :], 16):
            return None
        fields = line[1:star].decode().split(",")
        if len(fields) != 10 or fields[9] not in STATUSES:
            return None
        seq, t_ms, status = int(fields[1]), int(fields[2]), fields[9]
        if not (0 <= seq <= 65535 and t_ms >= 0):
            return None
        if all(f == "" for f in fields[3:9]):
            return None if status == "OK" else (seq, t_ms, status, None)
        if status not in ("OK", "STALE"):
            return None
        return (seq, t_ms, status, tuple(float(f) for f in fields[3:9]))
    except ValueError:
        return None


class Reader:
    """Collects bytes into lines (resynchronising on '$'); feed() returns the good frames completed."""

    def __init__(self):
        self.buf = b""
        self.bad = 0  # lines dropped: checksum, format or length

    def feed(self, data):
        frames = []
        for byte in data:
            if byte == 36:  # '$' starts a line, whatever came before
                self.buf = b"$"
            elif not self.buf:
                continue  # garbage between lines
            elif byte == 10:  # '\n' ends it
                frame = parse_line(self.buf)
                self.buf = b""
                if frame is None:
                    self.bad += 1
                else:
                    frames.append(frame)
            elif len(self.buf) >= MAX_LINE:
                self.buf = b""
                self.bad += 1
            else:
                self.buf += bytes((byte,))
        return frames
