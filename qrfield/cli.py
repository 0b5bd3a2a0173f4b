"""The ``qrfield`` command line: one subcommand per module in :mod:`qrfield.commands`.

Each command module defines ``HELP`` (one line), ``add_arguments(parser)`` and ``run(args) -> int``
(optionally ``ALIASES``, other names it answers to) and imports its heavy dependencies inside
``run`` so that ``qrfield --help`` stays fast.
No subcommand opens the bench app (``qrfield gui``).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import pkgutil
import sys
from collections.abc import Sequence

import qrfield
from qrfield import commands
from qrfield.arguments import NEGATIVE_VALUES_HELP, ArgumentParser, one_line, stdout_closed
from qrfield.camera import CameraModelError
from qrfield.files import describe_error


def command_names() -> list[str]:
    """Subcommand names: the modules of qrfield.commands, ``_`` spelled ``-``."""
    return sorted(
        m.name.replace("_", "-")
        for m in pkgutil.iter_modules(commands.__path__)
        if not m.name.startswith("_")
    )


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="qrfield",
        description="Measure the 3D position and orientation of a printed QR code from one camera. "
        "Without a subcommand, opens the bench app. Paths are taken from the current folder; "
        f"{NEGATIVE_VALUES_HELP}.",
    )
    parser.add_argument("--version", action="version", version=f"qrfield {qrfield.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in command_names():
        module = importlib.import_module(f"qrfield.commands.{name.replace('-', '_')}")
        description = getattr(module, "DESCRIPTION", module.HELP)
        sp = sub.add_parser(
            name,
            aliases=list(getattr(module, "ALIASES", ())),
            help=module.HELP,
            description=f"{description} ({NEGATIVE_VALUES_HELP}.)",
        )
        module.add_arguments(sp)
        sp.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    # A file name that is not UTF-8 (kept by Python as lone surrogates) is printed as the bytes it
    # was given, as ls does, instead of failing after the file is written (a strict UTF-8 locale).
    with contextlib.suppress(AttributeError, ValueError):
        sys.stdout.reconfigure(errors="surrogateescape")  # type: ignore[union-attr]
    parser = build_parser()
    if not argv or (argv[0].startswith("-") and argv[0] not in ("-h", "--help", "--version")):
        argv = ["gui", *argv]  # no subcommand: the app, with any options given
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error already printed in one line
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    if getattr(args, "config_dir", None):
        from qrfield import paths

        # One config folder for the whole command: the settings file and the camera profiles in it.
        paths.use_config_dir(args.config_dir)
    try:
        code = int(args._run(args) or 0)
        sys.stdout.flush()  # here, not at exit: a closed pipe must be caught below, not printed
        return code
    except BrokenPipeError:
        # The reader went away (`qrfield solve ... | head`): what it wanted it has; stop quietly.
        stdout_closed()
        return 0
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0] not in ("PySide6", "shiboken6", "pyqtgraph"):
            raise
        from qrfield.commands.gui import GUI_EXTRA_HINT  # e.g. `benchmark pipeline` measures the app too

        print(f"qrfield {args.command}: error: this needs {exc.name}: {GUI_EXTRA_HINT}", file=sys.stderr)
        return 3
    except (CameraModelError, ValueError, OSError) as exc:
        # Bad input is the user's to fix: one clear line, no traceback.
        print(f"qrfield {args.command}: error: {one_line(describe_error(exc))}", file=sys.stderr)
        return 2
    except Exception as exc:
        # OpenCV rejects bad arguments with cv2.error, not a ValueError (e.g. a QR text too long to
        # encode, reached from render, marker and the virtual bench): still the user's input to fix.
        cv2 = sys.modules.get("cv2")
        if cv2 is None or not isinstance(exc, cv2.error):
            raise
        detail = (getattr(exc, "err", "") or str(exc)).strip()
        print(f"qrfield {args.command}: error: OpenCV: {one_line(detail)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"qrfield {args.command}: interrupted", file=sys.stderr)
        return 130
