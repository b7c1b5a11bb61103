"""Errors of invalid input, and the translation of pydantic's validation errors into them.

The configuration (:mod:`lawn_env.config`), the RL interface (:mod:`lawn_env.interface`) and the
planners' settings are pydantic dataclasses. Their constructors raise :class:`ConfigError` (a
``ValueError``) instead of pydantic's raw ``ValidationError``: one line that names each bad field
by its dotted path, the value given and what the field allows (:func:`readable_errors`), with no
link to pydantic's documentation. Unknown keys raise :class:`UnknownConfigKeyError`, which is also
a ``TypeError``.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import annotated_types
from pydantic import ValidationError

__all__ = ["ConfigError", "UnknownConfigKeyError", "readable_errors", "describe_allowed"]


class ConfigError(ValueError):
    """An invalid configuration value. The message names each bad field by its dotted path
    (``channel.blocklength``), the value given and what is allowed; ``fields`` holds those paths."""

    def __init__(self, message: str, fields: Sequence[str] = ()):
        super().__init__(message)
        self.fields = tuple(fields)


class UnknownConfigKeyError(ConfigError, TypeError):
    """A configuration key (a keyword of ``gym.make``, a dotted override, a dict key) that the
    scenario does not have. A ``TypeError``, as Python raises for an unexpected keyword argument
    (libraries such as TorchRL retry without keywords an env rejects that way), and a
    ``ValueError`` (a :class:`ConfigError`) like every other invalid configuration."""


# ---------------------------------------------------------------------- what a field allows
_NOUNS = {int: ("an integer", "integers"), float: ("a number", "numbers"), str: ("a string", "strings"),
          bool: ("true or false", "booleans")}


def _number(x: Any) -> str:
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e7:
        return str(int(x))
    return repr(x) if isinstance(x, float) else str(x)


def _bounds(metadata: Sequence[Any]) -> str:
    lo: tuple[str, Any] | None = None
    hi: tuple[str, Any] | None = None
    for m in metadata:
        if isinstance(m, annotated_types.Ge):
            lo = ("[", m.ge)
        elif isinstance(m, annotated_types.Gt):
            lo = ("(", m.gt)
        elif isinstance(m, annotated_types.Le):
            hi = ("]", m.le)
        elif isinstance(m, annotated_types.Lt):
            hi = (")", m.lt)
        elif hasattr(m, "metadata"):  # a FieldInfo inside Annotated[...]
            inner = _bounds(m.metadata)
            if inner:
                return inner
    if lo and hi:
        return f" in {lo[0]}{_number(lo[1])}, {_number(hi[1])}{hi[0]}"
    if lo:
        return f" {'>=' if lo[0] == '[' else '>'} {_number(lo[1])}"
    if hi:
        return f" {'<=' if hi[0] == ']' else '<'} {_number(hi[1])}"
    return ""


def describe_allowed(annotation: Any, metadata: Sequence[Any] = ()) -> str:  # noqa: PLR0911 - one return per kind of type
    """What a field of this type and these constraints allows, in words: ``an integer in [1, 256]``,
    ``one of 'auto', 'paper', 'random'``, ``a sequence of 6 numbers``, ``a number in (0, 1] or None``."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Annotated:
        return describe_allowed(args[0], [*metadata, *args[1:]])
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (typing.Union, types.UnionType):
        options = [a for a in args if a is not type(None)]
        text = " or ".join(describe_allowed(a, metadata) for a in options)
        return text + (" or None" if len(options) < len(args) else "")
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a sequence of {_NOUNS.get(args[0], (None, 'values'))[1]}"
        if args and all(a == args[0] for a in args):
            return f"a sequence of {len(args)} {_NOUNS.get(args[0], (None, 'values'))[1]}"
        return f"a sequence of {len(args)} values"
    if isinstance(annotation, type) and dataclasses.is_dataclass(annotation):
        return f"a {annotation.__name__} or a dict of its fields"
    if annotation in _NOUNS:
        return _NOUNS[annotation][0] + ("" if annotation is bool else _bounds(metadata))
    return getattr(annotation, "__name__", str(annotation)) + _bounds(metadata)


def _fields(cls: Any) -> dict[str, Any]:
    return dict(getattr(cls, "__pydantic_fields__", {}) or {})


# ---------------------------------------------------------------------- pydantic's errors, readable
_MISSING = object()


def _given(cls: Any, args: tuple[Any, ...], kwargs: Mapping[str, Any], names: Sequence[str]) -> Any:
    """The value the caller gave at the field path ``names`` (positional or keyword, through nested
    dicts and dataclasses), or ``_MISSING``."""
    if not names:
        return _MISSING
    order = list(_fields(cls))
    first = names[0]
    if first in kwargs:
        value = kwargs[first]
    elif first in order and order.index(first) < len(args):
        value = args[order.index(first)]
    else:
        return _MISSING
    for name in names[1:]:
        if isinstance(value, Mapping) and name in value:
            value = value[name]
        elif dataclasses.is_dataclass(value) and hasattr(value, name):
            value = getattr(value, name)
        else:
            return _MISSING
    return value


def _reason(msg: str) -> str:
    for head in ("Input should be ", "Value should be "):
        if msg.startswith(head):
            return "should be " + msg[len(head):]
    return msg[:1].lower() + msg[1:] if msg[1:2].islower() else msg


def _locate(cls: Any, loc: tuple[Any, ...]) -> tuple[list[str], Any, Any, tuple[Any, ...]]:
    """Walk an error's ``loc`` through the (nested) dataclass fields of ``cls``: the field names on
    the way, the last field's ``FieldInfo`` (None at the root), the dataclass it holds (None for a
    leaf) and what is left of ``loc`` past the fields (tuple indices, an unknown key)."""
    owner, field = cls, None
    names: list[str] = []
    for i, part in enumerate(loc):
        fields = _fields(owner) if owner is not None else {}
        positional = i == 0 and isinstance(part, int) and part < len(fields)
        name = list(fields)[part] if positional else part
        if not (isinstance(name, str) and name in fields):
            return names, field, owner, loc[i:]
        names.append(name)
        field = fields[name]
        owner = field.annotation if isinstance(field.annotation, type) and dataclasses.is_dataclass(field.annotation) \
            else None
    return names, field, owner, ()


def _reason_at(kind: str, msg: str, rest: tuple[Any, ...], value: Any) -> str:
    """Why a field's value is refused, in words: tuple entries by index, a short tuple by its length."""
    if rest and isinstance(rest[0], int) and kind == "missing":
        return f"has {len(value) if isinstance(value, Sequence) else 'too few'} entries"
    if rest and isinstance(rest[0], int):
        return f"entry {rest[0]} {_reason(msg)}"
    return _reason(msg)


class _Report:
    """The problems of one ``ValidationError``, gathered by field (:func:`readable_errors`)."""

    def __init__(self, cls: Any, args: tuple[Any, ...], kwargs: Mapping[str, Any], prefix: str):
        self.cls, self.args, self.kwargs, self.prefix = cls, args, kwargs, prefix
        self.unknown: list[tuple[str, str, str]] = []  # (dotted key, the keyword, valid keys there)
        self.problems: dict[str, dict[str, Any]] = {}  # dotted field -> value, reasons, allowed
        self.remarks: list[str] = []  # the model validators' own messages (they name their fields)
        self.positional: list[str] = []

    def add(self, err: Mapping[str, Any]) -> None:
        loc, kind, msg = tuple(err.get("loc", ())), err.get("type", ""), err.get("msg", "")
        cls, prefix = self.cls, self.prefix
        if kind == "unexpected_positional_argument":  # one line, however many arguments are too many
            fields = list(_fields(cls))
            self.positional[:] = [(f"{len(self.args)} positional arguments {self.args!r}: {cls.__name__} takes at "
                                   f"most {len(fields)} (allowed: {', '.join(fields)} in this order, or as keywords)")]
            return
        names, field, owner, rest = _locate(cls, loc)
        if kind in ("unexpected_keyword_argument", "extra_forbidden"):
            valid = ", ".join(prefix + ".".join([*names, f]) for f in _fields(owner)) if owner is not None else ""
            key = prefix + ".".join(str(p) for p in loc)
            self.unknown.append((key, str(loc[-1]) if loc else key, valid))
            return
        if kind in ("value_error", "assertion_error") and not rest and (field is None or owner is not None):
            text = msg.split(", ", 1)[1] if msg.startswith(("Value error, ", "Assertion failed, ")) else msg
            if text not in self.remarks:
                self.remarks.append(text)
            return
        value = _given(cls, self.args, self.kwargs, names)
        value = err.get("input") if value is _MISSING else value
        entry = self.problems.setdefault(prefix + ".".join(names) or cls.__name__,
                                         {"value": value, "reasons": [], "allowed": None})
        if field is not None and kind != "literal_error":  # a Literal's message lists the allowed values
            entry["allowed"] = describe_allowed(field.annotation, field.metadata)
        reason = _reason_at(kind, msg, rest, value)
        if reason not in entry["reasons"]:
            entry["reasons"].append(reason)

    def error(self, noun: str, fallback: Sequence[Mapping[str, Any]]) -> ConfigError:
        parts = [f"{p}={e['value']!r}: {', '.join(e['reasons'])}"
                 + (f" (allowed: {e['allowed']})" if e["allowed"] else "") for p, e in self.problems.items()]
        parts += self.remarks + self.positional
        name = self.cls.__name__
        if self.unknown:
            keys = ", ".join(repr(k) for k, _, _ in self.unknown)
            words = ", ".join(repr(w) for _, w, _ in self.unknown)
            many, valid = len(self.unknown) > 1, self.unknown[0][2]
            text = (f"unknown {noun}{'s' if many else ''} {keys} (unexpected keyword argument{'s' if many else ''} "
                    f"{words}) of {name}" + (f"; valid {noun}s: {valid}" if valid else "")
                    + (f"; also invalid: {'; '.join(parts)}" if parts else ""))
            return UnknownConfigKeyError(text, [k for k, _, _ in self.unknown] + list(self.problems))
        if not parts:  # nothing recognised: still one line, without the links
            parts = [f"{'.'.join(map(str, e.get('loc', ()))) or name}: {e.get('msg', '')}" for e in fallback]
        return ConfigError(f"invalid {name}: " + "; ".join(parts), list(self.problems))


def readable_errors(cls: Any, exc: ValidationError, args: tuple[Any, ...] = (), kwargs: Mapping[str, Any] | None = None,
                    prefix: str = "", noun: str = "config key") -> ConfigError:
    """The :class:`ConfigError` (or :class:`UnknownConfigKeyError`) for pydantic's ``exc``, raised
    building ``cls(*args, **kwargs)``: one line naming every bad field by its dotted path
    (``prefix`` first: ``"channel."`` for a section built on its own), the value given and what the
    field allows (its type and bounds), without pydantic's documentation links. Unknown keys (called
    ``noun`` in the message) give an :class:`UnknownConfigKeyError` listing the valid ones."""
    report = _Report(cls, tuple(args), dict(kwargs or {}), prefix)
    errors = exc.errors(include_url=False)
    for err in errors:
        report.add(err)
    return report.error(noun, errors)


def raises_config_errors(prefix: str = "", noun: str = "config key") -> Any:
    """Class decorator for a pydantic dataclass: its constructor raises :func:`readable_errors`'
    :class:`ConfigError` instead of pydantic's ``ValidationError`` (fields named with ``prefix``,
    unknown keys called ``noun``)."""

    def wrap(cls: Any) -> Any:
        init = cls.__init__

        @functools.wraps(init)
        def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
            try:
                init(self, *args, **kwargs)
            except ValidationError as exc:
                raise readable_errors(cls, exc, args, kwargs, prefix, noun) from None

        cls.__init__ = __init__
        return cls

    return wrap

