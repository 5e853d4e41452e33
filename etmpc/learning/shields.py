"""Choosing a task's shield rule (``shield:``, :mod:`etmpc.policies.shield`) on training-distribution episodes.

Every rule of a grid (a maximum plan age, a safety margin, or both) is played around each given policy on
the first ``episodes`` episodes of the validation stream (``VALIDATION_ENTROPY``: never the test set),
beside the best fixed schedule on the same episodes. A shield is insurance, bought with objective: among
the rules whose shielded policies' mean objective is worse than the unshielded policies' by at most
``budget`` (a share of it, :data:`BUDGET`), the chosen rule is the safest (the one under which the policy
that fails most often fails least per episode), then the one with the best mean objective. A rule that
costs more buys safety the validation episodes cannot tell from noise when failures are rare. None is
chosen if no rule is within the budget, or if the chosen one would be no safer than no shield. Whether
the chosen rule (or no shield) is as safe as the schedule on these episodes is said beside it (``safe``).
The unshielded policies are played too, as the row the choice is measured against. :func:`pick` chooses
from a table alone, so a stored table can be read again.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from etmpc.common.sense import oriented
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import episode_outcomes
from etmpc.systems import make_system
from etmpc.systems.capabilities import ShieldRule


BUDGET = 0.01  # the share of the unshielded policies' mean objective a shield may cost on validation episodes


@dataclass(frozen=True)
class Outcome:
    """A policy's means over the validation episodes."""

    objective: float
    failures: float
    recomputes: float


def _mean(rows: np.ndarray) -> Outcome:
    return Outcome(*(float(v) for v in rows.mean(axis=0)))


def rules(ages: Sequence[int], margins: Sequence[float | None]) -> list[ShieldRule]:
    """The grid: every age with every margin (``None``: by age alone)."""
    return [ShieldRule(age, margin) for age in ages for margin in margins]


def choose(
    task: str,
    policies: Sequence[str],
    schedule: str,
    grid: Sequence[ShieldRule],
    episodes: int,
    pool,
    tick: Callable | None = None,
) -> dict:
    """Play ``policies`` unshielded and under each rule of ``grid``, and ``schedule``, on ``episodes`` validation
    episodes; return the table and the chosen rule (see the module's docstring)."""
    system = make_system(task)
    specs = [schedule, *policies] + [f"shield:{rule.text}:{p}" for rule in grid for p in policies]
    played = dict(
        zip(specs, (_mean(rows) for rows in episode_outcomes(pool, system.name, specs, VALIDATION_ENTROPY, episodes, tick)))
    )

    def summary(prefix: str) -> dict:
        outcomes = [played[prefix + p] for p in policies]
        return {
            "objective": float(np.mean([o.objective for o in outcomes])),
            "worst_failures": max(o.failures for o in outcomes),
            "policies": {p: vars(played[prefix + p]) for p in policies},
        }

    result = {
        "task": system.name,
        "episodes": episodes,
        "validation_entropy": VALIDATION_ENTROPY,
        "objective_sense": system.objective_sense,
        "schedule": {"spec": schedule, **vars(played[schedule])},
        "unshielded": summary(""),
        "rules": [{"rule": rule.text, **summary(f"shield:{rule.text}:")} for rule in grid],
        "margin_unit": system.margin_unit,
    }
    return pick(result)


def pick(result: dict, budget: float = BUDGET) -> dict:
    """``result`` (:func:`choose`'s, or one stored) with its ``chosen`` rule (None: none within ``budget``), the
    ``budget`` it was chosen within, and whether the chosen rule is as safe as the schedule (``safe``)."""
    sense, unshielded = result["objective_sense"], result["unshielded"]["objective"]
    allowed = oriented(unshielded, sense) - budget * abs(unshielded)  # the worst oriented objective a rule may give
    within = [row for row in result["rules"] if oriented(row["objective"], sense) >= allowed]
    chosen = min(within, key=lambda row: (row["worst_failures"], -oriented(row["objective"], sense)), default=None)
    if chosen is not None and chosen["worst_failures"] >= result["unshielded"]["worst_failures"]:
        chosen = None  # it buys no safety
    limit = result["schedule"]["failures"]
    safe = (chosen or result["unshielded"])["worst_failures"] <= limit
    return dict(result, chosen=None if chosen is None else chosen["rule"], budget=budget, safe=bool(safe))
