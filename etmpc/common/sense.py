"""Which way is better: an objective is a cost (``"min"``: lower is better) or a profit (``"max"``).

Decided here only, for every floor (the statistics of :mod:`etmpc.evaluation.metrics`, which
re-exports these, the evaluations, the learners and the views)."""

from __future__ import annotations

import numpy as np

SENSES = ("min", "max")


def _checked(sense: str) -> str:
    if sense not in SENSES:
        raise ValueError(f"an objective's sense is 'min' or 'max', got {sense!r}")
    return sense


def oriented(values, sense: str):
    """``values`` (objectives of sense ``sense``) so that higher is better: themselves for a profit
    (``"max"``), negated for a cost (``"min"``). A number stays a number; a list becomes an array.
    Negation is exact, so ``oriented(a) - oriented(b)`` is ``a - b`` or ``b - a`` bit for bit."""
    if isinstance(values, (list, tuple)):
        values = np.asarray(values, dtype=float)
    return values if _checked(sense) == "max" else -values


def sign(sense: str) -> float:
    """``1.0`` for a profit, ``-1.0`` for a cost: what multiplies an objective into higher-is-better."""
    return 1.0 if _checked(sense) == "max" else -1.0


def best(candidates, sense: str, key):
    """The candidate whose ``key`` is best in ``sense`` (the largest for ``"max"``, the smallest for
    ``"min"``; the first of a tie, as :func:`max` and :func:`min`)."""
    return (max if _checked(sense) == "max" else min)(candidates, key=key)


def higher_or_lower(sense: str) -> str:
    """``"higher"`` or ``"lower"``: which is better, in words."""
    return "higher" if _checked(sense) == "max" else "lower"


def cost_or_profit(sense: str) -> str:
    """``"cost"`` or ``"profit"``: what the objective is, in words."""
    return "profit" if _checked(sense) == "max" else "cost"
