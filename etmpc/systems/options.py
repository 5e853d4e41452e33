"""A task's options: the fields of its ``Config`` set by name, from the command line (``--option NAME=VALUE``)
or the API (``SystemKey(task, options={...})``).

An option's name is a declared field of the task's ``Config`` (:func:`~etmpc.common.declared.setting`: its
range or choices, its unit and why), or a dotted path into one of its settings (``sensor.noise_std``,
``estimator.process_std``, ``latency.intervals``); a field that is not declared is no option. Its value is
parsed by the field's type (a number, ``true``/``false``, a word, or comma-separated values for a tuple:
``0.01,0,0.02,0``), then checked against its declaration before anything is built. :func:`settable` lists a
task's options with their defaults, :func:`described` with what each may be (``etmpc options --task TASK``
prints both). The price of a recompute has its own argument (``--price``), not an option.

Options are kept as ``(name, text)`` pairs in the canonical text of their parsed value (:func:`canonical`),
sorted by name: two ways of writing the same options give the same key, the same card and the same replay.

This module may import ``etmpc.common`` and ``etmpc.control``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

from etmpc.common.checks import BadType, BadValue
from etmpc.common.declared import Declared, check_per_state, declarations, element_of
from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.control.settings import check_block

NOT_OPTIONS = ("recompute_price",)  # set by its own argument (--price, SystemKey's recompute_price)
_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def _scalar(kind: Any) -> bool:
    return kind in (bool, int, float, str)


def _element(kind: Any) -> Any | None:
    """The element type of ``tuple[X, ...]`` where X is a scalar type; else None."""
    element = element_of(kind)
    return element if _scalar(element) else None


def _declared(config: Any) -> dict[str, tuple[Declared, Any]]:
    """The options among ``config``'s own fields (not those of the settings within it): each declared one
    (:func:`~etmpc.common.declared.setting`) of a scalar type or a tuple of scalars, but the price."""
    config_class: type = type(config)  # a class is hashable (declarations caches by it); type[Any] reads as not
    return {
        name: (declared, kind)
        for name, (declared, kind) in declarations(config_class).items()
        if name not in NOT_OPTIONS and (_scalar(kind) or _element(kind) is not None)
    }


def _walk(config: Any, prefix: str = "") -> Iterator[tuple[str, Declared, Any, Any]]:
    """``(dotted name, declaration, type, value)`` of every option of ``config`` and the settings within it."""
    own = _declared(config)
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            yield from _walk(value, f"{prefix}{f.name}.")
        elif f.name in own:
            yield (f"{prefix}{f.name}", *own[f.name], value)


def settable(config: Any) -> dict[str, Any]:
    """Every option of ``config`` (a task's Config, or one of its settings) by dotted name, with its value:
    its declared fields, and those of the dataclasses within (not the price)."""
    return {name: value for name, _, _, value in _walk(config)}


def described(config: Any) -> dict[str, tuple[Declared, Any]]:
    """Every option of ``config`` by dotted name, with its declaration and its type (as :func:`settable`)."""
    return {name: (declared, kind) for name, declared, kind, _ in _walk(config)}


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
    own = _declared(config)
    if head not in own:
        raise UnknownNameError(f"{name!r} is not an option (a setting of the task's own); valid: {', '.join(known)}")
    declared, kind = own[head]
    parsed = declared.check(f"option {name}", kind, parse(kind, text, name))  # what it may be, said in its words
    return dataclasses.replace(config, **{head: parsed})


def drawn_only(config: Any, options: Iterable[tuple[str, Any]]) -> list[str]:
    """The names among ``options`` (valid ``(name, value)`` pairs of ``config``'s options) declared ``draws``: they
    say how episodes are drawn (a rate, a range), so they act on newly drawn episodes only, never on a stored test
    set's, whose episodes were drawn once and are replayed as they are."""
    declared = described(config)
    return [name for name, _ in options if name in declared and declared[name][0].draws]


def pairs(options: Any, argument: str = "options") -> list[tuple[str, Any]]:
    """``options`` as ``(name, value)`` pairs: a mapping of option names to values, or an iterable of
    ``(name, value)`` pairs; anything else is a :class:`BadType` naming ``argument`` and the shape it needs."""
    need = f"{argument} must be a mapping of option names to values (or (name, value) pairs)"
    if isinstance(options, Mapping):
        items = list(options.items())
    elif isinstance(options, (str, bytes)) or not isinstance(options, Iterable):
        raise BadType(f"{need}, got {type(options).__name__} {options!r:.60}")
    else:
        items = list(options)
        wrong = next((item for item in items if not (isinstance(item, (tuple, list)) and len(item) == 2)), None)
        if wrong is not None:
            raise BadType(f"{need}, got an entry {wrong!r:.60}")
    name = next((name for name, _ in items if not isinstance(name, str)), None)
    if name is not None:
        raise BadType(f"{need}: an option's name is text, got {type(name).__name__} {name!r:.60}")
    return items


def apply(config: Any, options: Mapping[str, Any] | Iterable[tuple[str, Any]]) -> Any:
    """``config`` with ``options`` set (each value text to parse, or a value of the field's type). An unknown
    name is refused listing the valid ones; a value is checked against what the option may be (its
    declaration: :mod:`etmpc.common.declared`), then by the settings' own checks."""
    items = pairs(options)
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
    items = pairs(options)
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


def options_line(options: Mapping[str, str] | Iterable[tuple[str, str]] | None) -> list[str]:
    """The line a table starts with when its run was played with options (``options: --option a=1 ...``), in a
    list to splice into the table's lines; none for the task as it is, whose tables stay as they were."""
    items = tuple((options or {}).items()) if isinstance(options, Mapping) or options is None else tuple(options)
    return [f"options: {shown(items)}"] if items else []


def check_together(system) -> None:
    """What of a system's Config depends on more than one field or on the plant, checked where the system is made
    (each field alone was checked when its settings were made: :mod:`etmpc.common.declared`): a per-state setting
    has one value per state of the plant (or one for all), and the MPC's shooting blocks fit in its horizon."""
    config = system.config
    if not dataclasses.is_dataclass(config):
        return
    values, states = {}, len(system.state_names)
    for name, declared, _, value in _walk(config):
        check_per_state(f"option {name}", declared, value, states)
        values[name] = value
    block, horizon = values.get("solver.block"), values.get("horizon")
    if block is not None and horizon is not None:
        check_block(block, horizon)
