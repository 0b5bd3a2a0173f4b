"""Text from a user or a file, checked once before use: the one path every text input goes through.

Python keeps bytes that are not UTF-8 as lone surrogates: ``sys.argv`` and ``os.environ`` decode
them with the ``surrogateescape`` handler (a name typed in Latin-1, ``$'\\xff'``), and JSON's
``"\\ud800"`` escape gives one too. Such a string cannot be written as UTF-8, and OpenCV's Python
binding, handed one (a QR text, a file name, an image suffix), crashes the process with a
segmentation fault instead of raising. So :func:`check_text` refuses a text that is not
representable in UTF-8 with one line naming where it came from and where the bad character is,
and :func:`check_path_for_library` does the same for a path handed to a C library (Python's own
file functions take such paths as they are).

Used by: the settings (every text setting, from app.json or ``--virtual-text``), the readers of
qrfield's files (:mod:`qrfield.files`), the QR encoder (:func:`qrfield.render.qr_symbol`, hence
``render``, ``marker`` and the virtual bench), sessions (name, operator, notes, combination, note)
and every path given to OpenCV.
"""

from __future__ import annotations

import os
from typing import Any


class TextError(ValueError):
    """A text that cannot be used: not text, not representable in UTF-8, or too long."""


def unencodable_at(text: str) -> int:
    """Index of the first character of ``text`` that UTF-8 cannot encode (a lone surrogate), or -1."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        return exc.start
    return -1


def check_text(value: Any, where: str, *, max_chars: int | None = None) -> str:
    """``value`` if it is a str that UTF-8 can encode (and at most ``max_chars`` long), else
    TextError: ``WHERE: not UTF-8 text (character 3 is U+DCFF, the byte 0xFF, which is not UTF-8)``."""
    if not isinstance(value, str):
        raise TextError(f"{where}: expected text, got {type(value).__name__}")
    bad = unencodable_at(value)
    if bad >= 0:
        code = ord(value[bad])
        origin = (
            f"the byte 0x{code - 0xDC00:02X}, which is not UTF-8"
            if 0xDC80 <= code <= 0xDCFF
            else "a lone surrogate, which is no character"
        )
        raise TextError(f"{where}: not UTF-8 text (character {bad + 1} is U+{code:04X}, {origin})")
    if max_chars is not None and len(value) > max_chars:
        raise TextError(f"{where}: {len(value)} characters long, more than {max_chars}")
    return value


def check_path_for_library(path: str | os.PathLike[str], where: str) -> str:
    """``path`` as a str a C library (OpenCV) can take: TextError when its name is not UTF-8."""
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    try:
        return check_text(text, where)
    except TextError as exc:
        raise TextError(f"{exc}; OpenCV cannot take such a file name: rename the file") from None
