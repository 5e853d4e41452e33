"""What a resumed training run is checked against before any work, for every learner alike.

A folder handed to ``--resume`` is data, and maybe someone else's or an edited one. So:

* it must hold the run asked for (:func:`same_run`, called by :func:`etmpc.learning.runner.run`): the
  task at its price with its options (``str`` of the :class:`~etmpc.systems.SystemKey`) and the settings,
  as the learner's saved state keeps them (:meth:`~etmpc.learning.base.Learner.saved_identity`) against
  the run asked for (:meth:`~etmpc.learning.base.Learner.identity`), whether it is under way or finished:
  a run finished with other options is not the run asked for either;
* each field of its saved state is of its type and size (:func:`numbers` here, and
  :func:`etmpc.common.checks.typed_json` for records), read by the learner's own reader; one that is not is
  one line naming the file and the field (:func:`corrupt`), never a traceback half-way through the run.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from etmpc.common import checks
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import what_differs

if TYPE_CHECKING:
    from etmpc.learning.base import Learner

AGAIN = "start the run again in another --out"  # the remedy for a saved state that cannot be read as the run's


def corrupt(where: str | Path, problem: Any, error: type[EtmpcError] = EtmpcError) -> EtmpcError:
    """The one-line error of a saved state ``where`` (a file) whose field is not what it must be (``problem``
    names the field: a :class:`~etmpc.common.checks.BadValue`'s message)."""
    return error(f"{where} is corrupt ({problem}); {AGAIN}")


def numbers(values: Any, name: str, shape: tuple[int, ...] | None = None, smallest: float | None = None) -> np.ndarray:
    """``values``, the numbers a saved state holds at ``name`` (a list, or a list of lists), as a float array of
    ``shape`` (where given) if each is a finite number (not a bool, a string or a null) and at least ``smallest``
    (where given); else :class:`~etmpc.common.checks.BadValue` naming the first that is not, or the shape.
    A run's state may hold millions (DPI's labels), so plain numbers are checked at once and only a bad list
    is walked number by number (:func:`~etmpc.common.checks.json_numbers`) to name the one at fault."""
    array = None
    if _plain(values):
        try:
            array = np.array(values, dtype=float)
        except (ValueError, OverflowError):  # ragged, or an integer beyond a double
            array = None
    if array is None or not np.all(np.isfinite(array)) or (smallest is not None and np.any(array < smallest)):
        array = checks.json_numbers(values, name, smallest=smallest)  # raises, naming the number at fault
    if shape is not None and array.shape != shape:
        raise checks.BadValue(f"{name} holds {_size(array.shape)}, not the run's {_size(shape)}")
    return array


def number(value: Any, name: str) -> float:
    """``value``, the number a saved state holds at ``name``, if it is a finite number (not a bool, text or null)."""
    shown = repr(value) if len(repr(value)) <= 24 else repr(value)[:20] + "..."  # as json_numbers shows one
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise checks.BadValue(f"{name} is {shown}, not a number")
    if not (abs(value) <= checks.DOUBLE_MAX if isinstance(value, int) else math.isfinite(value)):
        raise checks.BadValue(f"{name} is {shown}, not a finite number")
    return float(value)


def _plain(values: Any) -> bool:
    """Whether ``values`` is a list (of lists) of ints and floats only (no bool, text or null)."""
    if type(values) is not list:
        return False
    if values and type(values[0]) is list:
        return all(_plain(item) for item in values)
    return all(type(item) is float or type(item) is int for item in values)


def _size(shape: tuple[int, ...]) -> str:
    return f"{shape[0]} numbers" if len(shape) == 1 else " x ".join(map(str, shape)) + " numbers"


def same_run(learner: Learner, state: dict) -> None:
    """Refuse, in one line, to resume from ``state`` (the learner's :meth:`~etmpc.learning.base.Learner.saved_state`)
    a run of another task, price or options, or of other settings, than the one ``learner`` is asked to make. A
    learner that keeps no identity in its state (:meth:`~etmpc.learning.base.Learner.saved_identity` None) is not
    checked here."""
    found = learner.saved_identity(state)
    if found is None:
        return
    where, saved = found
    wanted = learner.identity()
    if saved["task"] != wanted["task"]:
        raise EtmpcError(
            f"{where} holds a {learner.name} run on {saved['task']}, not {wanted['task']}; resume it with that task, "
            "price and options, or choose another --out"
        )
    if saved["settings"] != wanted["settings"]:
        raise EtmpcError(
            f"{where} holds a {learner.name} run made with different settings "
            f"({what_differs(saved['settings'], wanted['settings'])}); resume it with the same ones, or choose another --out"
        )
