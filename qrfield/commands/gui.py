"""``qrfield gui`` (also ``qrfield`` alone): the bench app window."""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys
from collections.abc import Callable
from typing import Any

HELP = "open the bench app window (the default when no subcommand is given)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from qrfield.arguments import add_side_argument, seconds
    from qrfield.methods import METHOD_CHOICES
    from qrfield.runconfig import add_config_dir_argument
    from qrfield.sources import SOURCE_HELP

    parser.add_argument(
        "--source", default=None, help=SOURCE_HELP + " (default: the last one used, else auto)"
    )
    parser.add_argument(
        "--camera", default=None, metavar="CAM", help="camera profile NAME[@WxH] or PATH.json"
    )
    add_side_argument(parser, configured="the last one used")
    parser.add_argument("--method", choices=METHOD_CHOICES, default=None, help="pose method(s)")
    add_config_dir_argument(parser)
    parser.add_argument(
        "--quit-after",
        type=seconds("--quit-after"),
        default=None,
        metavar="SECONDS",
        help="close the window after SECONDS (smoke tests)",
    )
    parser.add_argument(
        "--screenshot",
        default=None,
        metavar="FILE",
        help="with --quit-after: save the window as an image first",
    )
    parser.add_argument("--force", action="store_true", help="overwrite --screenshot if it exists")


def display_available() -> bool:
    """True when Qt can open a window: a display server, or an explicit QT_QPA_PLATFORM."""
    if os.environ.get("QT_QPA_PLATFORM"):
        return True
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


#: The apt package (Debian, Raspberry Pi OS, Ubuntu) of each shared library Qt loads.
QT_LIBRARY_PACKAGES = {
    "libEGL.so.1": "libegl1",
    "libGL.so.1": "libgl1",
    "libOpenGL.so.0": "libopengl0",
    "libGLX.so.0": "libglx0",
    "libxkbcommon.so.0": "libxkbcommon0",
    "libxkbcommon-x11.so.0": "libxkbcommon-x11-0",
    "libfontconfig.so.1": "libfontconfig1",
    "libfreetype.so.6": "libfreetype6",
    "libdbus-1.so.3": "libdbus-1-3",
    "libglib-2.0.so.0": "libglib2.0-0",
    "libgthread-2.0.so.0": "libglib2.0-0",
    "libX11.so.6": "libx11-6",
    "libX11-xcb.so.1": "libx11-xcb1",
    "libxcb.so.1": "libxcb1",
    "libxcb-cursor.so.0": "libxcb-cursor0",
    "libxcb-icccm.so.4": "libxcb-icccm4",
    "libxcb-image.so.0": "libxcb-image0",
    "libxcb-keysyms.so.1": "libxcb-keysyms1",
    "libxcb-randr.so.0": "libxcb-randr0",
    "libxcb-render-util.so.0": "libxcb-render-util0",
    "libxcb-shape.so.0": "libxcb-shape0",
    "libxcb-xkb.so.1": "libxcb-xkb1",
    "libSM.so.6": "libsm6",
    "libICE.so.6": "libice6",
    "libwayland-client.so.0": "libwayland-client0",
    "libwayland-cursor.so.0": "libwayland-cursor0",
    "libwayland-egl.so.1": "libwayland-egl1",
}
#: Libraries Qt 6's X11 ("xcb") platform plugin loads when the window opens; without one of them
#: Qt aborts with "Could not load the Qt platform plugin xcb" (libxcb-cursor0 since Qt 6.5).
XCB_PLUGIN_LIBRARIES = (
    "libxcb-cursor.so.0",
    "libxcb-icccm.so.4",
    "libxcb-image.so.0",
    "libxcb-keysyms.so.1",
    "libxcb-randr.so.0",
    "libxcb-render-util.so.0",
    "libxcb-shape.so.0",
    "libxcb-xkb.so.1",
    "libxkbcommon-x11.so.0",
)
GUI_EXTRA_HINT = (
    "install the app's extra: pip install 'qrfield[gui]' (from a checkout: pip install -e '.[gui]', or "
    "QRFIELD_GUI=1 ./run.sh); on 32-bit Raspberry Pi OS the app cannot run: it needs 64-bit "
    "Raspberry Pi OS (docs/install.md)"
)


def qt_problem(
    import_module: Callable[[str], Any] = importlib.import_module,
    library_missing: Callable[[str], bool] | None = None,
) -> str:
    """ "" when the app's Qt can start; else one line: which extra or which apt package to install.

    Imports PySide6 and pyqtgraph only to see whether they load (the core never uses Qt), and,
    when the window will use X11, looks for the libraries Qt's xcb plugin needs.
    """
    for name in ("PySide6.QtWidgets", "pyqtgraph"):
        try:
            import_module(name)
        except ModuleNotFoundError as exc:
            if (exc.name or "").split(".")[0] in ("PySide6", "pyqtgraph", "shiboken6"):
                return (
                    f"the bench app needs {exc.name.split('.')[0]}, which is not installed: {GUI_EXTRA_HINT}"
                )
            raise
        except ImportError as exc:  # Qt's own shared libraries
            found = re.search(r"(lib[\w.+-]+?\.so(?:\.\d+)*)", str(exc))
            library = found.group(1) if found else ""
            package = QT_LIBRARY_PACKAGES.get(library)
            if package:
                return f"Qt cannot load {library}: sudo apt install {package}"
            if library:
                return f"Qt cannot load {library} (apt-file search {library} names its package): {exc}"
            return f"Qt cannot be loaded: {exc}"
    platform = os.environ.get("QT_QPA_PLATFORM", "")
    if sys.platform.startswith("linux") and platform in ("", "xcb") and os.environ.get("DISPLAY"):
        if platform == "" and os.environ.get("WAYLAND_DISPLAY"):
            return ""  # Qt uses Wayland there
        missing = _missing_libraries(XCB_PLUGIN_LIBRARIES, library_missing)
        if missing:
            packages = " ".join(sorted({QT_LIBRARY_PACKAGES[lib] for lib in missing}))
            return f"Qt's X11 plugin needs {', '.join(missing)}, not installed: sudo apt install {packages}"
    return ""


def _missing_libraries(names: tuple[str, ...], library_missing: Callable[[str], bool] | None) -> list[str]:
    if library_missing is None:
        import ctypes

        def library_missing(name: str) -> bool:
            try:
                ctypes.CDLL(name)
            except OSError:
                return True
            return False

    return [name for name in names if library_missing(name)]


def check_arguments(args: argparse.Namespace) -> None:
    """Reject bad --side-mm, --camera and --quit-after before any window opens (ValueError naming it).

    The app would otherwise take them as they are (a negative QR side, a camera it cannot resolve).
    """
    from qrfield.camera import resolve_camera
    from qrfield.runconfig import RunSettings
    from qrfield.settings import from_dict

    if args.side_mm is not None:
        from_dict(RunSettings, {"side_mm": args.side_mm})  # its declared limits, in mm
    if args.camera is not None:
        resolve_camera(args.camera)  # CameraModelError naming the preset or file
    if args.quit_after is not None and not args.quit_after > 0:
        raise ValueError(f"--quit-after must be a positive number of seconds, got {args.quit_after}")
    if args.screenshot:
        from qrfield.arguments import refuse_existing
        from qrfield.files import check_target

        refuse_existing(check_target(args.screenshot, "--screenshot"), args.force, "--screenshot")


def run(args: argparse.Namespace) -> int:
    check_arguments(args)
    if not display_available():
        print(
            "qrfield: no display (DISPLAY and WAYLAND_DISPLAY are unset), so no window can open; "
            "run headless instead: qrfield run --headless --source auto --json-lines",
            file=sys.stderr,
        )
        return 3
    problem = qt_problem()
    if problem:
        print(f"qrfield gui: {problem}", file=sys.stderr)
        return 3
    from ui.app import main as app_main

    return app_main(args)
