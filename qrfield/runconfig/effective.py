"""The effective settings: command line over the file over the default, each value with its origin."""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from typing import Any

from qrfield.methods import METHODS, methods_from_choice
from qrfield.runconfig.config import RunConfig
from qrfield.runconfig.run_settings import RunSettings
from qrfield.runconfig.sections import Section, sections
from qrfield.runconfig.store import ConfigStore
from qrfield.settings import SettingError, from_dict, specs, to_dict

#: Where a value came from (:func:`effective_settings`).
FROM_DEFAULT, FROM_FILE, FROM_COMMAND_LINE = "default", "config file", "command line"


@dataclass(frozen=True)
class Value:
    """One effective setting: its value, where it came from, and the option that sets it."""

    section: str
    name: str
    value: Any
    origin: str
    option: str
    unit: str = ""


@dataclass
class Effective:
    """The effective settings of every section, with their origins (see :func:`effective_settings`)."""

    store: ConfigStore
    groups: dict[str, Any]
    values: list[Value]
    camera: Any = None  # the CameraModel
    serial_port: str | None = None  # the port when --serial was given, else None

    def origin(self, section: str, name: str) -> str:
        return next(v.origin for v in self.values if v.section == section and v.name == name)

    def assumed(self) -> list[str]:
        """Notes for settings nobody chose that change every number measured (camera, QR side)."""
        notes = []
        if self.origin("run", "camera") == FROM_DEFAULT:
            notes.append(f"camera model: {self.camera.name} assumed (name yours with --camera or in the app)")
        if self.origin("run", "side_mm") == FROM_DEFAULT:
            side = self.groups["run"].side_mm
            notes.append(
                f"QR side: {side:g} mm assumed (measure your code's symbol without its quiet zone and give "
                "--side-mm, or set it in the app): every position scales with it"
            )
        return notes

    def run_config(
        self, *, camera: Any = None, pace: bool | None = None, allow_virtual: bool = True
    ) -> RunConfig:
        """The RunConfig of these settings (``camera``: another camera model, e.g. a session's)."""
        g = self.groups
        camera = camera if camera is not None else self.camera
        run: RunSettings = g["run"]
        # picamera2 is sized from the camera model unless its own size was chosen (file or option).
        picamera_chosen = any(v.origin != FROM_DEFAULT for v in self.values if v.section == "picamera")
        picamera = g["picamera"]
        if {self.origin("picamera", "width"), self.origin("picamera", "height")} == {FROM_DEFAULT}:
            picamera = dataclasses.replace(picamera, width=camera.width, height=camera.height)
        return RunConfig(
            source=run.source,
            camera=camera,
            side_mm=run.side_mm,
            methods=methods_from_choice(run.method),
            solver_settings={name: g[name] for name in METHODS},
            detector_settings=g["detector"],
            virtual=g["virtual"],
            loop=run.loop,
            picamera=picamera if picamera_chosen else None,
            usb=g["usb"],
            pace=run.pace if pace is None else pace,
            retry_s=run.retry_s,
            allow_virtual=allow_virtual,
            stream=g["stream"],
        )

    def serial_settings(self) -> Any:
        """The serial link's settings, with the port of ``--serial PORT`` when one was given."""
        settings = self.groups["serial"]
        return dataclasses.replace(settings, port=self.serial_port) if self.serial_port else settings


def effective_settings(
    args: argparse.Namespace | None = None,
    *,
    config_dir: Any = None,
    resolve_camera: bool = True,
    strict: bool = False,
) -> Effective:
    """Every setting of the run configuration: command line over the file over the default.

    ``args``: options added by :func:`add_run_arguments` (None = the file alone). Raises
    SettingError (a ValueError) naming a bad command-line value, CameraModelError for a camera that
    cannot be resolved (``resolve_camera`` False: not resolved, ``camera`` is None). ``strict``: a
    bad value in the file that would be used raises SettingError naming the file and the key (a
    headless run must not run on a default nobody chose), instead of a note and the default.
    """
    from qrfield.camera import camera_from_args
    from qrfield.camera import resolve_camera as resolve

    directory = getattr(args, "config_dir", None) if args is not None else config_dir
    store = ConfigStore(directory)
    groups: dict[str, Any] = {}
    values: list[Value] = []
    for section in sections().values():
        groups[section.name], section_values = _section_settings(section, store, args, strict)
        values += section_values
    camera: Any = None
    focal_given = args is not None and (
        getattr(args, "focal_px", None) is not None or getattr(args, "size", None) is not None
    )
    if focal_given:
        camera = camera_from_args(args)
        groups["run"] = dataclasses.replace(groups["run"], camera=camera.name)
        _set_origin(values, "run", "camera", camera.name, FROM_COMMAND_LINE, "--focal-px/--size")
    elif resolve_camera:
        camera = resolve(groups["run"].camera)
    port = getattr(args, "serial", None) if args is not None else None
    serial_port = None
    if port is not None:
        from qrfield.serial.port import LOOP_URL

        configured = groups["serial"].port
        origin = next(v.origin for v in values if v.section == "serial" and v.name == "port")
        if not port and configured == LOOP_URL and origin != FROM_COMMAND_LINE:
            # loop:// sends nothing anywhere, and it is both the default and what the app saves when
            # its Serial tab was never set: a bare --serial on the robot streamed there, "connected",
            # while the controller got nothing (audit-1). --serial-port loop:// is a choice: kept.
            where = "none, so it is the default, " if origin == FROM_DEFAULT else ""
            raise SettingError(
                f"--serial without PORT takes the configured port, and {store.path} names {where}"
                f"{LOOP_URL}: the simulated port, which sends nothing anywhere; give --serial PORT "
                f"(/dev/ttyUSB0, COM3), or --serial {LOOP_URL} to test"
            )
        serial_port = port or configured
        if port:
            _set_origin(values, "serial", "port", port, FROM_COMMAND_LINE, "--serial")
    return Effective(store, groups, values, camera, serial_port)


def _section_settings(
    section: Section, store: ConfigStore, args: argparse.Namespace | None, strict: bool
) -> tuple[Any, list[Value]]:
    """One section's settings (command line over the file over the default) and each value's origin;
    SettingError as :func:`effective_settings` says."""
    saved = store.group(section.name, section.cls)
    in_file = store.saved_keys(section.name)
    data = to_dict(saved)
    origins = {}
    for spec in specs(section.cls):
        option = "--" + (section.prefix + spec.name).replace("_", "-")
        given = getattr(args, f"{section.prefix}{spec.name}", None) if args is not None else None
        if given is not None:
            try:
                data[spec.name] = spec.validate(given)
            except SettingError as exc:
                raise SettingError(f"{option} {given}: {exc}") from None
            origins[spec.name] = (FROM_COMMAND_LINE, option)
        elif spec.name in in_file and _saved_ok(store, section, spec):
            origins[spec.name] = (FROM_FILE, option)
        elif spec.name in in_file and strict:
            try:
                spec.validate(store.value(section.name)[spec.name])
            except SettingError as exc:
                raise SettingError(f"{store.path}: key {section.name}.{spec.name}: {exc}") from None
        elif strict and f"{section.name}.{spec.name}" in store.dropped:
            raise SettingError(store.dropped[f"{section.name}.{spec.name}"].removesuffix("; default used"))
        else:
            origins[spec.name] = (FROM_DEFAULT, option)
    instance = from_dict(section.cls, data)
    values = []
    for spec in specs(section.cls):
        origin, option = origins[spec.name]
        values.append(Value(section.name, spec.name, getattr(instance, spec.name), origin, option, spec.unit))
    return instance, values


def _saved_ok(store: ConfigStore, section: Section, spec: Any) -> bool:
    raw = store.value(section.name)
    try:
        spec.validate(raw[spec.name])
    except (SettingError, KeyError, TypeError):
        return False
    return True


def _set_origin(values: list[Value], section: str, name: str, value: Any, origin: str, option: str) -> None:
    for k, v in enumerate(values):
        if v.section == section and v.name == name:
            values[k] = dataclasses.replace(v, value=value, origin=origin, option=option)
