"""The checks of the numbers a user gives, shared by the command line and the Python API, so that both
refuse the same input with the same message (the command line prefixes ``argument --NAME:``, the API
``NAME:``; both raise :class:`~etmpc.common.errors.EtmpcError`, exit code 2 on the command line)."""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import types
import typing
import warnings
from typing import Any

import numpy as np

from etmpc.common.errors import EtmpcError

MAX_WORKERS = 512
MAX_SEED = 2**63 - 1
DOUBLE_MAX = 1.7976931348623157e308  # the largest finite double (sys.float_info.max)
# What a learned policy's file (rl:, self:) may hold, checked when it is read (etmpc.policies.learned.LogisticPolicy.from_json
# says why): a weight at most MAX_WEIGHT in size, a normalisation's mean or scale at most MAX_SCALE, a scale at least MIN_SCALE
# (a fit writes a smaller standard deviation as 1).
MAX_WEIGHT, MAX_SCALE, MIN_SCALE = 1e6, 1e100, 1e-12


class BadValue(EtmpcError, ValueError):
    """A number out of its range or of the wrong kind (a ``ValueError`` too, for callers that catch those)."""


class BadType(EtmpcError, TypeError):
    """An argument of the wrong type (a path where a name is needed, ...): a ``TypeError`` too."""


def whole(value: Any) -> int:
    """``value`` as an int if it is a whole number (an int or numpy integer, never a bool or a float)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise BadValue(f"{value!r} is not a whole number")
    return int(value)


def flag(value: Any) -> bool:
    """``value`` as a bool if it is one (a Python or numpy bool). Anything else is refused, never read by
    its truth: ``"no"`` is a true string, and 0 or 1 may be a count given in the wrong place."""
    if not isinstance(value, (bool, np.bool_)):
        raise BadValue(f"must be True or False, got {type(value).__name__} {value!r}")
    return bool(value)


def at_least(value: int, low: int) -> int:
    if value < low:
        raise BadValue(f"must be >= {low}, got {value}")
    return value


def workers(value: Any) -> int:
    """A number of worker processes: 1..MAX_WORKERS."""
    value = at_least(whole(value), 1)
    if value > MAX_WORKERS:
        raise BadValue(f"at most {MAX_WORKERS} worker processes, got {value}")
    return value


def seed(value: Any) -> int:
    value = whole(value)
    if not 0 <= value <= MAX_SEED:
        raise BadValue(f"a seed is a whole number in 0..2**63-1, got {value}")
    return value


def price(value: Any) -> float:
    """A price of a recompute: a finite number >= 0."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise BadValue(f"{value!r} is not a number")
    if not (math.isfinite(value) and not value < 0):  # not below 0: typeshed's numbers.Real declares < and <=, not >=
        raise BadValue(f"a price of a recompute is a finite number >= 0, got {value}")
    return float(value)


def json_numbers(values: Any, name: str, largest: float = math.inf, smallest: float | None = None) -> np.ndarray:
    """``values``, the numbers of a file's field ``name`` as JSON gave them (a list, or a list of lists), as
    a float array, if each is a number (not a bool, a string or a null), finite, at most ``largest`` in
    size and, where ``smallest`` is given, at least it; else :class:`BadValue` naming the first that is not
    (``theta[3] is 1e+308, beyond the +-1e+06 it may be``). Compared as read (Python compares an int with a
    float exactly): an integer too large for a double is refused here, never an ``OverflowError``."""

    def check(value: Any, at: str) -> None:
        if isinstance(value, list):
            for i, item in enumerate(value):
                check(item, f"{at}[{i}]")
            return
        shown = repr(value) if len(repr(value)) <= 24 else repr(value)[:20] + "..."
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise BadValue(f"{at} is {shown}, not a number")
        if not (abs(value) <= DOUBLE_MAX if isinstance(value, int) else math.isfinite(value)):
            raise BadValue(f"{at} is {shown}, not a finite number")
        if not -largest <= value <= largest:
            raise BadValue(f"{at} is {shown}, beyond the +-{largest:g} it may be")
        if smallest is not None and value < smallest:
            raise BadValue(f"{at} is {shown}, below the {smallest:g} it may be")

    if not isinstance(values, list):
        raise BadValue(f"{name} is not a list of numbers ({type(values).__name__})")
    check(values, name)
    try:
        return np.array(values, dtype=float)
    except ValueError:  # lists of different lengths
        raise BadValue(f"{name} is not a list of numbers of one shape") from None


def argument(name: str, check, value: Any):
    """``check(value)``, its error naming the argument ``name`` (``workers: must be >= 1, got 0``)."""
    try:
        return check(value)
    except BadValue as exc:
        raise BadValue(f"{name}: {exc}") from None


def renamed(new: str, value: Any, old: str, old_value: Any, required: bool = True, stacklevel: int = 3) -> Any:
    """The value of a parameter that was called ``old`` before it was called ``new``: the old keyword
    works for one release, with a ``DeprecationWarning``; both at once, or neither when ``required``,
    is an error naming them. The warning names the line that called the caller (``stacklevel`` 3), or the
    frame ``stacklevel`` says."""
    if old_value is not None:
        if value is not None:
            raise EtmpcError(f"{new}: give it once ({old}= is its old name)")
        warnings.warn(f"the keyword {old}= is deprecated: call it {new}=", DeprecationWarning, stacklevel=stacklevel)
        return old_value
    if value is None and required:
        raise EtmpcError(f"{new}: missing")
    return value


# -- records read from files and settings: every field of the type its dataclass annotates -----------------
#: The largest count a setting may hold: more than any run could do (an episode a second for 30 years),
#: small enough for every C integer, array and range a count ends up in.
MAX_COUNT = 10**9


def short(count: int) -> str:
    """A large whole number as a reader takes it in: ``10**9`` is ``1e9``."""
    return f"{count:.0e}".replace("e+0", "e").replace("e+", "e") if count >= 10**6 else str(count)


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _conforms(value: Any, hint: Any, finite: bool, most: int | None) -> bool:
    """Whether ``value`` is of the type ``hint`` (an annotation: int, float, str, bool, None, ``X | Y``,
    ``list[X]``, ``tuple[X, ...]``, ``dict[K, V]``, ``Any``, a class), as a file's reader must see it."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return True
    if hint is type(None):
        return value is None
    if origin in (typing.Union, types.UnionType):
        return any(_conforms(value, arg, finite, most) for arg in args)
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        whole = isinstance(value, numbers.Integral) and not isinstance(value, bool)
        return whole and (most is None or abs(value) <= most)
    if hint is float:  # an integer beyond a double is not finite (math.isfinite would raise OverflowError)
        real = isinstance(value, numbers.Real) and not isinstance(value, bool)
        whole_number = isinstance(value, numbers.Integral)
        return real and (not finite or (abs(value) <= DOUBLE_MAX if whole_number else math.isfinite(value)))
    if origin in (list, tuple):
        if not isinstance(value, origin):
            return False
        if origin is tuple and args and args[-1] is not Ellipsis:
            return len(value) == len(args) and all(_conforms(v, a, finite, most) for v, a in zip(value, args))
        return not args or all(_conforms(v, args[0], finite, most) for v in value)
    if origin is dict:
        return isinstance(value, dict) and all(
            _conforms(k, args[0], finite, most) and _conforms(v, args[1], finite, most) for k, v in value.items()
        )
    return isinstance(value, origin or hint)


_WORDS = {
    int: "a whole number",
    float: "a number",
    str: "text",
    bool: "true or false",
    type(None): "null",
    list: "a list",
    dict: "an object",
}


def _spelled(hint: Any, finite: bool = False, most: int | None = None) -> str:
    """``hint`` in words: ``a whole number in 0..10**9 or null``, ``a list of text``."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_spelled(arg, finite, most) for arg in args)
    if origin in (list, tuple) and args:
        return "a list of " + ", ".join(_spelled(a, finite, most) for a in args if a is not Ellipsis)
    if origin is dict:
        return f"an object of {_spelled(args[1], finite, most)}"
    word = _WORDS.get(hint, getattr(hint, "__name__", str(hint)))
    if hint is int and most is not None:
        word += f" in -{short(most)}..{short(most)}"
    return word + (" (finite)" if hint is float and finite else "")


def typed(record: Any, finite: bool = False, most: int | None = None) -> None:
    """Raise :class:`BadValue` naming the first field of the dataclass ``record`` whose value is not of its
    annotated type (a bool is not a number; with ``finite``, a float is finite; with ``most``, a whole number
    is within ``-most..most``): the one check of settings and of records read from files, so that text where
    a number goes, a list where an object goes or a count past any C integer is one line, before any work."""
    kind: type = type(record)  # a class, hashable: the key of _hints' cache (mypy takes type[Any] for unhashable)
    for field in dataclasses.fields(record):
        hint = _hints(kind)[field.name]
        value = getattr(record, field.name)
        if not _conforms(value, hint, finite, most):
            raise BadValue(f"{field.name} must be {_spelled(hint, finite, most)}, got {_shown(value)}")


def typed_json(data: Any, hints: dict[str, Any], name: str, optional: tuple[str, ...] = (), finite=True, most=MAX_COUNT) -> dict:
    """``data``, the JSON object a file holds at ``name`` (``curve[0]``; ``""``: the file's own), if it has each field
    of ``hints`` (a field's name -> its annotated type, as :func:`typed` reads them) but those in ``optional``, no
    other, and each of its type (by default, as a file's must be: each float finite, each whole number within
    ``MAX_COUNT``); else :class:`BadValue` naming the first that is not (``curve[0].objective must be a number
    (finite), got 'x'``). :func:`typed` for records read from a file, whose fields need not be Python names."""
    if not isinstance(data, dict):
        raise BadValue(f"{name or 'it'} must be an object, got {_shown(data)}")
    missing = [key for key in hints if key not in data and key not in optional]
    if missing:
        raise BadValue(f"{name or 'it'} has no field {missing[0]!r}")
    unknown = [key for key in data if key not in hints]
    if unknown:
        raise BadValue(f"{name or 'it'} has a field it must not have, {_shown(unknown[0])}")
    for key, hint in hints.items():
        if key in data and not _conforms(data[key], hint, finite, most):
            field = f"{name}.{key}" if name else key
            raise BadValue(f"{field} must be {_spelled(hint, finite, most)}, got {_shown(data[key])}")
    return data


def _shown(value: Any) -> str:
    """``value`` as a message quotes it: its ``repr``, at most 60 characters."""
    return repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
