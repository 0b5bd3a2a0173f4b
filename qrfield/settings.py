"""Settings declared once: a frozen dataclass whose fields carry type, unit, limits and help.

Every group of settings (a solver's, the detector's, the serial link's, the app's) is a frozen
dataclass built with :func:`setting` fields. From that one declaration come validation
(:func:`validated`), JSON round trips (:func:`to_dict` / :func:`from_dict`, used by the app's
persistence and saved with every session), argparse options (:func:`add_arguments`) and the app's
widgets (:func:`specs` gives type, unit, limits, label, help for each field).

Example::

    @dataclass(frozen=True)
    class NumericalSettings:
        tf: float = setting(0.9, label="tuning factor tf", minimum=0.05, maximum=2.0,
                            help="step scale of the damped update")
        n_max: int = setting(30, label="n_max", unit="iterations", minimum=1, maximum=1000)
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import typing
from dataclasses import dataclass
from typing import Any, TypeVar

T = TypeVar("T")


class SettingError(ValueError):
    """A setting value of the wrong type or outside its limits; the message names the setting."""


@dataclass(frozen=True)
class SettingSpec:
    """What is known about one setting: for validation, widgets, CLI options and docs."""

    name: str
    type: type
    default: Any
    label: str
    unit: str = ""
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[str, ...] | None = None
    help: str = ""
    decimals: int = 3
    # A text setting's own rule beyond choices (a comma list of names): raises ValueError saying why.
    check: typing.Callable[[Any], Any] | None = None

    def describe(self) -> str:
        """One line for help texts: label, unit, limits, default."""
        parts = [self.label]
        if self.unit:
            parts.append(f"[{self.unit}]")
        if self.choices:
            parts.append("one of " + ", ".join(self.choices))
        elif self.minimum is not None or self.maximum is not None:
            parts.append(f"range {self.minimum}..{self.maximum}")
        parts.append(f"default {self.default}")
        text = " ".join(parts)
        return f"{text}: {self.help}" if self.help else text

    def validate(self, value: Any, where: str = "") -> Any:
        """Coerce ``value`` to the setting's type and check its limits; SettingError if not."""
        name = f"{where}{self.name}"
        if self.type is bool:
            if isinstance(value, bool):
                return value
            if isinstance(value, str) and value.strip().lower() in (
                "1",
                "true",
                "yes",
                "on",
                "0",
                "false",
                "no",
                "off",
            ):
                return value.strip().lower() in ("1", "true", "yes", "on")
            if isinstance(value, int) and value in (0, 1):
                return bool(value)
            raise SettingError(f"setting {name}: expected true or false, got {value!r}")
        if self.type is str:
            if not isinstance(value, str):
                raise SettingError(f"setting {name}: expected text, got {value!r}")
            if self.choices and value not in self.choices:
                raise SettingError(f"setting {name}: {value!r} is not one of {', '.join(self.choices)}")
            if self.check is not None:
                try:
                    self.check(value)
                except ValueError as exc:  # a SettingError subclass (BackendError) keeps its class
                    kind = type(exc) if isinstance(exc, SettingError) else SettingError
                    raise kind(f"setting {name}: {exc}") from None
            return value
        if self.type in (int, float):
            if isinstance(value, bool):
                raise SettingError(f"setting {name}: expected a number, got {value!r}")
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise SettingError(f"setting {name}: expected a number, got {value!r}") from None
            if not math.isfinite(number):
                raise SettingError(f"setting {name}: must be finite, got {value!r}")
            if self.type is int:
                if number != int(number):
                    raise SettingError(f"setting {name}: expected a whole number, got {value!r}")
                number = int(number)
            unit = f" {self.unit}" if self.unit else ""
            if self.minimum is not None and number < self.minimum:
                raise SettingError(
                    f"setting {name}: {number}{unit} is below the minimum {self.minimum}{unit}"
                )
            if self.maximum is not None and number > self.maximum:
                raise SettingError(
                    f"setting {name}: {number}{unit} is above the maximum {self.maximum}{unit}"
                )
            return number
        raise SettingError(f"setting {name}: unsupported type {self.type!r}")


def setting(
    default: Any,
    *,
    label: str,
    unit: str = "",
    minimum: float | None = None,
    maximum: float | None = None,
    choices: tuple[str, ...] | None = None,
    help: str = "",
    decimals: int = 3,
    check: typing.Callable[[Any], Any] | None = None,
) -> Any:
    """A dataclass field declaring one setting (use as the field's default). ``check``: for a text
    setting, a function that raises ValueError for a value its type and choices cannot rule out."""
    meta = {
        "qrfield_setting": {
            "label": label,
            "unit": unit,
            "minimum": minimum,
            "maximum": maximum,
            "choices": choices,
            "help": help,
            "decimals": decimals,
            "check": check,
        }
    }
    return dataclasses.field(default=default, metadata=meta)


def specs(cls_or_instance: Any) -> list[SettingSpec]:
    """The SettingSpec of every declared field of a settings dataclass, in declaration order."""
    cls = cls_or_instance if isinstance(cls_or_instance, type) else type(cls_or_instance)
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        meta = f.metadata.get("qrfield_setting")
        if meta is None:
            continue
        out.append(SettingSpec(name=f.name, type=hints[f.name], default=f.default, **meta))
    return out


def validated(instance: T) -> T:
    """Check every field of a settings instance; returns it (coerced) or raises SettingError."""
    changes = {
        spec.name: spec.validate(getattr(instance, spec.name), where=f"{type(instance).__name__}.")
        for spec in specs(instance)
    }
    return dataclasses.replace(instance, **changes)  # type: ignore[type-var]


def to_dict(instance: Any) -> dict[str, Any]:
    """JSON-ready dict of a settings instance (field name -> value)."""
    return {spec.name: getattr(instance, spec.name) for spec in specs(instance)}


def from_dict(cls: type[T], data: dict[str, Any] | None, *, strict: bool = True) -> T:
    """Build settings from a dict; unknown keys raise (strict) or are ignored (persisted files).

    Missing keys take their defaults; bad values raise SettingError naming the setting.
    """
    data = dict(data or {})
    known = {spec.name: spec for spec in specs(cls)}
    unknown = sorted(set(data) - set(known))
    if unknown and strict:
        raise SettingError(
            f"{cls.__name__}: unknown setting(s) {', '.join(unknown)}; known: {', '.join(known)}"
        )
    values = {
        name: known[name].validate(value, where=f"{cls.__name__}.")
        for name, value in data.items()
        if name in known
    }
    return cls(**values)


def add_arguments(
    parser: argparse.ArgumentParser | Any, cls: type, prefix: str = "", skip: tuple[str, ...] = ()
) -> None:
    """Add one ``--PREFIX-NAME`` option per setting but those in ``skip`` (default None = keep the
    declared default). A true/false setting alone means true: ``--loop`` = ``--loop true``."""
    for spec in specs(cls):
        if spec.name in skip:
            continue
        option = "--" + (prefix + spec.name).replace("_", "-")
        kwargs: dict[str, Any] = {
            "default": None,
            "dest": f"{prefix}{spec.name}".replace("-", "_"),
            "help": spec.describe(),
        }
        if spec.type is bool:
            kwargs["type"] = lambda text, spec=spec: spec.validate(text)
            kwargs["metavar"] = "true|false"
            kwargs["nargs"] = "?"
            kwargs["const"] = True
        elif spec.choices:
            kwargs["choices"] = spec.choices
        else:
            kwargs["type"] = spec.type
        parser.add_argument(option, **kwargs)


def from_arguments(cls: type[T], args: argparse.Namespace, prefix: str = "", base: T | None = None) -> T:
    """Settings from parsed options added by :func:`add_arguments` (unset options keep ``base``)."""
    data = to_dict(base) if base is not None else {}
    for spec in specs(cls):
        value = getattr(args, f"{prefix}{spec.name}".replace("-", "_"), None)
        if value is not None:
            data[spec.name] = value
    return from_dict(cls, data)
