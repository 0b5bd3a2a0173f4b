"""qrf_parser.py: read qrfield's serial lines (protocol 2) on a MicroPython board (or CPython).

    $QRF,<seq>,<t_ms>,<age_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,<status>*<CRC>
    $QRM,<seq>,<t_ms>,<x>,<y>,<z>,<alpha>,<beta>,<gamma>,<sx>,<sy>,<sz>,<salpha>,<sbeta>,<sgamma>,<n_used>,<status>*<CRC>
    $QRA,<command>,<field>[,<field>...]*<CRC>

(qrfield's docs/serial.md.) Values come out as integers, exact on every board (a float32 would
round 999999.9): positions and their sigmas in tenths of a mm, angles and theirs in hundredths of a
degree; an unknown sigma is None. $QRF status: OK (act on it), AMBIG (flip unresolved: do not act),
SIM (not a live camera: never act) with the pose; NOQR, NOCONV, STALE, NOSRC without. The pose's age
when the line's last byte arrived: age_ms + len(line) * 10 * 1000 // baud ms. CRC: CRC-16/CCITT-FALSE
over the bytes between '$' and '*', 4 uppercase hex digits; a line is at most 160 bytes with CR LF.

Strict, like assets/qrf_parser.c: numbers exactly as qrfield writes them (no '+', spaces, exponent,
leading zeros or "-0.0"; exactly 1 or 2 decimals), ranges checked, field counts checked. No imports,
so it runs on MicroPython. Example on a Raspberry Pi Pico::

    from machine import UART
    from qrf_parser import Reader, command
    uart = UART(0, baudrate=115200)
    reader = Reader()
    uart.write(command("MEAS", 10))
    while True:
        data = uart.read()
        if data:
            for kind, item in reader.feed_all(data):
                if kind == "QRF" and item[3] == "OK":
                    seq, t_ms, age_ms, status, pose, sigmas = item
                    x_dmm, y_dmm, z_dmm, alpha_cdeg, beta_cdeg, gamma_cdeg = pose
                elif kind == "QRM" and item[2] == "OK":
                    seq, t_ms, status, mean, sigmas, n_used = item
                elif kind == "QRA":
                    command_answered, fields = item      # fields[0]: "OK", "ERR", or HELLO's "QRF2"
"""

POSE_STATUSES = ("OK", "AMBIG", "SIM")
FRAME_EMPTY = ("NOQR", "NOCONV", "STALE", "NOSRC")
MEAS_EMPTY = ("NOQR", "NOCONV", "NOSRC", "TIMEOUT")
MAX_LINE = 160  # bytes, CR LF included
MAX_BODY = MAX_LINE - 2
MAX_ANSWER_FIELDS = 8
MAX_FIELD = 40
DIGITS = "0123456789"
HEX = "0123456789ABCDEF"


def _table():
    out = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        out.append(crc & 0xFFFF)
    return out


_CRC_TABLE = _table()


def crc16(data):
    """CRC-16/CCITT-FALSE of bytes ``data``; crc16(b"123456789") == 0x29B1."""
    crc = 0xFFFF
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ _CRC_TABLE[(crc >> 8) ^ byte]
    return crc


def _uint(text, limit):
    """'0' or [1-9][0-9]* up to ``limit``; ValueError otherwise."""
    if not text or len(text) > 10 or (len(text) > 1 and text[0] == "0"):
        raise ValueError(text)
    for c in text:
        if c not in DIGITS:
            raise ValueError(text)
    value = int(text)
    if value > limit:
        raise ValueError(text)
    return value


def _fixed(text, decimals, int_digits, signed=True):
    """-?(0|[1-9][0-9]*)\\.[0-9]{decimals} (not -0.0) as an int scaled by 10**decimals."""
    neg = signed and text[:1] == "-"
    body = text[1:] if neg else text
    point = body.find(".")
    whole, frac = body[:point], body[point + 1 :]
    if point < 1 or point > int_digits or len(frac) != decimals or (len(whole) > 1 and whole[0] == "0"):
        raise ValueError(text)
    for c in whole + frac:
        if c not in DIGITS:
            raise ValueError(text)
    value = int(whole + frac)
    if neg and value == 0:
        raise ValueError(text)
    return -value if neg else value


def _pose(fields):
    """(pose, sigmas) from 12 fields: x y z alpha beta gamma, then their sigmas (empty: None)."""
    pose = tuple(_fixed(f, 1, 6) for f in fields[0:3]) + tuple(_fixed(f, 2, 3) for f in fields[3:6])
    alpha, beta, gamma = pose[3], pose[4], pose[5]
    if not (-18000 < alpha <= 18000 and -9000 <= beta <= 9000 and -18000 < gamma <= 18000):
        raise ValueError("angle out of range")
    sigmas = tuple(None if f == "" else _fixed(f, 1, 6, False) for f in fields[6:9]) + tuple(
        None if f == "" else _fixed(f, 2, 3, False) for f in fields[9:12]
    )
    return pose, sigmas


def _fields(line):
    """The fields of one line (bytes from '$', without CR/LF), or None if its CRC is wrong or
    missing; ValueError for content that is not printable ASCII."""
    n = len(line)
    if n < 7 or n > MAX_BODY or line[0] != 36 or line[n - 5] != 42:  # '$', '*'
        return None
    crc = 0
    for byte in line[n - 4 :]:
        digit = HEX.find(chr(byte))
        if digit < 0:
            return None
        crc = crc * 16 + digit
    body = line[1 : n - 5]
    if crc16(body) != crc:
        return None
    for byte in body:
        if byte < 32 or byte > 126 or byte == 36 or byte == 42:
            raise ValueError("not printable")
    return body.decode().split(",")


def _frame(f):
    if len(f) != 17:
        raise ValueError("field count")
    seq, t_ms, status = _uint(f[1], 65535), _uint(f[2], 4294967295), f[16]
    if f[3] == "" and status in ("STALE", "NOSRC"):
        age = None
    else:
        age = _uint(f[3], 4294967295)
    if status in POSE_STATUSES:
        pose, sigmas = _pose(f[4:16])
        return (seq, t_ms, age, status, pose, sigmas)
    if status in FRAME_EMPTY and all(x == "" for x in f[4:16]):
        return (seq, t_ms, age, status, None, None)
    raise ValueError("status")


def _measurement(f):
    if len(f) != 17:
        raise ValueError("field count")
    seq, t_ms, status = _uint(f[1], 65535), _uint(f[2], 4294967295), f[16]
    if status in POSE_STATUSES:
        mean, sigmas = _pose(f[3:15])
        n_used = _uint(f[15], 100)
        if n_used < 1:
            raise ValueError("n_used")
        return (seq, t_ms, status, mean, sigmas, n_used)
    if status in MEAS_EMPTY and all(x == "" for x in f[3:16]):
        return (seq, t_ms, status, None, None, None)
    raise ValueError("status")


def _answer(f):
    if not 3 <= len(f) <= 2 + MAX_ANSWER_FIELDS or not f[1] or len(f[1]) > 16:
        raise ValueError("answer")
    if f[1] != "?":
        for c in f[1]:
            if not ("A" <= c <= "Z" or c in DIGITS):
                raise ValueError("command")
    for x in f[2:]:
        if len(x) > MAX_FIELD:
            raise ValueError("field length")
    if f[2] == "ERR" and (len(f) < 4 or f[3] == ""):
        raise ValueError("reason")
    return (f[1], tuple(f[2:]))


def parse(line):
    """One line (bytes from '$', CR/LF optional) -> ("QRF" | "QRM" | "QRA", tuple), ("OTHER", None)
    for a valid line of another talker, or ("ERR", "crc" | "format" | "length")."""
    while line and line[-1] in (10, 13):
        line = line[:-1]
    if len(line) > MAX_BODY:
        return ("ERR", "length")
    try:
        f = _fields(line)
        if f is None:
            return ("ERR", "crc")
        if f[0] == "QRF":
            return ("QRF", _frame(f))
        if f[0] == "QRM":
            return ("QRM", _measurement(f))
        if f[0] == "QRA":
            return ("QRA", _answer(f))
        if not 1 <= len(f[0]) <= 8:
            raise ValueError("talker")
        for c in f[0]:
            if not ("A" <= c <= "Z" or c in DIGITS):
                raise ValueError("talker")
        return ("OTHER", None)
    except (ValueError, UnicodeError):
        return ("ERR", "format")


def command(name, arg=None):
    """The bytes of a command to qrfield: command("MEAS", 10) -> b"$QRC,MEAS,10*8593\\r\\n"."""
    body = ("QRC," + name + ("" if arg is None else "," + str(arg))).encode()
    crc = crc16(body)
    return b"$" + body + b"*" + "".join(HEX[(crc >> s) & 15] for s in (12, 8, 4, 0)).encode() + b"\r\n"


class Reader:
    """Collects bytes into lines (resynchronising on '$', a line ends at CR or LF). ``feed_all``
    returns every good line completed, as ("QRF" | "QRM" | "QRA", tuple); ``bad`` counts the lines
    dropped (CRC, format, length)."""

    def __init__(self):
        self.buf = bytearray()
        self.active = False
        self.overflow = False
        self.bad = 0

    def feed_all(self, data):
        items = []
        for byte in data:
            if byte == 36:  # '$' starts a line, whatever came before
                self.buf = bytearray(b"$")
                self.active, self.overflow = True, False
            elif not self.active:
                continue  # garbage between lines, or the LF after a CR
            elif byte == 10 or byte == 13:
                self.active = False
                kind, item = ("ERR", "length") if self.overflow else parse(bytes(self.buf))
                if kind == "ERR":
                    self.bad += 1
                elif kind != "OTHER":
                    items.append((kind, item))
            elif len(self.buf) >= MAX_BODY:
                self.overflow = True
            else:
                self.buf.append(byte)
        return items

    def feed(self, data):
        """Only the $QRF lines of ``data``."""
        return [item for kind, item in self.feed_all(data) if kind == "QRF"]
