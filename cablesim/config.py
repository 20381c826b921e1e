"""Helpers shared by the typed, seeded, printable configuration dataclasses."""

from __future__ import annotations

import dataclasses
import json
import typing
from typing import Any, TypeVar

from cablesim.errors import ConfigError

T = TypeVar("T")


def to_dict(cfg: Any) -> dict[str, Any]:
    """A JSON-able dict of a (nested) config dataclass."""

    def conv(v: Any) -> Any:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return {f.name: conv(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, tuple | list):
            return [conv(x) for x in v]
        if isinstance(v, dict):
            return {str(k): conv(x) for k, x in v.items()}
        if hasattr(v, "item") and callable(v.item):  # numpy scalar
            return v.item()
        return v

    return conv(cfg)


def from_dict(cls: type[T], data: dict[str, Any], path: str = "") -> T:
    """Rebuild a config dataclass from ``to_dict`` output; unknown keys are an error."""
    if not isinstance(data, dict):
        raise ConfigError(path or cls.__name__, f"expected a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = set(data) - names
    if unknown:
        raise ConfigError(f"{path}{sorted(unknown)[0]}", f"unknown field for {cls.__name__}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        hint = hints.get(name)
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            kwargs[name] = from_dict(hint, value, f"{path}{name}.")
        elif typing.get_origin(hint) is tuple and isinstance(value, list):
            args = typing.get_args(hint)
            if args and isinstance(args[0], type) and dataclasses.is_dataclass(args[0]):
                kwargs[name] = tuple(from_dict(args[0], v, f"{path}{name}.") for v in value)
            else:
                kwargs[name] = tuple(tuple(v) if isinstance(v, list) else v for v in value)
        else:
            kwargs[name] = value
    return cls(**kwargs)


def pretty(cfg: Any) -> str:
    """Human-readable JSON of a config."""
    return json.dumps(to_dict(cfg), indent=2, sort_keys=False)


class Config:
    """Mixin of the top-level config dataclasses: ``replace``, ``to_dict``, ``from_dict`` and a
    JSON ``str`` (every config is typed, printable and reloadable the same way)."""

    def replace(self: T, **changes: Any) -> T:
        return dataclasses.replace(self, **changes)  # type: ignore[type-var]

    def to_dict(self) -> dict[str, Any]:
        return to_dict(self)

    @classmethod
    def from_dict(cls: type[T], data: dict[str, Any]) -> T:
        return from_dict(cls, data)

    def __str__(self) -> str:
        return pretty(self)


def check_range(
    field: str, value: tuple[float, float], lo: float | None = None, hi: float | None = None
) -> None:
    """Validate a (min, max) range field."""
    if len(value) != 2:
        raise ConfigError(field, f"expected (min, max), got {value!r}")
    a, b = float(value[0]), float(value[1])
    if a > b:
        raise ConfigError(field, f"min {a} is larger than max {b}")
    if lo is not None and a < lo:
        raise ConfigError(field, f"must be >= {lo}, got {a}")
    if hi is not None and b > hi:
        raise ConfigError(field, f"must be <= {hi}, got {b}")


def check_positive(field: str, value: float, allow_zero: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(field, f"must be a number, got {value!r}")
    if not (value >= 0 if allow_zero else value > 0):
        raise ConfigError(field, f"must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")
