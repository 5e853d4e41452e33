"""How the tables and lines etmpc prints write a count, a number and an interval: ``1 episode`` and
``2 episodes``, a float rounded to what it can say, and ``n/a`` where an interval cannot be had (one
episode has no spread), never ``nan`` or ``[nan, nan]``.

The ground floor: this module imports nothing of etmpc.
"""

from __future__ import annotations

import math

NOT_AVAILABLE = "n/a"  # an interval that cannot be had: one episode, or none finite


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``1 episode``, ``2 episodes`` (``plural``: where adding an s is wrong)."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def number(value: float, digits: int = 5) -> str:
    """``value`` with ``digits`` significant digits (``35.751``, ``1.2346e-05``), ``n/a`` if it is not finite."""
    return f"{value:.{digits}g}" if _finite(value) else NOT_AVAILABLE


def spread(value: float | None, spec: str = ".2f") -> str:
    """A ``± value`` half-width in ``spec``, or ``n/a`` where there is none (one episode)."""
    return format(value, spec) if _finite(value) else NOT_AVAILABLE


def interval(bounds, spec: str = ".1f") -> str:
    """``[low, high]`` in ``spec``, or ``n/a`` where either end cannot be had (one episode)."""
    low, high = bounds
    return f"[{low:{spec}}, {high:{spec}}]" if _finite(low) and _finite(high) else NOT_AVAILABLE


def _finite(value) -> bool:
    return value is not None and math.isfinite(value)
