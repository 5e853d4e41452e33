"""A task's options: the fields of its ``Config`` set by name, from the command line (``--option NAME=VALUE``)
or the API (``SystemKey(task, options={...})``).

An option's name is a field of the task's ``Config``, or a dotted path into one of its settings
(``sensor.noise_std``, ``estimator.process_std``, ``latency.intervals``). Its value is parsed by the field's
type: a number, ``true``/``false``, a word, or comma-separated values for a tuple (``0.01,0,0.02,0``).
:func:`settable` lists a task's options with their defaults (``etmpc tasks --options`` prints them). The
price of a recompute has its own argument (``--price``), not an option.

Options are kept as ``(name, text)`` pairs in the canonical text of their parsed value (:func:`canonical`),
sorted by name: two ways of writing the same options give the same key, the same card and the same replay.

This module may import ``etmpc.common`` and ``etmpc.control``.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Iterable, Mapping
from functools import cache
from typing import Any

from etmpc.common.checks import BadValue
from etmpc.common.errors import EtmpcError, UnknownNameError

NOT_OPTIONS = ("recompute_price",)  # set by its own argument (--price, SystemKey's recompute_price)
_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


@cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _kind(cls: type, name: str, value: Any) -> Any:
    """The type of field ``name`` of dataclass ``cls`` (its annotation, resolved; else its value's)."""
    try:
        return _hints(cls)[name]
    except (NameError, KeyError, TypeError):
        return type(value)


def _scalar(kind: Any) -> bool:
    return kind in (bool, int, float, str)


def _element(kind: Any) -> Any | None:
    """The element type of ``tuple[X, ...]`` where X is a scalar type; else None."""
    if typing.get_origin(kind) is tuple:
        args = typing.get_args(kind)
        if len(args) == 2 and args[1] is Ellipsis and _scalar(args[0]):
            return args[0]
    return None


def settable(config: Any, prefix: str = "") -> dict[str, Any]:
    """Every option of ``config`` (a task's Config, or one of its settings) by dotted name, with its value:
    the scalar fields, the tuples of scalars, and those of the dataclasses within (not the price)."""
    found: dict[str, Any] = {}
    for f in dataclasses.fields(config):
        if not prefix and f.name in NOT_OPTIONS:
            continue
        value, kind = getattr(config, f.name), _kind(type(config), f.name, getattr(config, f.name))
        if dataclasses.is_dataclass(value):
            found |= settable(value, f"{prefix}{f.name}.")
        elif _scalar(kind) or _element(kind) is not None:
            found[f"{prefix}{f.name}"] = value
    return found


def _parse_scalar(kind: type, text: str, name: str) -> Any:
    word = text.strip()
    if kind is bool:
        if word.lower() in _TRUE:
            return True
        if word.lower() in _FALSE:
            return False
        raise BadValue(f"option {name}: {text!r} is not true or false")
    if kind is str:
        return word
    try:
        value = kind(word)
    except ValueError:
        raise BadValue(f"option {name}: {text!r} is not {'a whole number' if kind is int else 'a number'}") from None
    if kind is float and not math.isfinite(value):
        raise BadValue(f"option {name}: {text!r} is not a finite number")
    return value


def parse(kind: Any, text: str, name: str) -> Any:
    """The value of option ``name`` of type ``kind`` written as ``text``."""
    element = _element(kind)
    if element is not None:
        words = [w for w in text.split(",") if w.strip()]
        return tuple(_parse_scalar(element, w, name) for w in words)
    return _parse_scalar(kind, text, name)


def canonical(value: Any) -> str:
    """An option's value as text, one way only (``parse`` reads it back to the same value)."""
    if isinstance(value, tuple):
        return ",".join(canonical(v) for v in value)
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def split(text: str) -> tuple[str, str]:
    """``NAME=VALUE`` as ``(NAME, VALUE)``."""
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise EtmpcError(f"an option is NAME=VALUE (e.g. sensor.noise_std=0.01), got {text!r}")
    return name.strip(), value


def _set(config: Any, path: list[str], text: str, name: str, known: Iterable[str]) -> Any:
    head, *rest = path
    fields = {f.name for f in dataclasses.fields(config)}
    if head not in fields or (name == head and head in NOT_OPTIONS):
        hint = " (the price is --price, not an option)" if head in NOT_OPTIONS else ""
        raise UnknownNameError(f"unknown option {name!r}{hint}; valid: {', '.join(known)}")
    value = getattr(config, head)
    if rest:
        if not dataclasses.is_dataclass(value):
            raise UnknownNameError(f"unknown option {name!r}; valid: {', '.join(known)}")
        return dataclasses.replace(config, **{head: _set(value, rest, text, name, known)})
    kind = _kind(type(config), head, value)
    if not (_scalar(kind) or _element(kind) is not None):
        raise UnknownNameError(f"option {name!r} is not a number, a word or a list of them; valid: {', '.join(known)}")
    return dataclasses.replace(config, **{head: parse(kind, text, name)})


def apply(config: Any, options: Mapping[str, Any] | Iterable[tuple[str, Any]]) -> Any:
    """``config`` with ``options`` set (each value text to parse, or a value of the field's type). An unknown
    name is refused listing the valid ones; a bad value names the option; the settings' own checks run."""
    items = options.items() if isinstance(options, Mapping) else options
    if not dataclasses.is_dataclass(config):
        raise EtmpcError(f"this task's Config ({type(config).__name__}) is not a dataclass: it takes no options")
    known = tuple(settable(config))
    for name, value in items:
        text = value if isinstance(value, str) else canonical(value if not isinstance(value, list) else tuple(value))
        try:
            config = _set(config, name.split("."), text, name, known)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, EtmpcError):
                raise
            raise BadValue(f"option {name}: {exc}") from None
    return config


def normalised(config: Any, options: Mapping[str, Any] | Iterable[tuple[str, Any]]) -> tuple[tuple[str, str], ...]:
    """``options`` checked against ``config`` and written canonically, sorted by name: ``((name, text), ...)``.
    An option given twice is refused; one set to its default is kept (it says what was asked)."""
    items = list(options.items() if isinstance(options, Mapping) else options)
    names = [n for n, _ in items]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise EtmpcError(f"option {twice[0]} is given twice")
    made = apply(config, items)
    values = settable(made)
    return tuple(sorted((name, canonical(values[name])) for name in names))


def of(config: Any) -> dict[str, str]:
    """The options ``config`` (a task's Config) was set with: each of its options that differs from the
    default ``type(config)()``'s, as canonical text (``{}`` for the task as it is)."""
    made, default = settable(config), settable(type(config)())
    return {name: canonical(value) for name, value in sorted(made.items()) if value != default.get(name)}


def shown(options: tuple[tuple[str, str], ...]) -> str:
    """Options as the command line writes them: ``--option a=1 --option b=2``."""
    return " ".join(f"--option {name}={text}" for name, text in options)
