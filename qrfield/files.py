"""The user's files, read and written safely: one home for every reader's limits and every writer.

Reading (camera profiles, session.json, rows.csv, study and combination files, the app's settings):

- at most ``max_bytes`` are read (:data:`MAX_FILE_BYTES` unless the reader says otherwise), so a
  huge or endless file (``/dev/zero``) cannot fill the memory;
- text is UTF-8, and a leading byte-order mark (what spreadsheets and Windows editors write) is
  accepted and dropped;
- JSON and TOML nested deeper than :data:`MAX_DEPTH` are refused by a scan *before* parsing, so
  neither parser can recurse into a RecursionError;
- a text value longer than :data:`MAX_FIELD_CHARS` (the csv module's own field limit, 131,072
  characters: rows.csv could not be read back with one) is refused;
- every refusal is a :class:`FileFormatError` (a ValueError) of one line naming the file and what is
  wrong; :func:`describe_value` and :class:`Fields` name a value of the wrong type.

Writing: :func:`atomic_write` / :func:`atomic_file` write all or nothing through a temporary file
that :func:`tempfile.mkstemp` creates in the target's folder (``O_CREAT | O_EXCL``, an
unpredictable name, no symlink followed), fsynced and renamed over the target; ``overwrite=False``
publishes it with a hard link, which fails if the target appeared meanwhile. No writer creates a
folder above the one the user named (:func:`make_folder`); qrfield's own folders
(:mod:`qrfield.paths`) are created with their parents.

Damaged settings files: :func:`read_json_or_set_aside` renames a file that cannot be used to
``NAME.bad-<YYYYmmdd-HHMMSS>`` and says so in one line, so that defaults replace it without
losing it.
"""

from __future__ import annotations

import contextlib
import errno
import io
import itertools
import json
import os
import re
import stat
import tempfile
import time
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from qrfield.limits import LimitError, as_number
from qrfield.texts import TextError, check_text

#: Largest file a reader reads unless it says otherwise (bytes): far above any profile, session or
#: study file, far below what would hurt a Raspberry Pi.
MAX_FILE_BYTES = 16 * 1024 * 1024
#: Deepest nesting of JSON arrays/objects or TOML arrays/tables accepted (qrfield's own files nest
#: three or four levels).
MAX_DEPTH = 32
#: Longest text value accepted in any file, characters: the csv module's default field size limit,
#: so that every value qrfield writes to a CSV file can be read back.
MAX_FIELD_CHARS = 131_072

_BOM = "\ufeff"
#: Longest digit run parsed as an integer: below sys.int_info.default_max_str_digits (4300), far
#: above any float.
_MAX_INT_DIGITS = 4000


class FileFormatError(ValueError):
    """A file that cannot be read or used; the message (one line) names the file and the problem.

    ``kind``: "missing" (no such file), "unreadable" (an OS error, not a regular file, too large)
    or "damaged" (not UTF-8, not JSON/TOML, too deep, a value too long or of the wrong type).
    """

    def __init__(self, message: str, kind: str = "damaged") -> None:
        super().__init__(message)
        self.kind = kind


# ---------------------------------------------------------------------------------------- values
def describe_value(value: Any, limit: int = 40) -> str:
    """A short description of a (JSON) value for messages: ``text 'abc'``, ``a list``, ``true``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        text = repr(value)
        return text if len(text) <= limit else text[:limit] + "..."
    if isinstance(value, str):
        shown = value if len(value) <= limit else value[:limit] + "..."
        return f"text {shown!r}" + (f" ({len(value)} characters)" if len(value) > limit else "")
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


class Fields:
    """Typed access to the fields of a JSON object; each wrong value is named with its file and key.

    ``where`` prefixes every message, e.g. ``"session file /a/session.json"``.
    """

    def __init__(self, data: Any, where: str) -> None:
        if not isinstance(data, dict):
            raise FileFormatError(f"{where}: expected a JSON object, got {describe_value(data)}")
        self.data = data
        self.where = where

    def _get(self, key: str, default: Any) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise FileFormatError(f"{self.where}: missing field '{key}'")
        return default

    def number(self, key: str, default: Any = None) -> float:
        """A finite number (JSON number; not true/false, not text, not too large for a float)."""
        value = self._get(key, _MISSING if default is None else default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise FileFormatError(
                f"{self.where}: field '{key}' must be a number, got {describe_value(value)}"
            )
        try:
            return as_number(value, f"{self.where}: field '{key}'", "the value")
        except LimitError as exc:
            raise FileFormatError(str(exc)) from None

    def integer(self, key: str, default: Any = None) -> int:
        """A whole number (3 or 3.0)."""
        value = self.number(key, default)
        if value != int(value):
            raise FileFormatError(f"{self.where}: field '{key}' must be a whole number, got {value!r}")
        return int(value)

    def text(self, key: str, default: str | None = None, max_chars: int = MAX_FIELD_CHARS) -> str:
        """A string of at most ``max_chars`` characters."""
        value = self._get(key, _MISSING if default is None else default)
        if not isinstance(value, str):
            raise FileFormatError(f"{self.where}: field '{key}' must be text, got {describe_value(value)}")
        if len(value) > max_chars:
            raise FileFormatError(
                f"{self.where}: field '{key}' is {len(value)} characters long, more than {max_chars}"
            )
        return value

    def mapping(self, key: str, default: dict[str, Any] | None = None) -> dict[str, Any]:
        """A JSON object."""
        value = self._get(key, _MISSING if default is None else default)
        if not isinstance(value, dict):
            raise FileFormatError(
                f"{self.where}: field '{key}' must be a JSON object, got {describe_value(value)}"
            )
        return value


_MISSING = object()


# ---------------------------------------------------------------------------------------- reading
def read_bytes(path: str | os.PathLike[str], what: str, max_bytes: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file, at most ``max_bytes``; FileFormatError naming ``what`` and the file."""
    path = Path(path)
    where = f"{what} {path}"
    try:
        # O_NONBLOCK: opening a FIFO must not wait for a writer; it is refused below like a folder.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise FileFormatError(f"{where}: no such file", "missing") from None
    except OSError as exc:
        raise FileFormatError(f"{where}: cannot read ({exc.strerror or exc})", "unreadable") from None
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise FileFormatError(f"{where}: is a folder, not a file", "unreadable")
        if not stat.S_ISREG(mode):  # a FIFO, a device: it may never end
            raise FileFormatError(f"{where}: not a regular file", "unreadable")
        os.set_blocking(fd, True)
        with os.fdopen(fd, "rb") as handle:
            fd = -1
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise FileFormatError(f"{where}: cannot read ({exc.strerror or exc})", "unreadable") from None
    finally:
        if fd >= 0:
            os.close(fd)
    if len(data) > max_bytes:
        raise FileFormatError(
            f"{where}: larger than {max_bytes // (1024 * 1024)} MiB; not a file qrfield wrote", "unreadable"
        )
    return data


def decode_text(data: bytes, where: str) -> str:
    """UTF-8 text with a leading byte-order mark dropped; FileFormatError if not UTF-8."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{where}: not UTF-8 text (byte {exc.start})") from None
    return text[1:] if text.startswith(_BOM) else text


def read_text(path: str | os.PathLike[str], what: str, max_bytes: int = MAX_FILE_BYTES) -> str:
    """A UTF-8 text file (a BOM accepted), at most ``max_bytes``."""
    return decode_text(read_bytes(path, what, max_bytes), f"{what} {path}")


def _depth(brackets: str) -> int:
    """The deepest nesting of a string of only ``[]{}`` (openers +1, closers -1), in C-speed steps."""
    return max(itertools.accumulate(map(_STEP.__getitem__, brackets)), default=0)


_STEP = {"[": 1, "{": 1, "]": -1, "}": -1}


# Strings (and TOML comments) are removed before the brackets are counted. Each pattern matches up
# to its closing quote or else to the end of the text, so an unclosed string never makes the regex
# backtrack: the scan stays linear in the size of the file.
_JSON_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"?', re.S)
_TOML_SKIP = re.compile(
    r'"""(?:(?!""")[\s\S])*(?:""")?'
    r"|'''(?:(?!''')[\s\S])*(?:''')?"
    r'|"(?:[^"\\\n]|\\.)*"?'
    r"|'[^'\n]*'?"
    r"|#[^\n]*"
)
_NOT_BRACKETS = re.compile(r"[^\[\]{}]+")


def nesting_depth(text: str, language: str = "json") -> int:
    """How deeply arrays/objects (JSON) or arrays/inline tables (TOML) nest, strings and comments aside."""
    skip = _JSON_STRINGS if language == "json" else _TOML_SKIP
    return _depth(_NOT_BRACKETS.sub("", skip.sub("", text)))


def _check_values(value: Any, where: str, max_chars: int, path: str = "") -> None:
    """Refuse any text (key or value) longer than ``max_chars`` or not UTF-8 (a ``"\\ud800"``
    escape), and any number that is not a finite float (:func:`qrfield.limits.as_number`: a
    400-digit integer, ``1e400``), naming the key; depth is already bounded."""
    if isinstance(value, str):
        if len(value) > max_chars:
            raise FileFormatError(
                f"{where}: value {path or '(top)'} is {len(value)} characters long, more than {max_chars}"
            )
        try:
            check_text(value, f"{where}: value {path or '(top)'}")
        except TextError as exc:
            raise FileFormatError(str(exc)) from None
    elif isinstance(value, _TooLongInteger):
        raise FileFormatError(f"{where}: value {path or '(top)'}: {value.why()}")
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            as_number(value, f"{where}: value {path or '(top)'}", "the number")
        except LimitError as exc:
            raise FileFormatError(str(exc)) from None
    elif isinstance(value, dict):
        for key, item in value.items():
            if isinstance(key, str) and len(key) > max_chars:
                raise FileFormatError(f"{where}: a key is {len(key)} characters long, more than {max_chars}")
            try:
                check_text(key, f"{where}: a key in {path or '(top)'}")
            except TextError as exc:
                raise FileFormatError(str(exc)) from None
            _check_values(item, where, max_chars, f"{path}.{key}" if path else str(key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _check_values(item, where, max_chars, f"{path}[{i}]")


def loads_json(
    text: str,
    where: str,
    *,
    max_depth: int = MAX_DEPTH,
    max_chars: int = MAX_FIELD_CHARS,
    dropped: list[tuple[str, str]] | None = None,
) -> Any:
    """Parse JSON text with the depth and field-size limits; FileFormatError naming ``where``.

    ``dropped``: when given (a settings file, whose readers fall back to defaults key by key), a
    value inside an object that breaks a limit (a number that is not a finite float, a text too
    long or not UTF-8) is left out with its key instead of refusing the whole text, and (its dotted
    key, one line naming it) is appended to the list; the text as a whole (not JSON, too deep) is
    still refused.
    """
    if text.startswith(_BOM):
        text = text[1:]
    depth = nesting_depth(text, "json")
    if depth > max_depth:
        raise FileFormatError(
            f"{where}: nested {depth} levels deep, more than {max_depth}; not a qrfield file"
        )
    try:
        data = json.loads(
            text, parse_constant=_no_constant, parse_int=_parse_int if dropped is None else _lenient_int
        )
    except _LongInteger as exc:
        raise FileFormatError(f"{where}: {exc.describe(text)}") from None
    except json.JSONDecodeError as exc:
        raise FileFormatError(
            f"{where}: not JSON ({exc.msg} at line {exc.lineno} column {exc.colno})"
        ) from None
    except ValueError as exc:  # NaN / Infinity, or a number too long for int()
        raise FileFormatError(f"{where}: not JSON ({exc})") from None
    except RecursionError:  # pragma: no cover - the scan above bounds the depth
        raise FileFormatError(f"{where}: nested too deeply") from None
    if dropped is not None and isinstance(data, dict):
        return _without_bad_values(data, where, max_chars, dropped)
    _check_values(data, where, max_chars)
    return data


def _without_bad_values(
    data: dict, where: str, max_chars: int, dropped: list[tuple[str, str]], path: str = ""
) -> dict:
    """``data`` without the keys whose value (or name) breaks a limit of :func:`_check_values`;
    objects are cleaned key by key, a list or a scalar is kept or left out whole."""
    kept = {}
    for key, item in data.items():
        here = f"{path}.{key}" if path else str(key)
        try:
            _check_values({key: {} if isinstance(item, dict) else item}, where, max_chars, path)
        except FileFormatError as exc:
            dropped.append((here, str(exc)))
            continue
        if isinstance(item, dict):
            item = _without_bad_values(item, where, max_chars, dropped, here)
        kept[key] = item
    return kept


class _TooLongInteger:
    """A digit run too long for int() (over 4000 digits), kept in place of its value so that a
    lenient reader (:func:`loads_json` with ``dropped``) can name the key holding it."""

    __slots__ = ("digits",)

    def __init__(self, digits: str) -> None:
        self.digits = digits

    def why(self) -> str:
        count = sum(ch.isdigit() for ch in self.digits)
        return f"the number is an integer of {count} digits, too large for a number"


def _lenient_int(digits: str) -> int | _TooLongInteger:
    return _TooLongInteger(digits) if len(digits) > _MAX_INT_DIGITS else int(digits)


class _LongInteger(ValueError):
    """An integer in JSON text longer than Python's int() takes (4300 digits, sys.int_info)."""

    def __init__(self, digits: str) -> None:
        super().__init__(digits[:20])
        self.digits = digits

    def describe(self, text: str) -> str:
        """Where it is (the line and the key before it) and why, in qrfield's words for numbers."""
        at = text.find(self.digits)
        line = text.count("\n", 0, at) + 1
        before = text[max(0, at - 200) : at]
        key = re.search(r'"([^"\\]{1,80})"\s*:\s*$', before) or re.search(
            r"(?m)^\s*([\w.\-\"]{1,80})\s*=\s*$", before
        )
        why = _TooLongInteger(self.digits).why()
        return f"value {key.group(1)}: {why} (line {line})" if key else f"line {line}: {why}"


def _parse_int(digits: str) -> int:
    """int(), except that a digit run too long for it is refused in words, not with Python's advice
    to call sys.set_int_max_str_digits()."""
    if len(digits) > _MAX_INT_DIGITS:
        raise _LongInteger(digits)
    return int(digits)


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def read_json(
    path: str | os.PathLike[str],
    what: str,
    *,
    max_bytes: int = MAX_FILE_BYTES,
    max_depth: int = MAX_DEPTH,
    max_chars: int = MAX_FIELD_CHARS,
    dropped: list[tuple[str, str]] | None = None,
) -> Any:
    """Read a JSON file with every limit of this module; FileFormatError naming ``what`` and the file
    (``dropped``: as for :func:`loads_json`)."""
    where = f"{what} {path}"
    return loads_json(
        decode_text(read_bytes(path, what, max_bytes), where),
        where,
        max_depth=max_depth,
        max_chars=max_chars,
        dropped=dropped,
    )


def loads_toml(
    text: str, where: str, *, max_depth: int = MAX_DEPTH, max_chars: int = MAX_FIELD_CHARS
) -> dict:
    """Parse TOML text with the depth and field-size limits; FileFormatError naming ``where``."""
    if text.startswith(_BOM):
        text = text[1:]
    depth = nesting_depth(text, "toml")
    if depth > max_depth:
        raise FileFormatError(f"{where}: nested {depth} levels deep, more than {max_depth}")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FileFormatError(f"{where}: not valid TOML ({exc})") from None
    except RecursionError:  # e.g. dotted keys a.b.c... thousands deep, which the scan cannot see
        raise FileFormatError(f"{where}: nested too deeply") from None
    except ValueError:  # int() refused a decimal integer of more than 4300 digits
        run = re.search(r"[-+]?[0-9][0-9_]{4000,}", text)
        if run is None:
            raise
        raise FileFormatError(f"{where}: {_LongInteger(run.group()).describe(text)}") from None
    _check_values(data, where, max_chars)
    return data


def read_toml(path: str | os.PathLike[str], what: str, *, max_bytes: int = MAX_FILE_BYTES) -> dict:
    """Read a TOML file with every limit of this module; FileFormatError naming ``what`` and the file."""
    where = f"{what} {path}"
    return loads_toml(decode_text(read_bytes(path, what, max_bytes), where), where)


@dataclass(frozen=True)
class LoadedJson:
    """What :func:`read_json_or_set_aside` found.

    data: the JSON object (None when the file is missing or damaged).
    problem: one line for the user ("" when all is well or the file is simply missing).
    kept_as: where a damaged file was moved (None if it was not damaged, or could not be moved).
    damaged: the file exists but could not be used.
    dropped: (dotted key, one line) for each value left out of ``data`` (an absurd number, a text
        too long), its key's default used; the rest of the file is kept.
    """

    data: dict[str, Any] | None
    problem: str = ""
    kept_as: Path | None = None
    damaged: bool = False
    dropped: tuple[tuple[str, str], ...] = ()

    @property
    def safe_to_overwrite(self) -> bool:
        """False while a damaged file is still in place (it could not be moved): do not save over it."""
        return not self.damaged or self.kept_as is not None


def read_json_or_set_aside(path: str | os.PathLike[str], what: str = "settings file") -> LoadedJson:
    """Read a JSON object (a settings file); a damaged one is kept as ``NAME.bad-<time>``.

    A missing file gives ``LoadedJson(None)``; an unreadable one (permissions) is left where it is
    with a problem line; one that is not a usable JSON object (not UTF-8, not JSON, too deep, not an
    object) is renamed beside itself, and ``problem`` says where it went. A value that breaks a
    limit (a 500-digit number, a text too long) is only left out, named in ``dropped``: one absurd
    value does not cost the rest of the file.
    """
    path = Path(path)
    dropped: list[tuple[str, str]] = []
    try:
        data = read_json(path, what, dropped=dropped)
        if not isinstance(data, dict):
            raise FileFormatError(f"{what} {path}: expected a JSON object, got {describe_value(data)}")
    except FileFormatError as exc:
        if exc.kind == "missing":
            return LoadedJson(None)
        if exc.kind == "unreadable":
            return LoadedJson(None, f"{exc}; defaults used (the file is left as it is)", None, True)
        try:
            kept = set_aside(path)
        except OSError as move:
            return LoadedJson(
                None,
                f"{exc}; could not keep it aside ({move.strerror or move}); defaults used, "
                "and the file will not be overwritten",
                None,
                True,
            )
        return LoadedJson(None, f"{exc}; kept as {kept.name}, defaults used", kept, True)
    return LoadedJson(data, dropped=tuple((key, f"{line}; default used") for key, line in dropped))


def set_aside(path: str | os.PathLike[str]) -> Path:
    """Rename ``path`` to ``NAME.bad-<YYYYmmdd-HHMMSS>`` beside it (a free name); returns the new path."""
    path = Path(path)
    target = unique_path(path.with_name(f"{path.name}.bad-{time.strftime('%Y%m%d-%H%M%S')}"))
    os.rename(path, target)
    fsync_dir(path.parent)
    return target


def unique_path(path: Path) -> Path:
    """``path`` if free, else ``path`` with -1, -2, ... appended."""
    if not os.path.lexists(path):
        return path
    for k in range(1, 10000):
        candidate = path.with_name(f"{path.name}-{k}")
        if not os.path.lexists(candidate):
            return candidate
    raise FileExistsError(f"no free name beside {path}")


# ---------------------------------------------------------------------------------------- writing
def fsync_dir(path: str | os.PathLike[str]) -> None:
    """fsync a directory so that a new or renamed entry in it survives a power cut (POSIX only)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return  # e.g. Windows: directories cannot be opened; the rename is still atomic
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _umask() -> int:
    try:  # Linux: read it without changing it (os.umask would, for every thread)
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return 0o022


def _file_mode(path: Path) -> int:
    """The mode of the file being replaced, else what open() would give a new one (0666 & ~umask)."""
    try:
        st = os.stat(path, follow_symlinks=False)
        if not os.path.islink(path):
            return st.st_mode & 0o7777
    except OSError:
        pass
    return 0o666 & ~_umask()


def check_target(path: str | os.PathLike[str], what: str = "") -> Path:
    """``path`` as a file to write: not a folder, in a folder that exists (which is never created)."""
    path = Path(path)
    label = f"{what} {path}" if what else str(path)
    folder = path.parent
    check_name_lengths(path, f"cannot write {label}")
    if path.is_dir():
        raise IsADirectoryError(f"{label} is a folder; give a file name")
    if not folder.is_dir():
        raise FileNotFoundError(
            f"cannot write {label}: folder {folder} does not exist (qrfield creates no folders you "
            "did not name; make it first)"
        )
    return path


def describe_error(exc: BaseException) -> str:
    """The message of an error for the user: an OS error the system raised (``[Errno 36] File
    name too long: 'x'``) as ``x: file name too long``, one qrfield raised with an errno
    (``OSError(errno.ENAMETOOLONG, "cannot write x: ...")``) as its words alone; any other as it is."""
    text = str(exc)
    if isinstance(exc, OSError) and exc.strerror and text.startswith("[Errno"):
        where = exc.filename if exc.filename is not None else ""
        if where == "" and not exc.strerror[:1].isupper():  # qrfield's own words, not the system's
            return exc.strerror
        return f"{where}: {exc.strerror.lower()}" if where != "" else exc.strerror.lower()
    return text


def check_name_lengths(path: Path, where: str) -> None:
    """OSError (ENAMETOOLONG) saying so in words when a name in ``path`` is longer than its file
    system takes; called before is_dir() and friends, which raise ``[Errno 36]`` for such a name."""
    folder = path.parent
    try:
        longest = name_max(folder if folder.is_dir() else ".")
    except OSError:  # the folder's own name is too long: measured against the current folder's
        longest = name_max(".")
    size = max((len(os.fsencode(part)) for part in path.parts), default=0)
    if size > longest:
        raise OSError(
            errno.ENAMETOOLONG,
            f"{where}: a name in it is {size} bytes long, more than the {longest} the file system "
            "allows; choose a shorter name",
        )


def name_max(folder: str | os.PathLike[str]) -> int:
    """The longest file name (bytes) the file system of ``folder`` takes (255 where unknown)."""
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


#: Bytes ``tempfile.mkstemp`` adds to a prefix and suffix: eight random characters.
_TEMP_RANDOM = 8
_TEMP_SUFFIX = ".tmp"


def _temp_prefix(path: Path) -> str:
    """``.NAME.`` for the temporary file beside ``path``, shortened so that the temporary name
    fits the file system even when ``path``'s own name is as long as it allows."""
    room = name_max(path.parent) - _TEMP_RANDOM - len(_TEMP_SUFFIX) - 2
    name = path.name
    while len(os.fsencode(name)) > room and name:
        name = name[: max(0, min(len(name) - 1, room))]
    return f".{name}."


@contextlib.contextmanager
def atomic_file(
    path: str | os.PathLike[str],
    mode: str = "wb",
    *,
    overwrite: bool = True,
    encoding: str = "utf-8",
    newline: str | None = None,
) -> Iterator[IO[Any]]:
    """Write ``path`` all or nothing: ``with atomic_file(p, "w") as fh: fh.write(...)``.

    The data goes to a temporary file that ``tempfile.mkstemp`` makes in the target's folder
    (O_EXCL, unpredictable name, never through a planted symlink), is fsynced, and then replaces
    ``path`` (``overwrite=False``: FileExistsError if ``path`` exists, checked atomically by a hard
    link where the file system has them). An exception inside the block leaves ``path`` as it was.
    The folder must exist (:func:`check_target`).
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_file mode must be 'w' or 'wb', got {mode!r}")
    path = check_target(path)
    if not overwrite and os.path.lexists(path):
        raise FileExistsError(errno.EEXIST, "file exists", str(path))
    try:
        fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=_temp_prefix(path), suffix=_TEMP_SUFFIX)
    except OSError as exc:
        # The system names the temporary file, a random name the user never gave: name the target
        # (a read-only folder or medium said "x/.rows-clean.csv.u_1_5t6s.tmp: read-only file system").
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    tmp = Path(tmp_name)
    try:
        with contextlib.suppress(OSError):  # e.g. FAT file systems have no modes
            os.fchmod(fd, _file_mode(path))
        handle: IO[Any]
        if mode == "wb":
            handle = os.fdopen(fd, "wb")
        else:
            handle = os.fdopen(fd, "w", encoding=encoding, newline=newline)
        with handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        _publish(tmp, path, overwrite)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    fsync_dir(path.parent)


def _publish(tmp: Path, path: Path, overwrite: bool) -> None:
    if overwrite:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)  # fails with EEXIST if the target appeared meanwhile: never clobbered
    except FileExistsError:
        raise FileExistsError(errno.EEXIST, "file exists", str(path)) from None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
            raise
        # A file system without hard links (FAT on a USB stick): check, then rename.
        if os.path.lexists(path):
            raise FileExistsError(errno.EEXIST, "file exists", str(path)) from None
        os.replace(tmp, path)
        return
    tmp.unlink()


def atomic_write(
    path: str | os.PathLike[str], data: bytes | str, *, overwrite: bool = True, encoding: str = "utf-8"
) -> Path:
    """Write ``data`` (bytes, or text in ``encoding``) to ``path`` all or nothing; returns ``path``."""
    payload = data.encode(encoding) if isinstance(data, str) else bytes(data)
    with atomic_file(path, "wb", overwrite=overwrite) as handle:
        view = memoryview(payload)
        while view:
            view = view[handle.write(view) :]
    return Path(path)


def atomic_write_json(path: str | os.PathLike[str], data: Any, **json_options: Any) -> Path:
    """``data`` as indented UTF-8 JSON (plus a newline), written all or nothing."""
    options = {"indent": 2, **json_options}
    return atomic_write(path, json.dumps(data, **options) + "\n")


def own_folders() -> tuple[Path, ...]:
    """qrfield's own folders (config, data and sessions, :mod:`qrfield.paths`): created with their
    parents."""
    from qrfield import paths

    return (paths.config_dir(), paths.data_dir(), paths.sessions_dir())


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.absolute().relative_to(folder.absolute())
    except ValueError:
        return False
    return True


def make_folder(folder: str | os.PathLike[str], what: str = "folder") -> Path:
    """Make sure ``folder`` exists, creating no folder the user did not name.

    A folder inside qrfield's own folders (:func:`own_folders`) is created with its parents; any
    other folder is created only when its parent exists (the user named it; qrfield never creates
    the folders above it). FileNotFoundError / NotADirectoryError say which.
    """
    folder = Path(folder)
    where = f"{what} {folder}: cannot create the folder"
    check_name_lengths(folder, where)
    if folder.is_dir():
        return folder
    if os.path.lexists(folder):
        raise NotADirectoryError(f"{where}: a file of that name exists")
    try:
        if any(_inside(folder, own) for own in own_folders()):
            folder.mkdir(parents=True, exist_ok=True)
            return folder
        parent = folder.parent
        if os.path.lexists(parent) and not parent.is_dir():
            raise NotADirectoryError(f"{where}: {parent} is a file, not a folder")
        if not parent.is_dir():
            raise FileNotFoundError(
                f"{where}: {parent} does not exist (qrfield creates no folders above the one you named; "
                "make it first)"
            )
        folder.mkdir(exist_ok=True)
    except (FileNotFoundError, NotADirectoryError):
        raise
    except OSError as exc:
        raise OSError(f"{where} ({exc.strerror or exc})") from None
    fsync_dir(folder.parent)
    return folder


def csv_text_reader(text: str) -> Iterator[list[str]]:
    """``csv.reader`` over text, with its field limit set to :data:`MAX_FIELD_CHARS` (the default)."""
    import csv

    if csv.field_size_limit() != MAX_FIELD_CHARS:  # someone raised or lowered it: ours is the rule
        csv.field_size_limit(MAX_FIELD_CHARS)
    return csv.reader(io.StringIO(text))


def check_field_sizes(values: Mapping[str, str], where: str, max_chars: int = MAX_FIELD_CHARS) -> None:
    """Refuse (ValueError naming the field) any value longer than ``max_chars`` before it is written."""
    for name, value in values.items():
        if len(value) > max_chars:
            raise FileFormatError(
                f"{where}: field '{name}' is {len(value)} characters long, more than {max_chars} "
                "(a CSV reader could not read it back); shorten it"
            )
