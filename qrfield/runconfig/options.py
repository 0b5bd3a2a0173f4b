"""The command-line options of the run configuration: ``--config-dir`` and one option per setting."""

from __future__ import annotations

import argparse

from qrfield.runconfig.run_settings import RunSettings
from qrfield.runconfig.sections import sections


def add_config_dir_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config-dir",
        default=None,
        metavar="DIR",
        help="the folder of app.json, the settings the app saves (default $QRFIELD_CONFIG_DIR or "
        "~/.config/qrfield)",
    )


def add_run_arguments(
    parser: argparse.ArgumentParser, *, only: tuple[str, ...] | None = None, run_skip: tuple[str, ...] = ()
) -> None:
    """``--config-dir`` and one option per setting of the run configuration (default None: the
    value comes from the file, else the declared default). ``only`` limits the sections,
    ``run_skip`` the settings of the run section."""
    from qrfield.arguments import add_side_argument
    from qrfield.camera import add_camera_arguments
    from qrfield.settings import add_arguments

    add_config_dir_argument(parser)
    for section in sections().values():
        if only is not None and section.name not in only:
            continue
        group = parser.add_argument_group(f"{section.title} (section {section.name!r} of app.json)")
        if section.cls is RunSettings:
            add_arguments(group, RunSettings, skip=("camera", "side_mm", *run_skip))
            if "camera" not in run_skip:
                add_camera_arguments(group, default=None)
            if "side_mm" not in run_skip:  # the one --side-mm of every command (qrfield.limits)
                add_side_argument(group, configured="the run configuration's, else 50")
        elif section.name == "serial":
            group.add_argument(
                "--serial",
                metavar="PORT",
                nargs="?",
                const="",
                default=None,
                help="send every frame's pose as a $QRF line and answer $QRC commands on PORT "
                "(/dev/ttyUSB0, COM3, loop://); without PORT, the configured serial port (refused when "
                "that is loop://, the simulated port, unless --serial-port names it)",
            )
            add_arguments(group, section.cls, prefix=section.prefix)
        else:
            add_arguments(group, section.cls, prefix=section.prefix)
            if section.name == "detector":
                group.add_argument(
                    "--select-text", dest="detect_select_text", metavar="TEXT", help="= --detect-select-text"
                )
                group.add_argument(
                    "--max-codes", dest="detect_max_codes", metavar="N", type=int, help="= --detect-max-codes"
                )
