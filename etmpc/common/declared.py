"""What a setting may be, declared beside its field: its range or choices, its unit, and why.

A task's options (``--option NAME=VALUE``, ``SystemKey(task, options=...)``, ``options=`` in Gymnasium) are
the fields of its ``Config`` and of the settings within it. A field is an option only if it is declared with
:func:`setting`::

    horizon: int = setting(20, low=1, high=100, unit="intervals", why="the MPC's horizon N: its OCP grows with it")

The declaration is data, read by one check (:meth:`Declared.check`) wherever a value enters: when an option is
set from text or from the API, and when a settings object is made (the ``__post_init__`` of the :class:`Checked`
base, which holds NumPy numbers as Python's own). So a value no controller can have (a weight of 0 where the LQR
needs R > 0, a negative interval, a horizon of 10^5 that would build for hours) is refused in one line before any
work, naming the option and what it may be; and no option can hang a run or exhaust memory, since every number
has a finite range. A word is chosen from its ``choices``, never passed on: no option names a library to load,
a file to read or code to run. A free label (a platform's name) is text of bounded length, shown and never read.

What depends on more than one field (shooting blocks no longer than the horizon, one value per state of the
task's plant) is checked where the system is made (:func:`etmpc.systems.options.check_together`).

This module is on the ground floor: it imports only :mod:`etmpc.common`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import typing
from dataclasses import MISSING, dataclass
from typing import Any

import numpy as np

from etmpc.common.checks import BadType, BadValue, short

#: The longest label a free-text setting may hold (a platform's name is shown in tables and files).
MAX_LABEL = 80
#: In a tuple's ``lengths``: one value per state of the task's plant, checked where the system is made (a
#: sensor's settings are the controller's, whatever the plant).
PER_STATE = -1
KEY = "etmpc.declared"  # the dataclass field's metadata key


@dataclass(frozen=True)
class Declared:
    """What one setting may be. Numbers: ``low``/``high`` inclusive, ``above``/``below`` exclusive (a number
    needs a lower and an upper bound, so that none is unbounded); tuples: the range of each element and the
    ``lengths`` they may have (None: any, checked against the plant where the system is made); words: their
    ``choices``; labels: ``label`` (free text of at most :data:`MAX_LABEL` characters, no control character).

    ``why`` says in one line what the setting is and why it is bounded; ``unit`` its unit ("" for none);
    ``draws``: it says how episodes are drawn (a rate, a range), so it acts on newly drawn episodes
    (``etmpc testset --option ...``), not on a stored test set's; ``pair``: a range ``(low, high)`` with
    ``low <= high``."""

    why: str
    low: float | None = None
    high: float | None = None
    above: float | None = None
    below: float | None = None
    choices: tuple[str, ...] = ()
    lengths: tuple[int, ...] | None = None
    label: bool = False
    unit: str = ""
    draws: bool = False
    pair: bool = False  # a range (low, high): two values, low <= high

    def _in_range(self, value: float) -> bool:
        return (
            (self.low is None or value >= self.low)
            and (self.high is None or value <= self.high)
            and (self.above is None or value > self.above)
            and (self.below is None or value < self.below)
        )

    def _bounds(self) -> str:
        """``in [0, 1)``, ``in 1..100`` for whole numbers (written by :meth:`describe`)."""
        left = "[" if self.low is not None else "("
        right = "]" if self.high is not None else ")"
        return f"in {left}{_number(self._lower())}, {_number(self._upper())}{right}"

    def _lower(self) -> float:
        """The lower bound, inclusive (``low``) or not (``above``): a number has one (checked by :func:`setting`)."""
        bound = self.low if self.low is not None else self.above
        assert bound is not None, "a number needs a lower bound"
        return bound

    def _upper(self) -> float:
        """The upper bound, inclusive (``high``) or not (``below``): a number has one (checked by :func:`setting`)."""
        bound = self.high if self.high is not None else self.below
        assert bound is not None, "a number needs an upper bound"
        return bound

    def describe(self, kind: Any) -> str:
        """What the setting may be, in words: ``a whole number in 1..100``, ``one of qrqp, osqp``."""
        element = element_of(kind)
        scalar = element if element is not None else kind
        if scalar is bool:
            word = "true or false"
        elif self.choices:
            word = "one of " + ", ".join(self.choices)
        elif self.label:
            word = f"a label of at most {MAX_LABEL} characters"
        elif scalar is int:
            low = self.low if self.low is not None else self._lower() + 1
            high = self.high if self.high is not None else self._upper() - 1
            word = f"a whole number in {short(int(low))}..{'2**63-1' if high == 2**63 - 1 else short(int(high))}"
        else:
            word = f"a number {self._bounds()}"
        if element is None:
            return word
        return f"a pair (low, high), low <= high, each {word}" if self.pair else f"{self._counts()}, each {word}"

    def _counts(self) -> str:
        if self.lengths is None:
            return "any number of values"
        if PER_STATE not in self.lengths:
            return " or ".join(str(n) for n in self.lengths) + (" value" if self.lengths == (1,) else " values")
        return "one value per state, one for all, or none" if 0 in self.lengths else "one value per state or one for all"

    def check(self, name: str, kind: Any, value: Any) -> Any:
        """``value`` if setting ``name`` of type ``kind`` may hold it (a tuple's elements each), as Python's own
        types (a NumPy bool, integer or float is taken as Python's; a list of values as a tuple); else
        :class:`BadValue` (a value of another type, :class:`BadType`) naming it and saying what it may be. Never
        read by its truth: ``"no"`` or 1 is no bool."""
        element = element_of(kind)
        if element is not None:
            if not isinstance(value, (tuple, list)):
                raise BadType(f"{name}: {_shown(value)} is not a list of values; it is {self.describe(kind)}")
            per_state = PER_STATE in (self.lengths or ()) and len(value) >= 2  # the plant's count: checked when it is made
            if self.lengths is not None and len(value) not in self.lengths and not per_state:
                raise BadValue(f"{name}: {_shown(value)} has {len(value)} values; it is {self.describe(kind)} ({self.why})")
            held = tuple(self._scalar(name, element, item, kind, value) for item in value)
            if self.pair and held[0] > held[1]:
                raise BadValue(f"{name}: {_shown(value)} is not {self.describe(kind)} ({self.why})")
            return held
        return self._scalar(name, kind, value, kind, value)

    def _scalar(self, name: str, kind: Any, value: Any, whole_kind: Any, whole: Any) -> Any:
        wrong = f"{name}: {_shown(whole)} is not {self.describe(whole_kind)} ({self.why})"
        if kind is bool:
            if not isinstance(value, (bool, np.bool_)):
                raise BadType(wrong)
            return bool(value)
        if kind is str:
            if not isinstance(value, str):
                raise BadType(wrong)
            if self.choices and value not in self.choices:
                raise BadValue(wrong)
            if self.label and (len(value) > MAX_LABEL or any(ord(c) < 32 or ord(c) == 127 for c in value)):
                raise BadValue(wrong)
            return value
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise BadType(wrong)
        if kind is int and not isinstance(value, numbers.Integral):
            raise BadType(wrong)
        # typeshed's numbers stubs are incomplete (its note says so): a checker sees no Real as a float, which it is here
        if not (math.isfinite(value) and self._in_range(value)):  # type: ignore[arg-type]
            raise BadValue(wrong)
        if type(value) in (int, float):
            return value
        return int(value) if isinstance(value, numbers.Integral) else float(value)


def _number(value: float) -> str:
    """``1e6`` as ``1e6``, not ``1e+06``."""
    return f"{value:g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")


def _shown(value: Any) -> str:
    text = repr(tuple(value) if isinstance(value, list) else value)
    return text if len(text) <= 60 else text[:57] + "..."


def element_of(kind: Any) -> Any | None:
    """The element type of ``tuple[X, ...]``; else None."""
    if typing.get_origin(kind) is tuple:
        args = typing.get_args(kind)
        if len(args) == 2 and args[1] is Ellipsis:
            return args[0]
    return None


def setting(
    default: Any = MISSING,
    *,
    why: str,
    low: float | None = None,
    high: float | None = None,
    above: float | None = None,
    below: float | None = None,
    choices: tuple[str, ...] = (),
    lengths: tuple[int, ...] | None = None,
    label: bool = False,
    unit: str = "",
    draws: bool = False,
    pair: bool = False,
    default_factory: Any = MISSING,
) -> Any:
    """A dataclass field that is an option, with what it may be (:class:`Declared`). A numeric setting must
    have both a lower and an upper bound (an option without one could ask for unbounded work), a word its
    choices: :func:`declarations` refuses one that has not."""
    declared = Declared(why, low, high, above, below, tuple(choices), (2,) if pair else lengths, label, unit, draws, pair)
    return dataclasses.field(default=default, default_factory=default_factory, metadata={KEY: declared})


@functools.cache
def declarations(cls: type) -> dict[str, tuple[Declared, Any]]:
    """Every declared field of the dataclass ``cls`` by name, with its declaration and its type. A subclass that
    gives a field another default (``compute_levels: bool = True``) keeps the declaration its base made."""
    hints = typing.get_type_hints(cls)
    found = {}
    for field in dataclasses.fields(cls):
        for klass in cls.__mro__:
            own = vars(klass).get("__dataclass_fields__", {}).get(field.name)
            if own is not None and KEY in own.metadata:
                found[field.name] = (_complete(own.metadata[KEY], hints[field.name], field.name), hints[field.name])
                break
    return found


def _complete(declared: Declared, kind: Any, name: str) -> Declared:
    """``declared``, if it says all that a setting of type ``kind`` needs: a number both bounds, a word its
    choices or that it is a label (a mistake in etmpc's own declarations, found by the first use)."""
    scalar = element_of(kind) or kind
    if scalar in (int, float) and (
        declared.low is None and declared.above is None or declared.high is None and declared.below is None
    ):
        raise TypeError(f"setting {name}: a number needs a lower and an upper bound")
    if scalar is str and not (declared.choices or declared.label):
        raise TypeError(f"setting {name}: a word needs its choices, or to be a label")
    if scalar not in (int, float, str, bool):
        raise TypeError(f"setting {name}: a setting is a number, a word, true or false, or a tuple of them")
    return declared


def check_per_state(name: str, declared: Declared, value: Any, states: int) -> None:
    """A tuple declared :data:`PER_STATE` against a plant of ``states`` states: one of its other lengths, or one
    value per state."""
    if declared.lengths is not None and PER_STATE in declared.lengths and len(value) not in (*declared.lengths, states):
        raise BadValue(
            f"{name}: {_shown(value)} has {len(value)} values, for a plant of {states} states; it is "
            f"{declared._counts().replace('per state', f'per state ({states})')}"
        )


def check_fields(settings: Any, prefix: str = "") -> None:
    """Check every declared field of the (frozen) dataclass ``settings`` (not those within it), naming each
    ``PREFIX + field``, and hold each as Python's own types (:meth:`Declared.check`)."""
    cls: type = type(settings)  # a class, hashable: the key of declarations' cache (mypy takes type[Any] for unhashable)
    for name, (declared, kind) in declarations(cls).items():
        value = getattr(settings, name)
        held = declared.check(f"{prefix}{name}", kind, value)
        if held is not value:  # a NumPy number, a list: held as Python's own, the equal value
            object.__setattr__(settings, name, held)


class Checked:
    """A base for settings dataclasses: each declared field is checked when the object is made. A subclass with
    a ``__post_init__`` of its own calls ``super().__post_init__()`` after it has normalised its fields."""

    def __post_init__(self) -> None:
        check_fields(self, f"{type(self).__name__}.")
