"""A simulation study: what is swept, through which camera, solved by which solvers, judged how.

A study is a TOML file (the shipped default is ``qrfield/data/study-default.toml``; a user's file
needs only the fields it changes) plus command-line overrides ``FIELD=VALUE``. Fields (mm, degrees):

  camera               NAME[@WxH] or PATH.json[@WxH] (qrfield.camera.resolve_camera)
  side_mm              QR symbol side L (quiet zone excluded)
  x_range, y_range,    [start, stop, step] of the QR centre in the camera frame, stop included;
  z_range              a single number is a single value
  combinations         "default" (the shipped 12) or a CSV path (relative to the study file)
  sweep_limit_deg      the tilt magnitude t runs 0, step, 2 step, ... up to this (<= 180)
  sweep_step_deg
  max_view_angle_deg   a card whose normal is more than this from the line of sight to its centre
                       is out of view (edge-on or facing away); 90 = only facing away
  degradation          none | round (corners rounded to whole pixels) | noise (Gaussian)
  noise_px, noise_seed sigma in pixels per coordinate, and the seed, for degradation = noise
  solvers              solver keys: "numerical" (the thesis' model), "numerical-<guess>" (another
                       initial guess, e.g. numerical-parallelogram), "ippe"; "ippe-<name>" and
                       "numerical-<name>" with their own [solver.KEY] table are allowed too
  [criteria]           angle_deg (each of alpha, beta, gamma), position_mm (Euclidean, strict <),
                       n_max (iterations; also the numerical solvers' n_max)
  [solver.KEY]         settings of that solver (fields of NumericalSettings or IppeSettings)

Overrides use the same names, tables with dots: ``z_range=200,600,100``, ``degradation=round``,
``criteria.angle_deg=1``, ``solver.numerical.tf=0.8``, ``solvers=numerical,ippe``.
"""

from __future__ import annotations

import copy
import difflib
import math
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from qrfield.files import FileFormatError, loads_toml, read_toml
from qrfield.methods import METHODS
from qrfield.sessions.criteria import AcceptanceCriteria
from qrfield.settings import SettingError, SettingSpec
from qrfield.simulation.combinations import DEFAULT_NAME, Combination, load_combinations

DEGRADATIONS = ("none", "round", "noise")
#: Most values along one grid axis or sweep, and most poses in one study (memory: about 70 bytes
#: per pose and solver are kept, so 2 million poses and 3 solvers take about 420 MB).
MAX_AXIS_VALUES = 10_000
MAX_POSES = 2_000_000
#: Every top-level field: a SettingSpec (type, unit, limits, help: validation and the app's widgets),
#: or "range" ([start, stop, step] in mm) or "list" (solver keys). "criteria" and "solver" are tables.
#: Defaults live in the shipped study (see :func:`field_specs`).
FIELDS: dict[str, SettingSpec | str] = {
    "camera": SettingSpec("camera", str, None, "camera", help="profile NAME[@WxH] or PATH.json[@WxH]"),
    "side_mm": SettingSpec(
        "side_mm", float, None, "QR side L", "mm", 0.001, 100_000.0, help="symbol side, quiet zone excluded"
    ),
    "x_range": "range",
    "y_range": "range",
    "z_range": "range",
    "combinations": SettingSpec(
        "combinations", str, None, "combinations", help='"default" (the shipped 12) or a CSV file'
    ),
    "sweep_limit_deg": SettingSpec(
        "sweep_limit_deg", float, None, "sweep limit", "deg", 0.001, 180.0, help="largest swept tilt t"
    ),
    "sweep_step_deg": SettingSpec(
        "sweep_step_deg", float, None, "sweep step", "deg", 0.001, 180.0, help="tilt step from 0"
    ),
    "max_view_angle_deg": SettingSpec(
        "max_view_angle_deg",
        float,
        None,
        "largest view angle",
        "deg",
        0.001,
        90.0,
        help="beyond this angle between the card's normal and the line of sight the card is out of view",
    ),
    "degradation": SettingSpec(
        "degradation",
        str,
        None,
        "corner degradation",
        choices=DEGRADATIONS,
        help="none, round (to whole pixels) or noise (Gaussian)",
    ),
    "noise_px": SettingSpec(
        "noise_px", float, None, "noise sigma", "px", 0.0, 100.0, help="per coordinate, degradation = noise"
    ),
    "noise_seed": SettingSpec(
        "noise_seed", int, None, "noise seed", "", 0, 2**32 - 1, help="repeatable noise"
    ),
    "solvers": "list",
}
CRITERIA_FIELDS: dict[str, SettingSpec] = {
    "angle_deg": SettingSpec(
        "angle_deg", float, None, "angle error", "deg", 1e-6, 180.0, help="on each of alpha, beta, gamma (<=)"
    ),
    "position_mm": SettingSpec(
        "position_mm", float, None, "position error", "mm", 1e-6, 1e6, help="Euclidean (strictly below)"
    ),
    "n_max": SettingSpec(
        "n_max", int, None, "n_max", "iterations", 1, 10_000, help="also the numerical solvers' n_max"
    ),
}
TABLES = ("criteria", "solver")
#: The app's small study (its Simulation tab starts with it; ``qrfield benchmark simulation`` times it):
#: the shipped study with a 5 x 3 x 2 grid (x -80..80 step 40, y -40..40 step 40, z 250 and 400 mm)
#: and tilts 0..60 deg in 5 deg steps: 12 combinations x 13 angles x 30 points = 4680 poses.
SMALL_STUDY: dict[str, Any] = {
    "x_range": [-80.0, 80.0, 40.0],
    "y_range": [-40.0, 40.0, 40.0],
    "z_range": [250.0, 400.0, 150.0],
    "sweep_limit_deg": 60.0,
    "sweep_step_deg": 5.0,
}


class StudyError(ValueError):
    """A study file or override that cannot be used; the message names the field."""


@dataclass(frozen=True)
class Criteria:
    """The seed's acceptance criteria: angle error <= angle_deg on each angle, position error
    < position_mm (Euclidean), within n_max iterations."""

    angle_deg: float = AcceptanceCriteria().max_angle_error_deg
    position_mm: float = AcceptanceCriteria().max_position_error_mm
    n_max: int = 30

    @property
    def acceptance(self) -> AcceptanceCriteria:
        """The pose part of these criteria as the one rule (qrfield.sessions.criteria)."""
        return AcceptanceCriteria(max_angle_error_deg=self.angle_deg, max_position_error_mm=self.position_mm)


@dataclass(frozen=True)
class SolverSpec:
    """One solver of the study: its key (the name in outputs), method and validated settings."""

    key: str
    method: str
    settings: Any


@dataclass(frozen=True)
class StudyConfig:
    """A validated study (see the module docstring for every field)."""

    camera: str
    side_mm: float
    x_range: tuple[float, float, float]
    y_range: tuple[float, float, float]
    z_range: tuple[float, float, float]
    combinations: str
    sweep_limit_deg: float
    sweep_step_deg: float
    max_view_angle_deg: float
    degradation: str
    noise_px: float
    noise_seed: int
    solvers: tuple[str, ...]
    criteria: Criteria = field(default_factory=Criteria)
    #: Raw [solver.KEY] tables as given (validated); see :meth:`solver_specs` for the settings used.
    solver_tables: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()

    # ------------------------------------------------------------------ derived
    def x_values(self) -> np.ndarray:
        """Grid values of x in mm (ascending)."""
        return range_values(self.x_range)

    def y_values(self) -> np.ndarray:
        return range_values(self.y_range)

    def z_values(self) -> np.ndarray:
        return range_values(self.z_range)

    def sweep_values(self) -> np.ndarray:
        """Swept magnitudes t in degrees: 0, step, ..., up to sweep_limit_deg."""
        return range_values((0.0, self.sweep_limit_deg, self.sweep_step_deg))

    def camera_model(self) -> Any:
        from qrfield.camera import resolve_camera

        return resolve_camera(self.camera)

    def combination_list(self) -> list[Combination]:
        return load_combinations(self.combinations)

    def solver_specs(self) -> list[SolverSpec]:
        """The solvers to run, with the settings each uses (see :func:`solver_spec`)."""
        tables = dict(self.solver_tables)
        return [solver_spec(key, dict(tables.get(key, ())), self.criteria.n_max) for key in self.solvers]

    def size(self) -> dict[str, int]:
        """Counts: grid points, combinations, swept angles, poses."""
        grid = self.x_values().size * self.y_values().size * self.z_values().size
        combos = len(self.combination_list())
        angles = self.sweep_values().size
        return {
            "grid_points": grid,
            "combinations": combos,
            "angles": angles,
            "poses": grid * combos * angles,
        }

    def describe_size(self) -> str:
        s = self.size()
        return (
            f"{self.x_values().size} x {self.y_values().size} x {self.z_values().size} grid points x "
            f"{s['combinations']} combinations x {s['angles']} angles = {s['poses']} poses, "
            f"each solved by {len(self.solvers)} solvers"
        )

    def to_toml(self) -> str:
        """The study as TOML (every field explicit), loadable by :func:`load_study`."""
        lines = ["# qrfield simulation study (resolved: every field explicit)"]
        for name in FIELDS:
            lines.append(f"{name} = {_toml_value(getattr(self, name))}")
        lines += ["", "[criteria]"]
        for name in CRITERIA_FIELDS:
            lines.append(f"{name} = {_toml_value(getattr(self.criteria, name))}")
        for key, items in self.solver_tables:
            if key not in self.solvers:
                continue
            lines += ["", f"[solver.{key}]"]
            lines += [f"{name} = {_toml_value(value)}" for name, value in items]
        return "\n".join(lines) + "\n"


def range_values(rng: Sequence[float]) -> np.ndarray:
    """start, start + step, ... up to stop (included, to a millionth of a step)."""
    start, stop, step = (float(v) for v in rng)
    count = math.floor((stop - start) / step + 1e-6) + 1
    return start + step * np.arange(count)


def solver_method(key: str) -> str:
    """ "numerical" or "ippe" from a solver key (the key itself or its prefix before '-')."""
    head = key.split("-", 1)[0]
    if head not in METHODS or key.endswith("-"):
        raise StudyError(
            f"field 'solvers': unknown solver {key!r}; use numerical, numerical-<guess> "
            "(e.g. numerical-parallelogram) or ippe"
        )
    return head


def solver_spec(key: str, table: Mapping[str, Any], n_max: int) -> SolverSpec:
    """Settings of solver ``key``: the defaults, then its [solver.KEY] table.

    Defaults: "numerical" = qrfield.solvers.SEED_SETTINGS (the thesis' model); "numerical-<guess>"
    = the same with initial_guess <guess>; "ippe" = IppeSettings(). n_max always comes from
    [criteria] (the seed's n_max is both the cap and the criterion); the study solves each pose once
    (no mirror search).
    """
    from qrfield import settings as settings_mod
    from qrfield.solvers import SEED_SETTINGS, NumericalSettings
    from qrfield.solvers.registry import pose_method

    method = solver_method(key)
    where = f"solver.{key}"
    if "n_max" in table:
        raise StudyError(f"field '{where}.n_max': set n_max once, as criteria.n_max")
    registered = pose_method(method)
    cls = registered.settings_class
    if cls is not NumericalSettings:
        base = settings_mod.to_dict(cls())
    else:  # the thesis' model as the seed ran it, or with the initial guess its key names
        base = settings_mod.to_dict(SEED_SETTINGS)
        suffix = key.partition("-")[2]
        if suffix:
            guesses = next(
                s.choices for s in settings_mod.specs(NumericalSettings) if s.name == "initial_guess"
            )
            if suffix in (guesses or ()):
                base["initial_guess"] = suffix
            elif "initial_guess" not in table:
                raise StudyError(
                    f"field 'solvers': {key!r} names no initial guess ({', '.join(guesses or ())}); "
                    f"give it a [solver.{key}] table with initial_guess"
                )
        base["n_max"] = n_max
        base["mirror"] = False
    known = {s.name for s in settings_mod.specs(cls)}
    for name in table:
        if name not in known:
            raise StudyError(
                f"field '{where}.{name}': unknown setting of {cls.__name__}{_suggest(name, known)}; "
                f"known: {', '.join(sorted(known - {'n_max', 'mirror'}))}"
            )
    try:
        settings = settings_mod.from_dict(cls, {**base, **table})
        registered.checked_settings(settings)
    except ValueError as exc:
        raise StudyError(f"field '{where}': {exc}") from None
    return SolverSpec(key, method, settings)


# ---------------------------------------------------------------------- loading


def default_study_path() -> Path:
    return Path(str(resources.files("qrfield.data") / "study-default.toml"))


def _read_toml(path: Path) -> dict[str, Any]:
    """A study file read with qrfield.files' limits (size, nesting, a BOM accepted)."""
    try:
        return read_toml(path, "study file")
    except FileFormatError as exc:
        raise StudyError(str(exc)) from None


def load_study(path: str | Path | None = None, overrides: Iterable[str] = ()) -> StudyConfig:
    """The default study, with the fields of ``path`` (if given) and then ``overrides`` applied.

    ``overrides`` are ``FIELD=VALUE`` strings (see the module docstring). Relative paths in the
    study file (combinations, a camera JSON) are relative to that file; in overrides, to the
    current folder. Raises StudyError naming the field for anything unusable.
    """
    raw = _read_toml(default_study_path())
    where = "study"
    if path is not None:
        path = Path(path)
        where = f"study file {path}"
        user = _read_toml(path)
        _check_names(user, where)
        user = _resolve_paths(user, path.parent)
        raw = merge(raw, user)
    for text in overrides:
        raw = merge(raw, parse_override(text))
    return build_config(raw, where)


def config_from_dict(data: Mapping[str, Any], base: StudyConfig | None = None) -> StudyConfig:
    """A study from a dict of the TOML's shape, over ``base`` (default: the shipped study)."""
    raw = tomllib.loads(base.to_toml()) if base is not None else _read_toml(default_study_path())
    _check_names(dict(data), "study")
    return build_config(merge(raw, dict(data)), "study")


def with_overrides(config: StudyConfig, overrides: Iterable[str]) -> StudyConfig:
    """``config`` with ``FIELD=VALUE`` overrides applied."""
    raw = tomllib.loads(config.to_toml())
    for text in overrides:
        raw = merge(raw, parse_override(text))
    return build_config(raw, "study")


def _resolve_paths(data: dict[str, Any], folder: Path) -> dict[str, Any]:
    data = dict(data)
    combos = data.get("combinations")
    if isinstance(combos, str) and combos != DEFAULT_NAME and not Path(combos).is_absolute():
        data["combinations"] = str(folder / combos)
    cam = data.get("camera")
    if isinstance(cam, str):
        base, at, size = cam.rpartition("@") if "@" in cam else (cam, "", "")
        if base.endswith(".json") and not Path(base).is_absolute():
            data["camera"] = str(folder / base) + (f"@{size}" if at else "")
    return data


def _absolute_paths(values: Mapping[str, Any]) -> dict[str, str]:
    """combinations and a camera JSON as absolute paths, so that a written study.toml reruns anywhere."""
    out = {}
    combos = values["combinations"]
    if combos != DEFAULT_NAME:
        out["combinations"] = str(Path(combos).expanduser().resolve())
    base, at, size = (
        values["camera"].rpartition("@") if "@" in values["camera"] else (values["camera"], "", "")
    )
    if base.endswith(".json"):
        out["camera"] = str(Path(base).expanduser().resolve()) + (f"@{size}" if at else "")
    return out


def merge(base: dict[str, Any], extra: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``extra`` laid over it; tables merge key by key (solver.KEY tables too)."""
    out = copy.deepcopy(base)
    for key, value in extra.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), dict):
            out[key] = merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def parse_override(text: str) -> dict[str, Any]:
    """``FIELD=VALUE`` (FIELD may be dotted: criteria.n_max, solver.ippe.refine) as a nested dict."""
    name, sep, value_text = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise StudyError(f"override {text!r}: expected FIELD=VALUE, e.g. z_range=200,600,100")
    parts = name.split(".")
    if parts[0] not in FIELDS and parts[0] not in TABLES:
        raise StudyError(
            f"override {text!r}: unknown field {parts[0]!r}{_suggest(parts[0], [*FIELDS, *TABLES])}"
        )
    if parts[0] == "criteria" and len(parts) != 2:
        raise StudyError(f"override {text!r}: use criteria.FIELD=VALUE, e.g. criteria.angle_deg=1")
    if parts[0] == "solver" and len(parts) != 3:
        raise StudyError(f"override {text!r}: use solver.KEY.FIELD=VALUE, e.g. solver.numerical.tf=0.8")
    if parts[0] in FIELDS and len(parts) != 1:
        raise StudyError(f"override {text!r}: field {parts[0]!r} has no sub-fields")
    value = _parse_value(value_text.strip())
    if parts[0] == "solvers" and isinstance(value, str):
        value = [value]
    out: dict[str, Any] = {}
    node = out
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value
    return out


def _parse_value(text: str) -> Any:
    """A TOML value, a comma-separated list of them, or else plain text."""

    def one(item: str) -> Any:
        try:
            return loads_toml(f"v = {item}", "override")["v"]
        except FileFormatError as exc:
            if "nested" in str(exc):  # [[[[...: too deep for any field (qrfield.files.MAX_DEPTH)
                raise StudyError(
                    f"override value {item[:40]!r}...: {str(exc).removeprefix('override: ')}"
                ) from None
            return item

    if text.startswith("["):
        return one(text)
    if "," in text:
        return [one(item.strip()) for item in text.split(",")]
    return one(text)


def _suggest(name: str, known: Iterable[str]) -> str:
    close = difflib.get_close_matches(name, list(known), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _check_names(data: Mapping[str, Any], where: str) -> None:
    for name, value in data.items():
        if name not in FIELDS and name not in TABLES:
            raise StudyError(
                f"{where}: unknown field {name!r}{_suggest(name, [*FIELDS, *TABLES])}; "
                f"fields: {', '.join([*FIELDS, *TABLES])}"
            )
        if name in TABLES and not isinstance(value, Mapping):
            raise StudyError(f"{where}: field {name!r} must be a table ([{name}])")


def build_config(raw: Mapping[str, Any], where: str = "study") -> StudyConfig:
    """Validate a merged raw study dict; StudyError naming the field for anything unusable."""
    _check_names(raw, where)
    values: dict[str, Any] = {}
    for name, kind in FIELDS.items():
        if name not in raw:
            raise StudyError(f"{where}: field {name!r} is missing")
        values[name] = _validate(name, kind, raw[name], where)
    values.update(_absolute_paths(values))
    criteria_raw = dict(raw.get("criteria", {}))
    for name in criteria_raw:
        if name not in CRITERIA_FIELDS:
            raise StudyError(
                f"{where}: unknown field 'criteria.{name}'{_suggest(name, CRITERIA_FIELDS)}; "
                f"known: {', '.join(CRITERIA_FIELDS)}"
            )
    crit = {
        n: _validate(f"criteria.{n}", k, criteria_raw[n], where)
        for n, k in CRITERIA_FIELDS.items()
        if n in criteria_raw
    }
    criteria = replace(Criteria(), **crit)
    solver_raw = dict(raw.get("solver", {}))
    tables = []
    for key, table in solver_raw.items():
        if not isinstance(table, Mapping):
            raise StudyError(f"{where}: field 'solver.{key}' must be a table ([solver.{key}])")
        solver_method(key)
        tables.append((key, tuple(table.items())))
    config = StudyConfig(**values, criteria=criteria, solver_tables=tuple(tables))
    _check_consistency(config, where)
    return config


def _validate(name: str, kind: SettingSpec | str, value: Any, where: str) -> Any:
    label = f"{where}: field {name!r}"
    if isinstance(kind, SettingSpec):
        try:
            value = kind.validate(value)
        except SettingError as exc:
            raise StudyError(f"{label}: {str(exc).partition(': ')[2]}") from None
        if kind.type is str:
            value = value.strip()
            if not value:
                raise StudyError(f"{label} must not be empty")
        return value
    if kind == "list":
        if isinstance(value, str):
            value = [value]
        if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
            raise StudyError(f'{label} must be a list of names, e.g. ["numerical", "ippe"], got {value!r}')
        if len(set(value)) != len(value):
            raise StudyError(f"{label} names a solver twice: {value!r}")
        return tuple(value)
    if kind == "range":
        if _is_number(value):
            value = [value, value, 1.0]
        if not isinstance(value, list) or len(value) != 3 or not all(_is_number(v) for v in value):
            raise StudyError(f"{label} must be [start, stop, step] in mm (or one number), got {value!r}")
        start, stop, step = (float(v) for v in value)
        if not all(math.isfinite(v) for v in (start, stop, step)):
            raise StudyError(f"{label} must be finite, got {value!r}")
        if step <= 0:
            raise StudyError(f"{label}: step must be positive, got {step:g}")
        if stop < start:
            raise StudyError(f"{label}: stop {stop:g} is below start {start:g}")
        if (stop - start) / step + 1 > MAX_AXIS_VALUES:
            raise StudyError(f"{label}: more than {MAX_AXIS_VALUES} values; use a larger step")
        return (start, stop, step)
    raise AssertionError(kind)  # pragma: no cover


def field_specs() -> list[SettingSpec]:
    """SettingSpecs of the study's scalar fields and criteria ("criteria.NAME"), with the shipped
    defaults: for the app's widgets. The ranges (x_range, y_range, z_range: [start, stop, step] mm)
    and the solver list are not scalar settings and are not included."""
    raw = _read_toml(default_study_path())
    out = [replace(spec, default=raw[name]) for name, spec in FIELDS.items() if isinstance(spec, SettingSpec)]
    out += [
        replace(spec, name=f"criteria.{name}", default=raw["criteria"][name])
        for name, spec in CRITERIA_FIELDS.items()
    ]
    return out


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _check_consistency(c: StudyConfig, where: str) -> None:
    if c.degradation == "noise" and c.noise_px <= 0:
        raise StudyError(f"{where}: field 'noise_px' must be positive with degradation = noise")
    if c.degradation != "noise" and c.noise_px != 0:
        raise StudyError(
            f"{where}: field 'noise_px' = {c.noise_px:g} is used only with degradation = noise "
            "(set degradation=noise too)"
        )
    if c.z_range[0] <= 0:
        raise StudyError(f"{where}: field 'z_range' must lie in front of the camera (start > 0 mm)")
    if c.sweep_step_deg > c.sweep_limit_deg:
        raise StudyError(
            f"{where}: field 'sweep_step_deg' ({c.sweep_step_deg:g}) is above sweep_limit_deg "
            f"({c.sweep_limit_deg:g})"
        )
    try:
        c.camera_model()
    except ValueError as exc:
        raise StudyError(f"{where}: field 'camera': {exc}") from None
    try:
        combos = c.combination_list()
    except ValueError as exc:
        raise StudyError(f"{where}: field 'combinations': {exc}") from None
    for key in c.solvers:
        solver_method(key)
    c.solver_specs()
    poses = c.x_values().size * c.y_values().size * c.z_values().size * len(combos) * c.sweep_values().size
    if poses > MAX_POSES:
        raise StudyError(
            f"{where}: the study has {poses} poses, more than {MAX_POSES}; use larger steps or smaller ranges"
        )


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Criteria):
        raise AssertionError("criteria is a table")  # pragma: no cover
    raise TypeError(f"cannot write {value!r} as TOML")
