"""Command-line values: the parser every command is built with, one parser for comma lists of
numbers, and number options checked against :mod:`qrfield.limits`.

argparse takes any word that starts with '-' and is not a plain negative number for an option,
so ``--pose -10,5,300,0,0,0`` failed with "expected one argument". :class:`ArgumentParser` reads a
word that starts with '-' followed by a digit (or '.' and a digit) as a value: qrfield has no
option that starts with a digit, so such a word can only be a negative number or a list of them.
Every subcommand parser is made by ``add_subparsers`` of the top parser, so every option of every
command, including options added later, gets this. ``--pose=-10,...`` works as well.

Errors are one line, ``qrfield CMD: error: ... (see qrfield CMD --help)``, with exit code 2.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from qrfield.limits import Limit, LimitError

#: A word that is a value, not an option: '-' then a digit, or '-.' then a digit, or a negative
#: infinity or NaN (refused as not finite by the option's type, not taken for an unknown option).
_VALUE_WORD = re.compile(r"^-(\.?\d|(inf|infinity|nan)$)", re.IGNORECASE)
#: How alike a mistyped word must be to a known one to be suggested (difflib's ratio).
SUGGEST_CUTOFF = 0.6

#: Separators of :func:`parse_numbers`: commas, semicolons, white space.
_SEPARATORS = re.compile(r"[,;\s]+")

#: Text for help messages.
NEGATIVE_VALUES_HELP = (
    "values may start with '-': --pose -10,5,300,0,0,0 and --pose=-10,5,300,0,0,0 both work"
)


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser that takes ``-10,5,300`` as a value, reports errors in one line, and
    suggests the nearest option or choice for a mistyped one ("did you mean --side-mm?").

    Python 3.14's ``suggest_on_error`` does the same, but qrfield runs on 3.11: every parser of
    every subcommand is of this class (``add_subparsers`` makes its parsers with the parent's
    class), so each one suggests among its own options.
    """

    def _parse_optional(self, arg_string: str) -> Any:
        if _VALUE_WORD.match(arg_string):
            return None  # a value (a negative number or a list of them), never an option
        return super()._parse_optional(arg_string)

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        words = list(sys.argv[1:] if args is None else args)
        self._refuse_unknown_options(words)  # before argparse says a required option is missing
        return super().parse_known_args(words, namespace)

    def _refuse_unknown_options(self, words: list[str]) -> None:
        """Error, with the nearest known option, for the first word argparse would take for an
        option this parser does not have; the words from a subcommand's name on are its own."""
        commands = {
            name
            for action in self._actions
            if isinstance(action, argparse._SubParsersAction)
            for name in action.choices
        }
        for word in words:
            if word == "--" or word in commands:
                return
            found = self._parse_optional(word)
            if found is None:
                continue
            # (action, option, ...) on Python 3.11, a list of such on 3.12 and later
            options = found if isinstance(found, list) else [found]
            if all(option[0] is None for option in options):
                name = word.partition("=")[0]
                self.error(f"unrecognized option {name}{self._suggestion(name, self._option_words())}")

    def _check_value(self, action: argparse.Action, value: Any) -> None:
        if action.choices is not None and value not in action.choices:
            choices = [str(c) for c in action.choices]
            shown = ", ".join(map(repr, choices))
            raise argparse.ArgumentError(
                action, f"invalid choice: {value!r} (choose from {shown}){self._suggestion(value, choices)}"
            )

    def _option_words(self) -> list[str]:
        return [word for action in self._actions for word in action.option_strings]

    @staticmethod
    def _suggestion(word: Any, known: Sequence[str]) -> str:
        """``; did you mean X?`` for the known word nearest ``word``, "" when none is near."""
        import difflib

        if not isinstance(word, str):
            return ""
        matches = difflib.get_close_matches(word, known, n=1, cutoff=SUGGEST_CUTOFF)
        return f"; did you mean {matches[0]}?" if matches else ""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


_CONTROL = re.compile(r"[\x00-\x1f\x7f\x85\u2028\u2029]")


def one_line(text: str) -> str:
    """``text`` with line breaks and other control characters shown escaped (``\\n``, ``\\x00``), so
    that a message quoting what the user typed stays one line."""
    return _CONTROL.sub(lambda m: repr(m.group())[1:-1], str(text))


def split_list(text: str) -> list[str]:
    """The items of a command-line list (docs/cli.md: commas, semicolons or spaces separate them),
    empty items dropped: ``"-10, 5;300 0"`` -> ``["-10", "5", "300", "0"]``."""
    return [p for p in _SEPARATORS.split(text.strip()) if p]


def parse_numbers(
    text: Any,
    where: str,
    *,
    count: int | None = None,
    names: Sequence[str] | None = None,
) -> list[float]:
    """The finite numbers of a list such as ``-10,5,300,0,0,0`` (commas, semicolons or spaces).

    ``count``: how many are required (also ``len(names)``); ``names`` name the values in messages
    (e.g. ``("X", "Y", "Z", "A", "B", "G")``). ValueError naming ``where`` (the option) and the value.
    """
    if names is not None and count is None:
        count = len(names)
    if not isinstance(text, str):
        raise ValueError(f"{where}: expected a comma-separated list of numbers, got {text!r}")
    parts = split_list(text)
    if count is not None and len(parts) != count:
        shape = ",".join(names) if names else f"{count} numbers"
        raise ValueError(
            f"{where}: expected {count} comma-separated numbers {shape}, got {len(parts)}: {text!r}"
        )
    values = []
    for i, part in enumerate(parts):
        label = names[i] if names else f"value {i + 1}"
        try:
            value = float(part)
        except ValueError:
            raise ValueError(f"{where}: {label} {part!r} is not a number") from None
        if not math.isfinite(value):
            raise ValueError(f"{where}: {label} must be a finite number, got {part!r}")
        values.append(value)
    return values


def limited(limit: Limit, option: str) -> Callable[[str], float]:
    """An argparse ``type=`` for a number inside ``limit`` (the error names the option and limits)."""

    def parse(text: str) -> float:
        try:
            return limit.check(_number(text), option)
        except LimitError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f"{option}: ")) from None

    parse.__name__ = limit.label.replace(" ", "_")  # argparse names the type in some messages
    return parse


def text(option: str) -> Callable[[str], str]:
    """An argparse ``type=`` for a text option (a QR payload, a name, a note): refused in one line
    when it is not UTF-8 (:func:`qrfield.texts.check_text`), before anything is done with it."""
    from qrfield.texts import TextError, check_text

    def parse(value: str) -> str:
        try:
            return check_text(value, option)
        except TextError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f"{option}: ")) from None

    parse.__name__ = "text"
    return parse


def add_side_argument(parser: Any, default: float | None = None, *, configured: str = "") -> None:
    """``--side-mm L``: the QR symbol's side without its quiet zone (mm), checked against
    :data:`qrfield.limits.SIDE_MM`; required unless a ``default`` is given, or ``configured`` says
    where the value comes from when the option is left out (then its default is None)."""
    from qrfield.limits import SIDE_MM

    shown = f"; default {default:g}" if default is not None else ""
    shown += f"; default: {configured}" if configured else ""
    parser.add_argument(
        "--side-mm",
        type=limited(SIDE_MM, "--side-mm"),
        required=default is None and not configured,
        default=default,
        metavar="L",
        help=f"QR symbol side without quiet zone, mm ({SIDE_MM.describe()}{shown})",
    )


def number(
    option: str, minimum: float | None = None, maximum: float | None = None, unit: str = ""
) -> Callable[[str], float]:
    """An argparse ``type=`` for a finite number in ``minimum..maximum`` (either may be None)."""
    lo = -math.inf if minimum is None else minimum
    hi = math.inf if maximum is None else maximum
    return limited(Limit(option.lstrip("-").replace("-", " "), unit, lo, hi), option)


def whole_number(option: str, minimum: int | None = None, maximum: int | None = None) -> Callable[[str], int]:
    """An argparse ``type=`` for an int in ``minimum..maximum``."""

    def parse(text: str) -> int:
        try:
            if len(text.strip()) > 64:  # int() of thousands of digits is slow, and none is meant
                raise ValueError
            value = int(text.strip())
        except ValueError:
            shown = text if len(text) <= 40 else text[:40] + "..."
            raise argparse.ArgumentTypeError(f"expected a whole number, got {shown!r}") from None
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"{value} is below the smallest accepted, {minimum}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"{value} is above the largest accepted, {maximum}")
        return value

    parse.__name__ = "whole_number"
    return parse


def count(option: str, minimum: int = 0, maximum: int | None = None) -> Callable[[str], int]:
    """An argparse ``type=`` for a count of frames, lines, rows (``minimum``..``maximum``, by
    default :data:`qrfield.limits.MAX_COUNT`)."""
    from qrfield.limits import MAX_COUNT

    return whole_number(option, minimum, MAX_COUNT if maximum is None else maximum)


def seconds(option: str, minimum: float = 0.0) -> Callable[[str], float]:
    """An argparse ``type=`` for a duration in seconds up to :data:`qrfield.limits.DURATION_S`."""
    from qrfield.limits import DURATION_S

    return limited(Limit(DURATION_S.label, "s", minimum, DURATION_S.maximum), option)


def rate(option: str, minimum: float = 0.0) -> Callable[[str], float]:
    """An argparse ``type=`` for a rate in Hz up to :data:`qrfield.limits.RATE_HZ`."""
    from qrfield.limits import RATE_HZ

    return limited(Limit(RATE_HZ.label, "Hz", minimum, RATE_HZ.maximum), option)


def seed(option: str = "--seed") -> Callable[[str], int]:
    """An argparse ``type=`` for a noise seed, 0..:data:`qrfield.limits.MAX_SEED`."""
    from qrfield.limits import MAX_SEED

    return whole_number(option, 0, MAX_SEED)


def _number(text: str) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        raise LimitError(f"expected a number, got {text!r}") from None


def refuse_existing(path: str | os.PathLike[str], force: bool, what: str = "--out") -> None:
    """The command-line rule for a named output file: one that exists is refused unless
    ``--force`` (``force``); FileExistsError naming ``what`` and the file."""
    if not force and os.path.lexists(path):
        raise FileExistsError(f"{what} {path} exists; choose another name, or add --force to overwrite it")


def stdout_closed() -> None:
    """After BrokenPipeError on stdout (``qrfield solve ... | head``): point stdout at /dev/null, so
    that Python's exit flush cannot fail again and print "Broken pipe"."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        sys.stdout = None  # type: ignore[assignment]
