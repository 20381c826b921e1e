"""Registries of plug-in parts (flow back ends, segmentation methods), reached by a spec string.

A spec names one part and, optionally, parameters for its constructor::

    SPEC   := TARGET ("," KEY "=" VALUE)*
    TARGET := NAME               a registered name: a built-in, or an installed package's entry
                                 point in the registry's group (e.g. ``cablesim.flows``)
            | MODULE ":" ATTR    a class (or factory) in any importable module, e.g. my_flow:MyFlow
    VALUE  := a JSON literal (2, 0.5, true, null, "text") or else the bare text

so ``dis,preset=fast``, ``raft,checkpoint=weights.pt`` and ``my_flow:ShiftFlow,dx=2`` are all
specs.  A part is built by calling the target with the registered defaults, the spec's
parameters and the caller's keyword arguments (later ones win).  An unknown name is an
:class:`~cablesim.errors.InputError` that lists the valid choices.

Built-ins register a ``"module:attr"`` string, so a heavy back end (RAFT's torch) is imported
only when it is used; entry points are read with :func:`importlib.metadata.entry_points` each
time a name is not a built-in (a package installed while Python runs is found).
"""

from __future__ import annotations

import importlib
import inspect
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any, Generic, TypeVar

from cablesim.errors import InputError

T = TypeVar("T")


@dataclass(frozen=True)
class Spec:
    """A parsed spec: the target (a name or ``MODULE:ATTR``) and its parameters."""

    text: str
    target: str
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def is_path(self) -> bool:
        """Whether the target is ``MODULE:ATTR`` rather than a registered name."""
        return ":" in self.target


def _value(text: str) -> Any:
    try:
        return json.loads(text)
    except ValueError:
        return text


def parse_spec(text: str, kind: str = "part") -> Spec:
    """``"target,key=value,..."`` -> :class:`Spec` (module docstring)."""
    if not isinstance(text, str) or not text.strip():
        raise InputError(f"a {kind} must be a non-empty name or MODULE:CLASS, got {text!r}")
    target, *pairs = (p.strip() for p in text.strip().split(","))
    if not target:
        raise InputError(f"{kind} {text!r}: the name before the first ',' is empty")
    if target.count(":") > 1 or target.startswith(":") or target.endswith(":"):
        raise InputError(f"{kind} {text!r}: write MODULE:CLASS (one ':'), e.g. my_flow:MyFlow")
    params: dict[str, Any] = {}
    for pair in pairs:
        key, eq, value = pair.partition("=")
        key = key.strip()
        if not eq or not key.isidentifier():
            raise InputError(f"{kind} {text!r}: parameter {pair!r} is not KEY=VALUE")
        if key in params:
            raise InputError(f"{kind} {text!r}: parameter {key!r} is given twice")
        params[key] = _value(value.strip())
    return Spec(text, target, params)


@dataclass(frozen=True)
class Entry:
    """One registered part: what to call (``"module:attr"`` or the object) and its defaults."""

    name: str
    target: str | Callable[..., Any]
    defaults: Mapping[str, Any] = field(default_factory=dict)
    summary: str = ""
    origin: str = "built-in"  # or "entry point <value> (<distribution>)"


@dataclass(frozen=True)
class Resolved:
    """A spec made concrete: the factory to call and every parameter it gets."""

    spec: Spec
    name: str  # the registered name, or MODULE:ATTR
    factory: Callable[..., Any]
    params: dict[str, Any]


def load_attr(path: str, what: str | None = None) -> Any:
    """The object ``MODULE:ATTR`` names (``ATTR`` may be dotted); ``InputError`` naming
    ``what`` (default: the path) if the module or the attribute is missing."""
    what = what or repr(path)
    module, _, attr = path.partition(":")
    try:
        obj: Any = importlib.import_module(module)
    except ImportError as e:
        raise InputError(f"{what}: cannot import module {module!r} ({e})") from e
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise InputError(f"{what}: module {module!r} has no {attr!r}") from None
    return obj


class Registry(Generic[T]):
    """Named parts of one kind, all instances of ``base`` (module docstring)."""

    def __init__(self, kind: str, base: type[T], group: str) -> None:
        self.kind, self.base, self.group = kind, base, group
        self._entries: dict[str, Entry] = {}

    # ------------------------------------------------------------------ registering
    def register(
        self,
        name: str,
        target: str | Callable[..., Any],
        summary: str = "",
        **defaults: Any,
    ) -> None:
        """Register ``target`` (a class, a factory or ``"module:attr"``) as ``name``."""
        if not isinstance(name, str) or not name or any(c in name for c in ",:= "):
            raise InputError(f"a {self.kind} name must be non-empty without ',:= ', got {name!r}")
        if name in self._entries:
            raise InputError(f"{self.kind} {name!r} is registered already")
        self._entries[name] = Entry(name, target, dict(defaults), summary)

    def unregister(self, name: str) -> None:
        """Forget ``name`` (``InputError`` if it is not registered here)."""
        if name not in self._entries:
            raise InputError(f"{self.kind} {name!r} is not registered")
        del self._entries[name]

    # ------------------------------------------------------------------ looking up
    def builtins(self) -> list[str]:
        """The names registered in code (the built-ins and any registered at run time)."""
        return list(self._entries)

    def _installed(self) -> dict[str, list[Any]]:
        found: dict[str, list[Any]] = {}
        for ep in entry_points(group=self.group):
            found.setdefault(ep.name, []).append(ep)
        return found

    def names(self) -> list[str]:
        """Every name a spec may use: the built-ins, then the installed entry points."""
        return self.builtins() + sorted(n for n in self._installed() if n not in self._entries)

    def entry(self, name: str) -> Entry:
        """The registered entry of ``name`` (a built-in, else an entry point of ``group``)."""
        if name in self._entries:
            return self._entries[name]
        eps = self._installed().get(name)
        if not eps:
            raise InputError(self._unknown(name))
        values = sorted({ep.value for ep in eps})
        if len(values) > 1:
            raise InputError(
                f"{self.kind} {name!r} is registered by several installed packages "
                f"({', '.join(values)}); give one of them as MODULE:CLASS"
            )
        ep = eps[0]
        dist = getattr(getattr(ep, "dist", None), "name", None) or "an installed package"
        return Entry(name, ep.value, {}, "", f"entry point {ep.value} ({dist})")

    def _unknown(self, name: str) -> str:
        return (
            f"unknown {self.kind} {name!r}; choose one of {', '.join(self.names())}, "
            f"or give MODULE:CLASS (a {self.base.__name__} in an importable module)"
        )

    def resolve(self, spec: str | Spec) -> Resolved:
        """The factory and parameters of ``spec``; imports the target's module, not more."""
        s = spec if isinstance(spec, Spec) else parse_spec(spec, self.kind)
        if s.is_path:
            name, target, defaults = s.target, s.target, {}
        else:
            e = self.entry(s.target)
            name, target, defaults = e.name, e.target, dict(e.defaults)
        factory = load_attr(target, f"{self.kind} {name!r}") if isinstance(target, str) else target
        if inspect.isclass(factory):
            if not issubclass(factory, self.base):
                raise InputError(
                    f"{self.kind} {name!r}: {factory.__module__}.{factory.__qualname__} is not "
                    f"a subclass of {self.base.__module__}.{self.base.__name__}"
                )
            if inspect.isabstract(factory):
                missing = ", ".join(sorted(factory.__abstractmethods__))
                raise InputError(f"{self.kind} {name!r}: {factory.__name__} lacks {missing}")
        elif not callable(factory):
            raise InputError(f"{self.kind} {name!r}: {target!r} is neither a class nor callable")
        return Resolved(s, name, factory, {**defaults, **s.params})

    def check(self, spec: str | Spec, complete: bool = False) -> Resolved:
        """:meth:`resolve`, and the spec's parameters are ones the factory takes; with
        ``complete`` they must include the required ones (else the caller may add them at
        :meth:`create`).  Builds nothing."""
        r = self.resolve(spec)
        self._bind(r, r.params, partial=not complete)
        return r

    def _bind(self, r: Resolved, params: dict[str, Any], partial: bool) -> None:
        try:
            sig = inspect.signature(r.factory)
        except (TypeError, ValueError):  # a builtin without a signature: let the call decide
            return
        try:
            (sig.bind_partial if partial else sig.bind)(**params)
        except TypeError as e:
            raise InputError(
                f"{self.kind} {r.name!r}: {e} (its parameters: {_parameters(sig)})"
            ) from None

    def create(self, spec: str | Spec, **kwargs: Any) -> T:
        """A new part built from ``spec`` (``kwargs`` add to or override its parameters)."""
        r = self.resolve(spec)
        params = {**r.params, **kwargs}
        self._bind(r, params, partial=False)
        obj = r.factory(**params)
        if not isinstance(obj, self.base):
            raise InputError(
                f"{self.kind} {r.name!r} made a {type(obj).__name__}, not a {self.base.__name__}"
            )
        return obj

    def describe(self) -> list[dict[str, Any]]:
        """Name, target, defaults, summary and origin of every name (for listings)."""
        out = []
        for name in self.names():
            e = self.entry(name)
            target = e.target if isinstance(e.target, str) else _qualname(e.target)
            out.append(
                {
                    "name": name,
                    "target": target,
                    "defaults": dict(e.defaults),
                    "summary": e.summary,
                    "origin": e.origin,
                }
            )
        return out


def _qualname(obj: Any) -> str:
    return f"{getattr(obj, '__module__', '?')}:{getattr(obj, '__qualname__', repr(obj))}"


def _parameters(sig: inspect.Signature) -> str:
    names = [
        p.name
        for p in sig.parameters.values()
        if p.kind not in (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    ]
    return ", ".join(names) or "none"
