"""The checks of the numbers a user gives, shared by the command line and the Python API, so that both
refuse the same input with the same message (the command line prefixes ``argument --NAME:``, the API
``NAME:``; both raise :class:`~etmpc.common.errors.EtmpcError`, exit code 2 on the command line)."""

from __future__ import annotations

import math
import numbers
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
    """A price of a computation: a finite number >= 0."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise BadValue(f"{value!r} is not a number")
    if not (math.isfinite(value) and value >= 0):
        raise BadValue(f"a price of a computation is a finite number >= 0, got {value}")
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


def renamed(new: str, value: Any, old: str, old_value: Any, required: bool = True) -> Any:
    """The value of a parameter that was called ``old`` before it was called ``new``: the old keyword
    works for one release, with a ``DeprecationWarning``; both at once, or neither when ``required``,
    is an error naming them."""
    if old_value is not None:
        if value is not None:
            raise EtmpcError(f"{new}: give it once ({old}= is its old name)")
        warnings.warn(f"the keyword {old}= is deprecated: call it {new}=", DeprecationWarning, stacklevel=3)
        return old_value
    if value is None and required:
        raise EtmpcError(f"{new}: missing")
    return value
