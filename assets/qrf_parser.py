"""qrf_parser.py: read qrfield's serial lines on a MicroPython board (or CPython), send it commands.

    $QRF,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<status>*<CS>\\r\\n     a pose frame
    $QRM,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,
         <n_used>,<status>*<CS>\\r\\n                                          the answer to MEAS,n
    $QRA,<command>,OK*<CS>\\r\\n   or   $QRA,<command>,ERR,<reason>*<CS>\\r\\n   other answers

x, y, z in mm (1 decimal), alpha, beta, gamma in degrees (2 decimals), s* the standard deviations in
the same units. $QRF status: OK (a live camera's pose) or SIM (virtual bench or recording: never
act on it as a measurement) with the pose, NOQR, NOCONV or NOSRC (no camera frames) without it,
STALE either way. $QRM status: OK or SIM with every field, NOQR, NOCONV, NOSRC or TIMEOUT with the
number fields empty. CS = XOR of the bytes between '$' and '*', two hex digits; a line is at most
160 bytes with its CR LF. Commands: command("PING"), command("STREAM", "OFF"), command("MEAS", 10).
Uses only bytes, int and float (no imports), so it runs on MicroPython. Example on a Raspberry
Pi Pico::

    from machine import UART
    from qrf_parser import Reader, command
    uart = UART(0, baudrate=115200)
    reader = Reader()
    uart.write(command("MEAS", 10))
    while True:
        data = uart.read()
        if data:
            for kind, item in reader.feed_all(data):
                if kind == "QRF" and item[2] == "OK":
                    seq, t_ms, status, (x, y, z, alpha, beta, gamma) = item
                elif kind == "QRM" and item[-1] == "OK":
                    seq, t_ms, mean, std, n_used, status = item
"""

STATUSES = ("OK", "SIM", "NOQR", "NOCONV", "STALE", "NOSRC")
FILLED = ("OK", "SIM")
EMPTY = ("NOQR", "NOCONV", "NOSRC")
MEAS_STATUSES = ("OK", "SIM", "NOQR", "NOCONV", "NOSRC", "TIMEOUT")
MAX_LINE = 160  # bytes, CR LF included


def _checked_fields(line):
    """The comma-separated fields of one line (bytes from '$', CR/LF optional) if its checksum is
    right, else None."""
    line = line.rstrip(b"\r\n")
    star = line.rfind(b"*")
    if not line.startswith(b"$") or star < 0 or len(line) - star != 3 or len(line) + 2 > MAX_LINE:
        return None
    cs = 0
    for byte in line[1:star]:
        cs ^= byte
    try:
        if cs != int(line[star + 1 :], 16):
            return None
        return line[1:star].decode().split(",")
    except ValueError:
        return None


def _number(text, decimals):
    """A decimal with exactly ``decimals`` digits after the point, as float; ValueError otherwise."""
    point = text.find(".")
    if point < 0 or len(text) - point - 1 != decimals:
        raise ValueError(text)
    return float(text)


def _pose(fields):
    return tuple(_number(f, 1) for f in fields[:3]) + tuple(_number(f, 2) for f in fields[3:6])


def _seq_t(fields):
    seq, t_ms = int(fields[1]), int(fields[2])
    if not (0 <= seq <= 65535 and t_ms >= 0):
        raise ValueError("seq or t_ms out of range")
    return seq, t_ms


def parse_line(line):
    """One $QRF line -> (seq, t_ms, status, pose or None), or None if bad (or not $QRF)."""
    fields = _checked_fields(line)
    if fields is None or fields[0] != "QRF" or len(fields) != 10 or fields[9] not in STATUSES:
        return None
    try:
        seq, t_ms = _seq_t(fields)
        status = fields[9]
        if all(f == "" for f in fields[3:9]):
            return None if status in FILLED else (seq, t_ms, status, None)
        if status in EMPTY:
            return None
        return (seq, t_ms, status, _pose(fields[3:9]))
    except ValueError:
        return None


def parse_measurement(line):
    """One $QRM line -> (seq, t_ms, mean pose or None, std or None, n_used or None, status), or None."""
    fields = _checked_fields(line)
    if fields is None or fields[0] != "QRM" or len(fields) != 17 or fields[16] not in MEAS_STATUSES:
        return None
    try:
        seq, t_ms = _seq_t(fields)
        status = fields[16]
        if status not in FILLED:
            if any(f != "" for f in fields[3:16]):
                return None
            return (seq, t_ms, None, None, None, status)
        mean, std, n_used = _pose(fields[3:9]), _pose(fields[9:15]), int(fields[15])
        if min(std) < 0 or not 1 <= n_used <= 100:
            return None
        return (seq, t_ms, mean, std, n_used, status)
    except ValueError:
        return None


def parse_answer(line):
    """One $QRA line -> (command, "OK" or "ERR", reason), or None."""
    fields = _checked_fields(line)
    if fields is None or fields[0] != "QRA":
        return None
    if len(fields) == 3 and fields[2] == "OK":
        return (fields[1], "OK", "")
    if len(fields) == 4 and fields[2] == "ERR" and len(fields[3]) <= 40:
        return (fields[1], "ERR", fields[3])
    return None


PARSERS = {
    b"$QRF,": ("QRF", parse_line),
    b"$QRM,": ("QRM", parse_measurement),
    b"$QRA,": ("QRA", parse_answer),
}


def command(name, arg=None):
    """The bytes of a command to qrfield: command("MEAS", 10) -> b"$QRC,MEAS,10*5B\\r\\n"."""
    body = "QRC," + name + ("" if arg is None else "," + str(arg))
    cs = 0
    for byte in body.encode():
        cs ^= byte
    return ("$" + body + "*" + "0123456789ABCDEF"[cs >> 4] + "0123456789ABCDEF"[cs & 15] + "\r\n").encode()


class Reader:
    """Collects bytes into lines (resynchronising on '$'). ``feed_all`` returns every good line
    completed, as ("QRF" | "QRM" | "QRA", parsed tuple); ``feed`` only the $QRF frames."""

    def __init__(self):
        self.buf = b""
        self.bad = 0  # lines dropped: checksum, format or length

    def feed_all(self, data):
        items = []
        for byte in data:
            if byte == 36:  # '$' starts a line, whatever came before
                self.buf = b"$"
            elif not self.buf:
                continue  # garbage between lines
            elif byte == 10:  # '\n' ends it
                kind, parse = PARSERS.get(self.buf[:5], (None, None))
                if parse is None:  # another talker's line (a command): only counted when broken
                    self.bad += _checked_fields(self.buf) is None
                else:
                    item = parse(self.buf)
                    if item is None:
                        self.bad += 1
                    else:
                        items.append((kind, item))
                self.buf = b""
            elif len(self.buf) >= MAX_LINE:
                self.buf = b""
                self.bad += 1
            else:
                self.buf += bytes((byte,))
        return items

    def feed(self, data):
        return [item for kind, item in self.feed_all(data) if kind == "QRF"]
