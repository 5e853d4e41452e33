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


# A name's unit suffix (etmpc names carry their unit: ``force_n``, ``vx_m_s``) and the unit it stands for, the
# longer suffixes first (``_rad_s2`` before ``_rad_s`` before ``_s``).
_UNITS = (
    ("_rad_s2", "rad/s²"),
    ("_rad_s", "rad/s"),
    ("_m_s", "m/s"),
    ("_eur_kwh", "EUR/kWh"),
    ("_rad", "rad"),
    ("_nm", "N m"),
    ("_kwh", "kWh"),
    ("_kw", "kW"),
    ("_n", "N"),
    ("_m", "m"),
    ("_s", "s"),
)


def unit_label(name: str) -> str:
    """A state's, input's or signal's name as an axis label with its unit, read from the name's suffix:
    ``vx_m_s`` -> ``vx (m/s)``, ``shoulder_torque_nm`` -> ``shoulder torque (N m)``; a name without a unit suffix
    as its words."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix) and len(name) > len(suffix):
            return f"{name.removesuffix(suffix).replace('_', ' ')} ({unit})"
    return name.replace("_", " ")


def _finite(value) -> bool:
    return value is not None and math.isfinite(value)
