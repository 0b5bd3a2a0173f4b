"""One run configuration for the bench app, ``qrfield run`` and ``qrfield session log``.

What a frame loop measures with is declared once here, as settings groups (:mod:`qrfield.settings`),
each one section of one JSON file, ``<config folder>/app.json`` (:func:`qrfield.paths.config_dir`:
``--config-dir``, else ``$QRFIELD_CONFIG_DIR``, else ``~/.config/qrfield``):

=========== ============================ ======================================================
section     settings                     command-line options (override the file)
=========== ============================ ======================================================
run         :class:`RunSettings`         ``--source --camera --side-mm --method --loop --pace
                                         --retry-s`` (and ``--focal-px/--size`` for the camera)
detector    DetectorSettings             ``--detect-NAME`` (``--select-text``, ``--max-codes``: short forms)
numerical   NumericalSettings            ``--numerical-NAME``
ippe        IppeSettings                 ``--ippe-NAME``
virtual     VirtualBenchSettings         ``--virtual-NAME``
picamera    Picamera2Settings            ``--picamera-NAME``
usb         UsbCameraSettings            ``--usb-NAME``
serial      SerialLinkSettings           ``--serial-NAME`` (``--serial [PORT]`` turns the link on)
handeye     HandEyeSettings              ``--frame --handeye-file`` (poses in the tool or base frame)
stream      StreamSettings               ``--continuity --filter-s`` (the live stream: flips from
                                         history, the filter; docs/conventions.md)
=========== ============================ ======================================================

The app writes the file when it closes (with sections of its own: window, simulation, session
folder, ...); the commands read it and never write it. Unknown keys are ignored and bad values fall
back to their defaults with a note (:attr:`ConfigStore.problems`), so a damaged or older file never
stops the app (``qrfield run`` is strict: a bad value it would use stops it at start, naming the
file and the key, ``effective_settings(strict=True)``); a file that cannot be read as a JSON object
at all is kept as ``app.json.bad-<time>`` (whoever reads it first moves it aside, so the app never
saves defaults over it), with one line saying so. :func:`effective_settings` says where each value came from
(``qrfield config``).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from qrfield import paths
from qrfield.camera import DEFAULT_CAMERA
from qrfield.files import atomic_write_json, make_folder, read_json_or_set_aside
from qrfield.limits import SIDE_MM
from qrfield.methods import METHOD_CHOICES, METHODS, methods_from_choice
from qrfield.settings import SettingError, from_dict, setting, specs, to_dict

#: The one file of settings in the config folder.
CONFIG_FILE = "app.json"
#: Where a value came from (:func:`effective_settings`).
FROM_DEFAULT, FROM_FILE, FROM_COMMAND_LINE = "default", "config file", "command line"


@dataclass(frozen=True)
class RunSettings:
    """What to measure from and with: source, camera model, QR side, pose methods."""

    source: str = setting(
        "auto",
        label="source",
        help="auto (picamera2, then USB camera 0, then the virtual bench), virtual, picamera2, usb:N, "
        "or a video file / folder of images",
    )
    camera: str = setting(DEFAULT_CAMERA, label="camera model", help="preset NAME[@WxH] or PATH.json[@WxH]")
    side_mm: float = setting(
        50.0,
        label="QR side",
        unit="mm",
        minimum=SIDE_MM.minimum,
        maximum=SIDE_MM.maximum,
        decimals=1,
        help="side of the QR symbol without its quiet zone",
    )
    method: str = setting(
        "both",
        label="method",
        choices=METHOD_CHOICES,
        help="the thesis' numerical model, OpenCV IPPE, or both side by side (numerical gives the status)",
    )
    loop: bool = setting(False, label="loop files", help="a video file or folder starts again at its end")
    pace: bool = setting(
        False, label="pace files", help="play a video file at its own frame rate (a folder at 2 images/s)"
    )
    retry_s: float = setting(
        0.0,
        label="retry after",
        unit="s",
        minimum=0.0,
        maximum=3600.0,
        decimals=1,
        help="when the source fails, reopen it after this many seconds (0 = stop, or wait for Reopen)",
    )


@dataclass(frozen=True)
class Section:
    """One section of the file: its settings class and the prefix of its command-line options."""

    name: str
    cls: type
    prefix: str
    title: str


def sections() -> dict[str, Section]:
    """The run configuration's sections, in file order (imports the settings' modules)."""
    from qrfield.detect import DetectorSettings
    from qrfield.handeye.settings import HandEyeSettings
    from qrfield.serial.link import SerialLinkSettings
    from qrfield.solvers import settings_classes
    from qrfield.sources import Picamera2Settings, UsbCameraSettings, VirtualBenchSettings
    from qrfield.stream import StreamSettings

    solvers = settings_classes()
    table = [
        Section("run", RunSettings, "", "source, camera, QR side, methods"),
        Section("detector", DetectorSettings, "detect_", "QR detection and code selection"),
        Section("numerical", solvers["numerical"], "numerical_", "the thesis' numerical model"),
        Section("ippe", solvers["ippe"], "ippe_", "OpenCV IPPE"),
        Section("virtual", VirtualBenchSettings, "virtual_", "the virtual bench (--source virtual)"),
        Section("picamera", Picamera2Settings, "picamera_", "Raspberry Pi camera (--source picamera2)"),
        Section("usb", UsbCameraSettings, "usb_", "USB camera (--source usb:N)"),
        Section("serial", SerialLinkSettings, "serial_", "serial link to the gripper controller"),
        Section("handeye", HandEyeSettings, "", "the frame poses are reported in (docs/handeye.md)"),
        Section("stream", StreamSettings, "", "the live stream: flips resolved from history, the filter"),
    ]
    return {s.name: s for s in table}


class ConfigStore:
    """Loads and saves the settings groups of one JSON file (the app's and the run configuration's).

    ``problems`` lists what could not be restored (shown once by the app, on stderr by commands).
    """

    def __init__(self, directory: str | os.PathLike[str] | None = None) -> None:
        self.path = paths.config_dir(directory) / CONFIG_FILE
        self.problems: list[str] = []
        self._data: dict[str, Any] = {}
        self._can_save = True
        self.load()

    def load(self) -> None:
        """Read the file (qrfield.files' limits: size, nesting, a BOM accepted). A damaged file
        (not UTF-8, not JSON, too deep, not an object) is kept as ``app.json.bad-<time>`` beside
        itself and one line in ``problems`` says so; the defaults are used."""
        loaded = read_json_or_set_aside(self.path, "settings file")
        self._data = {}
        # False only while a damaged file is still in place (it could not be moved): never save over it.
        self._can_save = loaded.safe_to_overwrite
        if loaded.problem:
            self.problems.append(loaded.problem)
        data = loaded.data
        if data is None:
            return
        old = data.get("app")
        if "run" not in data and isinstance(old, dict):
            # Written before the run configuration had its own section: same fields, and the code
            # selection that now lives in the detector's section.
            data["run"] = old
            if "select_text" in old and isinstance(data.get("detector", {}), dict):
                data.setdefault("detector", {}).setdefault("select_text", old["select_text"])
        self._data = data

    def saved_keys(self, section: str) -> set[str]:
        """The keys of ``section`` present in the file (whether or not their values are good)."""
        raw = self._data.get(section)
        return set(raw) if isinstance(raw, dict) else set()

    def group(self, section: str, cls: type) -> Any:
        """The saved settings of ``section`` as ``cls`` (defaults for what is missing or bad)."""
        raw = self._data.get(section)
        if not isinstance(raw, dict):
            return cls()
        try:
            return from_dict(cls, raw, strict=False)
        except SettingError:
            # Keep each good value; drop only the bad ones, and say which.
            good = {}
            for key, value in raw.items():
                try:
                    from_dict(cls, {key: value}, strict=False)
                except SettingError as exc:
                    self.problems.append(f"{section}: {exc}; default used")
                    continue
                good[key] = value
            return from_dict(cls, good, strict=False)

    def set_group(self, section: str, instance: Any) -> None:
        self._data[section] = to_dict(instance)

    def value(self, key: str, default: Any = None) -> Any:
        return self._data.get(key, default)

    def set_value(self, key: str, value: Any) -> None:
        self._data[key] = value

    def save(self) -> None:
        """Write the file all or nothing (:func:`qrfield.files.atomic_write_json`: a random
        temporary file in the folder, renamed over the old one). Not while a damaged file that
        could not be set aside is still in place (``problems`` said so at load)."""
        if not self._can_save:
            return
        make_folder(self.path.parent, "config folder")  # qrfield's own folder: made with its parents
        data = {k: v for k, v in self._data.items() if k != "app"}  # "app" was renamed "run"
        atomic_write_json(self.path, data, sort_keys=True)


@dataclass(frozen=True)
class RunConfig:
    """Everything a frame loop needs, resolved (a camera model, a tuple of methods).

    Attributes:
        source: the ``--source`` spec; camera: the camera model; side_mm: QR side, mm;
        methods: pose methods in order (the first gives the status); solver_settings: method ->
        its settings; detector_settings: DetectorSettings (its ``select_text`` picks the code);
        virtual, picamera, usb: those sources' settings (picamera None = sized from the camera
        model);
        loop, pace: for files and folders; retry_s: reopen a failed source after this long
        (0 = do not); allow_virtual: ``auto`` may fall back to the virtual bench;
        stream: qrfield.stream.StreamSettings (branch continuity, the filter; None = defaults).
    """

    source: str
    camera: Any
    side_mm: float
    methods: tuple[str, ...]
    solver_settings: dict[str, Any] = field(default_factory=dict)
    detector_settings: Any = None
    virtual: Any = None
    loop: bool = False
    picamera: Any = None
    usb: Any = None
    pace: bool = False
    retry_s: float = 0.0
    allow_virtual: bool = True
    stream: Any = None

    def source_key(self) -> tuple[Any, ...]:
        """What requires reopening the source when it changes."""
        from qrfield.sources import source_kind

        kind = source_kind(self.source)
        bench = (self.camera, self.side_mm) if kind in ("virtual", "auto") else ()
        usb = (self.camera.size, self.usb) if kind in ("usb", "auto") else ()
        # picamera2 derives the stream's model from the profile at open: a new profile reopens it.
        pi = (self.camera, self.picamera) if kind in ("picamera2", "picamera2-sim", "auto") else ()
        sim = (self.virtual, self.side_mm) if kind == "picamera2-sim" else ()
        return (self.source, self.loop, self.pace, self.allow_virtual, *bench, *usb, *pi, *sim)

    def pipeline_key(self) -> tuple[Any, ...]:
        """What requires a new pipeline when it changes."""
        return (
            self.camera,
            self.side_mm,
            self.methods,
            tuple(sorted(self.solver_settings.items())),
            self.detector_settings,
            self.stream,
        )

    def make_pipeline(self, camera: Any = None) -> Any:
        """A :class:`qrfield.pipeline.Pipeline` for these settings (ValueError if they do not fit);
        ``camera``: the stream's own model (a picamera2 stream's, through its crop) instead of
        the named one."""
        from qrfield.pipeline import Pipeline

        return Pipeline(
            camera if camera is not None else self.camera,
            self.side_mm,
            self.methods,
            solver_settings=self.solver_settings,
            detector_settings=self.detector_settings,
            stream=self.stream,
        )

    def open_source(self, opener: Callable[..., Any] | None = None) -> Any:
        """The source, opened (SourceError if it cannot be); ``opener`` replaces open_source."""
        from qrfield import sources

        kwargs: dict[str, Any] = dict(
            camera=self.camera,
            side_mm=self.side_mm,
            virtual=self.virtual,
            picamera=self.picamera,
            usb=self.usb,
            loop=self.loop,
            pace=self.pace,
        )
        if not self.allow_virtual:
            kwargs["allow_virtual"] = False
        return (opener or sources.open_source)(self.source, **kwargs)


# ------------------------------------------------------------------------------ command line
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
                "(/dev/ttyUSB0, COM3, loop://); without PORT, the configured serial port",
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
            else:
                origins[spec.name] = (FROM_DEFAULT, option)
        instance = from_dict(section.cls, data)
        groups[section.name] = instance
        for spec in specs(section.cls):
            origin, option = origins[spec.name]
            values.append(
                Value(section.name, spec.name, getattr(instance, spec.name), origin, option, spec.unit)
            )
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
        serial_port = port or groups["serial"].port
        if port:
            _set_origin(values, "serial", "port", port, FROM_COMMAND_LINE, "--serial")
    return Effective(store, groups, values, camera, serial_port)


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


def config_file(directory: Any = None) -> Path:
    """The path of the settings file for ``--config-dir`` ``directory`` (None: the default folder)."""
    return paths.config_dir(directory) / CONFIG_FILE
