"""Helpers shared by the typed, seeded, printable configuration dataclasses.

One validation style: a config is checked when it is made.  :class:`Config` runs, after the
dataclass ``__init__``, :func:`check_fields` (every field against its type hint: an ``int``
field takes an integer but not a bool, a ``float`` field a finite real number, a ``str`` a
string, a ``tuple[...]`` a sequence of the right length, ...) and then the class's own
``_validate`` (ranges, choices, fields that depend on each other), so a config that exists is
valid; the config classes are frozen, so it stays valid (change one with ``replace`` or
:meth:`Config.with_values`, which build a new, checked config).  Every check raises
:class:`~cablesim.errors.ConfigError` naming the field and the value; :func:`from_dict` checks
the values of a mapping the same way before it builds anything, names nested fields by their
full dotted path (``episode.scene.camera.width``) and moves the fields of config files written
by earlier versions to where they live now (:class:`ConfigMigrationWarning`).  The ``check_*``
helpers validate ranges.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import numbers
import types
import typing
import warnings
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, TypeVar

import numpy as np

from cablesim.errors import ConfigError

T = TypeVar("T")

#: Makes the error a check raises: ``error(field, message)``.
ErrorFactory = Callable[[str, str], Exception]


class ConfigMigrationWarning(UserWarning):
    """A config written by an earlier cablesim was loaded: a field of it moved (the message
    names its old and its new place) or is no longer a config field."""


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


# ------------------------------------------------------------------------- type checks
def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def is_int(value: Any) -> bool:
    """An integer (Python or NumPy), but not a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool | np.bool_)


def is_real(value: Any) -> bool:
    """A real number (Python or NumPy, int or float), but not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    try:
        return typing.get_type_hints(cls)
    except Exception:  # noqa: BLE001 - an unresolvable hint: no type checks for that class
        return {}


def check_value(field: str, value: Any, hint: Any, error: ErrorFactory = ConfigError) -> None:
    """Raise ``error(field, ...)`` unless ``value`` fits the type ``hint``.

    Numbers must be finite; ``int`` refuses bools and floats, ``float`` refuses bools and
    strings; tuples may come as lists (JSON); nested dataclasses must be instances.  Hints
    this does not understand (``Any``, arrays, callables) accept anything.
    """
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if hint is Any:
        return
    if hint is None or hint is type(None):
        if value is not None:
            raise error(field, f"must be null, got {_short(value)}")
        return
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                check_value(field, value, a, error)
                return
            except Exception as e:  # noqa: BLE001 - collected, re-raised below
                errors.append(e)
        if len(errors) == 1:
            raise errors[0]
        names = " or ".join(getattr(a, "__name__", str(a)) for a in args)
        raise error(field, f"expected {names}, got {_short(value)}")
    if origin is typing.Literal:
        if value not in args:
            raise error(field, f"must be one of {args}, got {_short(value)}")
        return
    if origin is tuple:
        if not isinstance(value, tuple | list):
            raise error(field, f"expected a sequence, got {_short(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            for i, v in enumerate(value):
                check_value(f"{field}[{i}]", v, args[0], error)
            return
        if args and len(value) != len(args):
            raise error(field, f"expected {len(args)} values, got {_short(value)}")
        for i, (v, a) in enumerate(zip(value, args, strict=False)):
            check_value(f"{field}[{i}]", v, a, error)
        return
    if hint is bool:
        if not isinstance(value, bool | np.bool_):
            raise error(field, f"must be true or false, got {_short(value)}")
        return
    if hint is int:
        if not is_int(value):
            raise error(field, f"must be an integer, got {_short(value)}")
        return
    if hint is float:
        if not is_real(value):
            raise error(field, f"must be a number, got {_short(value)}")
        if not math.isfinite(float(value)):
            raise error(field, f"must be a finite number, got {_short(value)}")
        return
    if hint is str:
        if not isinstance(value, str):
            raise error(field, f"must be a string, got {_short(value)}")
        return
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        if not isinstance(value, hint):
            raise error(field, f"expected a {hint.__name__}, got {_short(value)}")
        return


def check_fields(cfg: Any, prefix: str = "", error: ErrorFactory = ConfigError) -> None:
    """Check every field of the dataclass instance ``cfg`` against its type hint (nested
    dataclasses only for their type: their own ``validate`` checks their fields)."""
    hints = _hints(type(cfg))
    for f in dataclasses.fields(cfg):
        if f.name in hints:
            check_value(f"{prefix}{f.name}", getattr(cfg, f.name), hints[f.name], error)


def _from_value(hint: Any, value: Any, field: str) -> Any:
    """``value`` (from JSON) made into what the hint wants: nested configs rebuilt, lists made
    tuples.  Values are type-checked before anything is built."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return from_dict(hint, value, f"{field}.")
    if origin in (typing.Union, types.UnionType) and value is not None:
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            return _from_value(inner[0], value, field)
    if origin is tuple and isinstance(value, list | tuple):
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_from_value(args[0], v, f"{field}[{i}]") for i, v in enumerate(value))
        if args and len(args) == len(value):
            return tuple(
                _from_value(a, v, f"{field}[{i}]")
                for i, (v, a) in enumerate(zip(value, args, strict=True))
            )
        return tuple(value)
    return value


def from_dict(cls: type[T], data: dict[str, Any], path: str = "") -> T:
    """Rebuild a config dataclass from ``to_dict`` output; unknown keys and values of the
    wrong type are a ``ConfigError`` naming the field by its dotted path from the top
    (``path`` is the prefix of ``cls``'s fields, e.g. ``"episode.scene."``).  A class with a
    ``_migrate(data, path)`` classmethod first moves the fields of its earlier layouts."""
    if not isinstance(data, dict):
        raise ConfigError(path.rstrip(".") or cls.__name__, f"expected a mapping, got {data!r}")
    migrate = getattr(cls, "_migrate", None)
    if migrate is not None:
        data = migrate(dict(data), path)
    hints = _hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(str(k) for k in set(data) - names)
    if unknown:
        raise ConfigError(f"{path}{unknown[0]}", f"unknown field for {cls.__name__}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        hint = hints.get(name, Any)
        value = _from_value(hint, value, f"{path}{name}")
        check_value(f"{path}{name}", value, hint)
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except ConfigError as e:
        if not path:
            raise
        field = _rebase(e.field, getattr(cls, "SECTION", ""), path)
        raise ConfigError(field, _message(e)) from None


def _message(e: ConfigError) -> str:
    """The message of ``e`` without its field."""
    text = str(e)
    head = f"{e.field}: "
    return text[len(head) :] if text.startswith(head) else text


def _rebase(field: str, section: str, path: str) -> str:
    """``field`` as a config of section ``section`` names it (``camera.width``), named from
    where that config sits (``path``, e.g. ``episode.scene.camera.``)."""
    base = path.rstrip(".")
    if not section:
        rest = field if field.startswith("[") else f".{field}"
    elif field == section:
        rest = ""
    elif field.startswith(section) and field[len(section)] in ".[/":
        rest = field[len(section) :]
    else:
        return field
    return base + rest


def moved_fields(
    data: dict[str, Any],
    path: str,
    moves: Mapping[str, str],
    *,
    old_layout: bool,
    dropped: Mapping[str, str] | None = None,
    null_keeps: tuple[str, ...] = (),
) -> dict[str, Any]:
    """``data`` (a config mapping at ``path``) with the fields ``moves`` names (old name ->
    new dotted path below ``data``) moved to their new place, each with a
    :class:`ConfigMigrationWarning` naming the old and the new field; the fields ``dropped``
    names (name -> why) are removed with a warning.

    ``old_layout``: the file is of the earlier layout as a whole, where the old field was the
    one the run used and the new place held a value the run overwrote (it is replaced, and the
    warning says so).  Otherwise (a file that mixes layouts) an old field whose new place holds
    another value is a ``ConfigError`` naming both: which one to take is not known.  An old
    field named in ``null_keeps`` moves nothing when it is null (the earlier runs kept the
    nested value then)."""
    data = dict(data)
    for name, why in (dropped or {}).items():
        if name in data:
            value = data.pop(name)
            _warn(f"{path}{name} ({_json(value)}) is no longer a config field: {why}")
    for old, new in moves.items():
        if old not in data:
            continue
        value = data.pop(old)
        node = data
        keys = new.split(".")
        for key in keys[:-1]:
            child = node.get(key, {})
            if not isinstance(child, dict):
                raise ConfigError(f"{path}{old}", f"moved to {path}{new}, but {key} is no section")
            node[key] = child = dict(child)
            node = child
        last = keys[-1]
        if value is None and old in null_keeps:
            kept = f" ({_json(node[last])})" if last in node else ""
            _warn(f"{path}{old} moved to {path}{new}; null here, so {path}{new}{kept} stays")
            continue
        note = ""
        if last in node and node[last] != value:
            if not old_layout:
                raise ConfigError(
                    f"{path}{old}",
                    f"moved to {path}{new}, and the file gives both ({_json(value)} and "
                    f"{_json(node[last])}): keep one of them",
                )
            note = f"; the file's {path}{new} ({_json(node[last])}) was not what its run used"
        node[last] = value
        _warn(f"{path}{old} moved to {path}{new} ({_json(value)}){note}")
    return data


def _json(value: Any) -> str:
    text = json.dumps(value, default=str, separators=(",", ":"))
    return text if len(text) <= 60 else text[:57] + "..."


def _warn(message: str) -> None:
    warnings.warn(ConfigMigrationWarning(message), stacklevel=4)


def parse_value(text: str) -> Any:
    """A command-line value: JSON (``3``, ``0.5``, ``true``, ``null``, ``[1, 2]``,
    ``"text"``), Python's ``True``/``False``/``None``, else the text itself."""
    named = {"True": True, "False": False, "None": None}
    if text in named:
        return named[text]
    try:
        return json.loads(text)
    except ValueError:
        return text


def override(cfg: T, assignment: str) -> T:
    """``cfg`` (a config dataclass) with one field set from ``"dotted.path=value"`` (the value
    as :func:`parse_value` reads it), rebuilt through :func:`from_dict` so that the new value
    is type-checked like a loaded file; an unknown path or a bad value is a ``ConfigError``
    naming the field (and, for a field that moved or has a shortcut, where it lives)."""
    path, sep, text = assignment.partition("=")
    path = path.strip()
    if not sep or not path:
        raise ConfigError("--set", f"expected FIELD=VALUE, got {assignment!r}")
    return replace_paths(cfg, {path: parse_value(text.strip())}, shortcuts=False)


def replace_paths(cfg: T, values: Mapping[str, Any], shortcuts: bool = True) -> T:
    """``cfg`` with each dotted path of ``values`` set (a value may be a config dataclass: its
    fields are set; a field inside it given too wins), built anew through :func:`from_dict`:
    every value is type-checked and the result validated once, whatever the order.  With
    ``shortcuts``, a key without a dot may be one of the class's ``SHORTCUTS`` (``seed`` ->
    ``episode.scene.seed``)."""
    cls = type(cfg)
    table: Mapping[str, str] = getattr(cls, "SHORTCUTS", {}) if shortcuts else {}
    names = {f.name for f in dataclasses.fields(cfg)}  # type: ignore[arg-type]
    changes = {(table[k] if k in table and k not in names else k): v for k, v in values.items()}
    implied = getattr(cls, "_implied", None)
    if implied is not None:
        changes = implied(changes)
    data = to_dict(cfg)
    # a section before the fields inside it: ``episode`` and then ``episode.scene.seed``
    for path, value in sorted(changes.items(), key=lambda kv: kv[0].count(".")):
        _set_path(cls, data, path, to_dict(value))
    return from_dict(cls, data)


def _set_path(cls: type, data: dict[str, Any], path: str, value: Any) -> None:
    node: Any = data
    keys = path.split(".")
    for i, key in enumerate(keys):
        where = ".".join(keys[: i + 1])
        if not isinstance(node, dict) or key not in node:
            known = ", ".join(sorted(node)) if isinstance(node, dict) else "none (not a section)"
            raise ConfigError(where, f"no such field{_hint(cls, path)} (fields here: {known})")
        if i == len(keys) - 1:
            node[key] = value
        else:
            node = node[key]


def _hint(cls: type, path: str) -> str:
    """Where a field that is not at ``path`` lives: it moved, or ``path`` is a shortcut."""
    moved = getattr(cls, "MOVED", {}).get(path)
    if moved:
        return f"; it moved to {moved}"
    short = getattr(cls, "SHORTCUTS", {}).get(path)
    return f"; the shortcut {path} writes {short}" if short else ""


def flatten(cfg: Any) -> list[tuple[str, Any]]:
    """(dotted path, value) of every leaf field of a config: what ``override`` can set."""
    out: list[tuple[str, Any]] = []

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, dict) and value:
            for k, v in value.items():
                walk(f"{prefix}{k}.", v)
        else:
            out.append((prefix.rstrip("."), value))

    walk("", to_dict(cfg))
    return out


def pretty(cfg: Any) -> str:
    """Human-readable JSON of a config."""
    return json.dumps(to_dict(cfg), indent=2, sort_keys=False)


# ------------------------------------------------------------------------- range checks
def check_number(
    field: str,
    value: Any,
    lo: float | None = None,
    hi: float | None = None,
    error: ErrorFactory = ConfigError,
) -> float:
    """A finite real number (not a bool) within [lo, hi]; returns it as a float."""
    if not is_real(value):
        raise error(field, f"must be a number, got {_short(value)}")
    v = float(value)
    if not math.isfinite(v):
        raise error(field, f"must be a finite number, got {_short(value)}")
    if lo is not None and v < lo:
        raise error(field, f"must be >= {lo}, got {_short(value)}")
    if hi is not None and v > hi:
        raise error(field, f"must be <= {hi}, got {_short(value)}")
    return v


def check_int(
    field: str,
    value: Any,
    lo: int | None = None,
    hi: int | None = None,
    error: ErrorFactory = ConfigError,
) -> int:
    """An integer (not a bool) within [lo, hi]; returns it as an int."""
    if not is_int(value):
        raise error(field, f"must be an integer, got {_short(value)}")
    v = int(value)
    if lo is not None and v < lo:
        raise error(field, f"must be >= {lo}, got {v}")
    if hi is not None and v > hi:
        raise error(field, f"must be <= {hi}, got {v}")
    return v


def check_vector(
    field: str, value: Any, n: int, limit: float | None = None, error: ErrorFactory = ConfigError
) -> tuple[float, ...]:
    """``n`` finite numbers (each within +-``limit``); returns them as a tuple of floats."""
    if not isinstance(value, tuple | list) or len(value) != n:
        raise error(field, f"expected {n} numbers, got {_short(value)}")
    lo = None if limit is None else -limit
    return tuple(check_number(f"{field}[{i}]", v, lo, limit, error) for i, v in enumerate(value))


class Config:
    """Base of the config dataclasses: checked when made, printable, reloadable.

    A subclass (a ``@dataclass(frozen=True)``) that defines ``_validate(self)`` is checked on
    construction: :func:`check_fields` (types, named ``SECTION.field``) and then
    ``_validate``, which raises ``ConfigError`` naming the first impossible field.  A config
    that exists is therefore valid, and :meth:`validate` has nothing left to check (it returns
    the config, for code written when the check was a separate call).

    ``SECTION`` is how the class's errors name its fields when it is made on its own
    (``camera`` -> ``camera.width``); built through :func:`from_dict` (a file, ``--set``,
    :meth:`with_values`) they are named by their full path (``episode.scene.camera.width``).
    ``SHORTCUTS`` maps short names to the dotted path they write (``seed`` ->
    ``episode.scene.seed``): :meth:`of`, :meth:`with_values` and :meth:`replace` accept them;
    ``MOVED`` maps fields of earlier layouts to their place now (for error hints)."""

    SECTION: ClassVar[str] = ""
    SHORTCUTS: ClassVar[Mapping[str, str]] = {}
    MOVED: ClassVar[Mapping[str, str]] = {}

    def __post_init__(self) -> None:
        check = getattr(self, "_validate", None)
        if check is not None:
            check_fields(self, f"{self.SECTION}." if self.SECTION else "")
            check()

    def validate(self: T) -> T:
        """The config itself: it was checked when it was made."""
        return self

    def replace(self: T, **changes: Any) -> T:
        """A copy with ``changes`` (field names, or the class's ``SHORTCUTS``), checked."""
        names = {f.name for f in dataclasses.fields(self)}  # type: ignore[arg-type]
        if set(changes) <= names:
            return dataclasses.replace(self, **changes)  # type: ignore[type-var]
        return replace_paths(self, changes)

    def with_values(self: T, values: Mapping[str, Any] | None = None, /, **more: Any) -> T:
        """A copy with the dotted paths of ``values`` (``{"scene.camera.width": 160}``) and the
        fields or shortcuts of ``more`` set, checked once (see :func:`replace_paths`)."""
        return replace_paths(self, {**(values or {}), **more})

    @classmethod
    def of(cls: type[T], values: Mapping[str, Any] | None = None, /, **more: Any) -> T:
        """The default config with ``values`` / ``more`` set (see :meth:`with_values`):
        ``EpisodeConfig.of(seed=3, width=160, height=120)``."""
        return replace_paths(cls(), {**(values or {}), **more})

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
    """Validate a (min, max) range field: two finite numbers, min <= max, within [lo, hi]."""
    if not isinstance(value, tuple | list) or len(value) != 2:
        raise ConfigError(field, f"expected (min, max), got {_short(value)}")
    a = check_number(f"{field}[0]", value[0])
    b = check_number(f"{field}[1]", value[1])
    if a > b:
        raise ConfigError(field, f"min {a} is larger than max {b}")
    if lo is not None and a < lo:
        raise ConfigError(field, f"must be >= {lo}, got {a}")
    if hi is not None and b > hi:
        raise ConfigError(field, f"must be <= {hi}, got {b}")


def check_positive(field: str, value: float, allow_zero: bool = False) -> None:
    """A finite number > 0 (>= 0 with ``allow_zero``)."""
    v = check_number(field, value)
    if not (v >= 0 if allow_zero else v > 0):
        raise ConfigError(field, f"must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")
