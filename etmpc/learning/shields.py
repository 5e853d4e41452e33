"""Choosing a task's shield rule (``shield:``, :mod:`etmpc.policies.shield`) on training-distribution episodes.

Every rule of a grid (a maximum plan age, a safety margin, or both, and a bound on the state's deviation from
the plan) is played around each given policy on the first ``episodes`` episodes of the validation stream
(``VALIDATION_ENTROPY``: never the test set),
beside the best fixed schedule on the same episodes. A shield is insurance, bought with objective: among
the rules whose shielded policies' mean objective is worse than the unshielded policies' by at most
``budget`` (a share of it, :data:`BUDGET`), the chosen rule is the safest (the one under which the policy
that fails most often fails least per episode), then the one with the best mean objective. A rule that
costs more buys safety the validation episodes cannot tell from noise when failures are rare. None is
chosen if no rule is within the budget, or if the chosen one would be no safer than no shield. Whether
the chosen rule (or no shield) is as safe as the schedule on these episodes is said beside it (``safe``).
The unshielded policies are played too, as the row the choice is measured against. :func:`pick` chooses
from a table alone, so a stored table can be read again.

:func:`certify` chooses by a bound instead of a budget, safety as a constraint: a rule (or no shield) is
*certified* when, for every policy, the paired difference of failures per episode against the schedule, on
the same validation episodes, has a 95 % upper confidence bound of at most ``bound`` (:data:`SAFETY_BOUND`),
the bound widened for the number of rules tried (Bonferroni), so that the one chosen is not the luckiest of
many, and every policy under it still beats the schedule's mean objective (a shield that makes a learner dearer
than the schedule buys nothing the schedule does not give cheaper). Among the certified, the best mean objective
wins. This is the test a shipped learner is held to on
fresh episodes (the ``safety`` study), asked of validation episodes first. Where nothing is certified, not
even no shield, :func:`certify_or_budget` falls back on the budget's choice, said to be uncertified: a task
whose failures are rare and long (a quadrotor that stays on the ground) may certify nothing on a thousand
episodes, and no shield at all would be the worst answer to that.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from etmpc.common.sense import oriented
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import episode_outcomes
from etmpc.systems import make_system
from etmpc.systems.capabilities import ShieldRule


BUDGET = 0.01  # the share of the unshielded policies' mean objective a shield may cost on validation episodes
SAFETY_BOUND = 0.05  # failures per episode a shielded learner may add to the schedule's (a 95 % upper bound)
CONFIDENCE = 0.95  # of certify's bound, shared by the rules it tries


@dataclass(frozen=True)
class Outcome:
    """A policy's means over the validation episodes."""

    objective: float
    failures: float
    recomputes: float


def _mean(rows: np.ndarray) -> Outcome:
    return Outcome(*(float(v) for v in rows.mean(axis=0)))


def rules(ages: Sequence[int], margins: Sequence[float | None], deviations: Sequence[float | None] = (None,)) -> list[ShieldRule]:
    """The grid: every age with every margin (``None``: by age alone), and each rule with a margin with every
    deviation (``None``: not read; a deviation is read only beside a margin)."""
    return [
        ShieldRule(age, margin, deviation)
        for age in ages
        for margin in margins
        for deviation in (deviations if margin is not None else (None,))
    ]


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
    rows = dict(zip(specs, episode_outcomes(pool, system.name, specs, VALIDATION_ENTROPY, episodes, tick)))
    played = {spec: _mean(outcomes) for spec, outcomes in rows.items()}

    def summary(prefix: str) -> dict:
        outcomes = [played[prefix + p] for p in policies]
        return {
            "objective": float(np.mean([o.objective for o in outcomes])),
            "worst_failures": max(o.failures for o in outcomes),
            "policies": {
                p: dict(vars(played[prefix + p]), failure_gap=paired_gap(rows[prefix + p][:, 1], rows[schedule][:, 1]))
                for p in policies
            },
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
    return dict(
        result, chosen=None if chosen is None else chosen["rule"], budget=budget, selection={"by": "budget"}, safe=bool(safe)
    )


def select(result: dict) -> dict:
    """``result`` chosen again as it was chosen (its ``selection``: by :func:`certify`'s bound, by
    :func:`certify_or_budget`'s fallback, or by :func:`pick`'s budget, which a table made before the choice was
    recorded was chosen by)."""
    selection = result.get("selection", {"by": "budget"})
    if selection["by"] == "certify" or selection.get("uncertified"):
        return certify_or_budget(result, selection["bound"], selection["confidence"], result.get("budget", BUDGET))
    return pick(result, result.get("budget", BUDGET))


def certify_or_budget(result: dict, bound: float = SAFETY_BOUND, confidence: float = CONFIDENCE, budget: float = BUDGET) -> dict:
    """:func:`certify`'s choice where a candidate (a rule, or no shield) is certified; else :func:`pick`'s within
    ``budget``, its ``selection`` keeping the bounds certification found (``uncertified``: True) and ``safe``
    False: not certified, whatever its mean failures say."""
    certified = certify(result, bound, confidence)
    if certified["certified"]:
        return certified
    fallback = pick(result, budget)
    return dict(fallback, selection={**certified["selection"], "by": "budget", "uncertified": True}, certified=[], safe=False)


def paired_gap(values: np.ndarray, reference: np.ndarray) -> dict:
    """The paired difference ``values - reference`` over the same episodes: its mean, standard deviation
    (``ddof=1``) and the number of episodes, what a confidence bound on it needs."""
    gap = np.asarray(values, dtype=float) - np.asarray(reference, dtype=float)
    return {"mean": float(gap.mean()), "sd": float(gap.std(ddof=1)) if len(gap) > 1 else 0.0, "episodes": len(gap)}


def upper_bound(gap: dict, z: float, least_sd: float = 0.0) -> float:
    """``mean + z sd / sqrt(n)`` of a :func:`paired_gap`, its upper confidence bound at ``z``, with ``sd`` at least
    ``least_sd``."""
    return gap["mean"] + z * max(gap["sd"], least_sd) / np.sqrt(gap["episodes"])


def candidates(result: dict) -> list[dict]:
    """A table's rows as chosen among: no shield (``"rule": "none"``, the unshielded row) first, then each rule's."""
    return [{"rule": "none", **result["unshielded"]}, *result["rules"]]


def certify(result: dict, bound: float = SAFETY_BOUND, confidence: float = CONFIDENCE) -> dict:
    """``result`` (:func:`choose`'s) with its ``chosen`` rule by certification (see the module's docstring):
    ``certified`` lists the candidates (``"none"``: no shield) whose every policy's failure gap to the schedule
    has its upper bound at most ``bound`` and whose every policy still beats the schedule's mean objective (those
    within the bound that do not are the selection's ``behind_schedule``); ``chosen`` is the certified rule with
    the best mean objective (None: no shield, certified or not; ``safe`` says whether what is chosen was
    certified)."""
    rows = candidates(result)
    if any("failure_gap" not in p for row in rows for p in row["policies"].values()):
        raise ValueError("this table has no paired failure gaps (made before certify was written): play it again")
    # a two-sided (1 - confidence) interval's upper end, shared by the candidates (Bonferroni)
    z = NormalDist().inv_cdf(1.0 - (1.0 - confidence) / (2 * len(rows)))
    # Failures are rare: a few hundred episodes may see none, and a spread of 0 would certify anything. The
    # spread is taken at least as that of one more failure in a share `bound` of the episodes, the gap at the
    # bound itself (as Wilson's interval takes the variance at the value tested): with no failure seen, about
    # z^2 (1 - bound) / bound episodes certify (150 at 0.05 and z = 2.8).
    share = min(bound, 0.5)
    least = float(np.sqrt(share * (1.0 - share)))
    worst = {row["rule"]: max(upper_bound(p["failure_gap"], z, least) for p in row["policies"].values()) for row in rows}
    # A shield that leaves a learner worse on objective than the schedule buys nothing the schedule does not give
    # cheaper: a rule is certified only where every learner under it still beats the schedule on mean objective.
    sense = result["objective_sense"]
    schedule = oriented(result["schedule"]["objective"], sense)
    ahead = {row["rule"]: all(oriented(p["objective"], sense) > schedule for p in row["policies"].values()) for row in rows}
    certified = [row for row in rows if worst[row["rule"]] <= bound and ahead[row["rule"]]]
    best = max(certified, key=lambda row: oriented(row["objective"], sense), default=None)
    chosen = None if best is None or best["rule"] == "none" else best["rule"]
    dearer = [row["rule"] for row in rows if worst[row["rule"]] <= bound and not ahead[row["rule"]]]  # behind the schedule
    return dict(
        {key: value for key, value in result.items() if key != "budget"},  # a budget's choice is not this one's
        chosen=chosen,
        selection={
            "by": "certify",
            "bound": bound,
            "confidence": confidence,
            "z": z,
            "least_sd": least,
            "upper_bounds": worst,
            "behind_schedule": dearer,
        },
        certified=[row["rule"] for row in certified],
        safe=best is not None,
    )
