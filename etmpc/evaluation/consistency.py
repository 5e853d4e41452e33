"""What ``etmpc verify`` checks of a card from its own numbers, before it replays anything: each row's numbers
follow from the episodes it carries (each episode's score from its objective and the references, bit for bit;
the means, totals, intervals and shares from the episodes; the CPU time's total from its parts), and the
suite's aggregates follow from the rows, as :mod:`etmpc.evaluation.scorecard` computes them. Each function
returns its mismatches, one line each (:mod:`etmpc.evaluation.verify` says where they come from)."""

from __future__ import annotations

import math

import numpy as np

from etmpc.common.outputs import strict
from etmpc.evaluation import metrics
from etmpc.evaluation.card import TaskScore, aggregate, by_policy
from etmpc.evaluation.references import References

TOLERANCE = 1e-9  # relative: a row's score against the mean of its episode scores (two summations)
CPU_PARTS = ("solve", "feedback", "decide", "total")


def same(a, b) -> bool:
    """Equal as the card stores numbers: NaN (JSON's null) equals NaN."""
    return (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)) or a == b


def row_mismatches(row: TaskScore, refs: References, version) -> list[str]:
    """What in a complete ``row`` does not follow from its own episodes (``version``: the card's task version)."""
    name = f"{row.task} {row.policy}"
    s = row.scores
    if row.reference != refs.best:
        return [f"{name}: scored against {row.reference}, the references' best schedule is {refs.best}"]
    if not np.all(np.isfinite(s)):
        return [f"{name}: an episode score is not a number"]
    found = [
        f"{name}: {what} {mine!r} in the row, {theirs!r} {whose}"
        for what, mine, theirs, whose in (
            ("task version", row.task_version, version, "in the card's task versions"),
            ("objective sense", row.objective_sense, refs.objective_sense, "the task's"),
            ("non-finite episodes", row.nonfinite_episodes, 0, "in a row that was scored"),
        )
        if mine != theirs
    ]
    found += _episodes_consistency(row, refs, name) + _cpu_consistency(row, name)
    if not math.isclose(row.score, float(np.mean(s)), rel_tol=TOLERANCE, abs_tol=TOLERANCE):
        found.append(f"{name}: score {row.score!r} in the card, the mean of its episode scores is {float(np.mean(s))!r}")
    ci = metrics.mean_ci95(s)
    if not same(row.score_ci95, ci):
        found.append(f"{name}: 95 % CI {row.score_ci95!r} in the card, {ci!r} from its episode scores")
    better = metrics.improvement_share(s)
    if not same(row.better_share, better):
        found.append(f"{name}: better in {row.better_share!r} of the episodes in the card, {better!r} from its episode scores")
    return found + _failures_consistency(row, name)


def _mean_differs(stated, values) -> bool:
    return not (
        isinstance(stated, (int, float)) and math.isclose(stated, float(np.mean(values)), rel_tol=TOLERANCE, abs_tol=TOLERANCE)
    )


def _episodes_consistency(row: TaskScore, refs: References, name: str) -> list[str]:
    """What of a row's objective, recomputes, solver failures and episode scores does not follow from the
    objectives, recomputes and solver failures it carries per episode."""
    carried = {
        "episode_objectives": row.episode_objectives,
        "episode_recomputes": row.episode_recomputes,
        "episode_solver_failures": row.episode_solver_failures,
    }
    for key, values in carried.items():
        if values is None:
            return [f"{name}: no {key} (a row of an older etmpc): score the policy again to verify its numbers"]
        if len(values) != row.episodes:
            return [f"{name}: {len(values)} {key} for {row.episodes} episodes"]
    recomputes = row.episode_recomputes
    solver_failures = row.episode_solver_failures
    assert recomputes is not None and solver_failures is not None  # each checked in the loop above
    objectives = np.asarray(row.episode_objectives, dtype=float)
    if not np.all(np.isfinite(objectives)):
        return [f"{name}: an episode objective is not a number in a row that was scored"]
    best = refs.costs(refs.periodic[refs.best])
    expected = [float(v) for v in metrics.normalized_scores(refs.costs(objectives), best, refs.gap)]
    found = [
        f"{name} episode {e}: score {row.episode_scores[e]!r} in the card, {v!r} from its objective {float(objectives[e])!r}"
        for e, v in enumerate(expected)
        if row.episode_scores[e] != v
    ]
    if _mean_differs(row.objective_mean, objectives):
        found.append(f"{name}: objective {row.objective_mean!r} in the card, {float(np.mean(objectives))!r} from its episodes")
    if _mean_differs(row.recomputes_mean, recomputes):
        mean = float(np.mean(recomputes))
        found.append(f"{name}: recomputes {row.recomputes_mean!r} per episode in the card, {mean!r} from its episodes")
    if row.solver_failures != sum(solver_failures):
        total = sum(solver_failures)
        found.append(f"{name}: {row.solver_failures!r} solver failures in the card, {total!r} from its episodes")
    return found


def _cpu_consistency(row: TaskScore, name: str) -> list[str]:
    """What of a row's CPU time per episode (the scorer's measurement, not replayed) does not hold together:
    the four parts, each a finite number >= 0, the total their sum (none at all: not measured)."""
    cpu = row.cpu_ms
    if not cpu:
        return []
    if sorted(cpu) != sorted(CPU_PARTS):
        return [f"{name}: CPU time of {', '.join(sorted(cpu))} in the card; a row measures {', '.join(CPU_PARTS)}"]
    if not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in cpu.values()):
        return [f"{name}: a CPU time in the card is not a finite number >= 0 ({cpu})"]
    parts = cpu["solve"] + cpu["feedback"] + cpu["decide"]
    if not math.isclose(cpu["total"], parts, rel_tol=TOLERANCE, abs_tol=TOLERANCE):
        return [f"{name}: CPU total {cpu['total']!r} ms in the card, its parts sum to {parts!r}"]
    return []


def _failures_consistency(row: TaskScore, name: str) -> list[str]:
    """What of a row's failures (a card of an older etmpc has none) does not follow from its episodes' counts."""
    counts = row.episode_failures
    if counts is None:
        return []
    if len(counts) != row.episodes or not all(isinstance(c, (int, float)) and math.isfinite(c) for c in counts):
        return [f"{name}: {len(counts)} episode failure counts for {row.episodes} episodes, or one not a number"]
    found = []
    mean = float(np.mean(counts))
    if row.failures_mean is None or not math.isclose(row.failures_mean, mean, rel_tol=TOLERANCE, abs_tol=TOLERANCE):
        found.append(f"{name}: failures {row.failures_mean!r} per episode in the card, {mean!r} from its episodes")
    if not same(row.failures_ci95, metrics.mean_ci95(counts)):
        found.append(
            f"{name}: failures' 95 % CI {row.failures_ci95!r} in the card, {metrics.mean_ci95(counts)!r} from its episodes"
        )
    return found


def aggregate_mismatches(card: dict, rows: list[TaskScore]) -> list[str]:
    """Which of the card's aggregates do not follow from its rows: each computed again and compared as the
    card stores it (strict JSON: a tuple a list, NaN null), where equal floats are equal bits."""
    policies = [a["policy"] for a in card["aggregates"]]  # each an object with a policy (etmpc.evaluation.card_checks)
    given = {a["policy"]: a for a in card["aggregates"]}
    found = [f"{policy}: {policies.count(policy)} aggregates in the card" for policy in given if policies.count(policy) > 1]
    found += [f"{policy}: an aggregate in the card, but no rows of it" for policy in given if policy not in by_policy(rows)]
    for policy, mine in by_policy(rows).items():
        stated = given.get(policy)
        if stated is None:
            found.append(f"{policy}: no aggregate in the card")
            continue
        for key, value in strict(aggregate(mine).to_json()).items():
            if stated.get(key) != value:
                found.append(f"{policy}: aggregate {key} {stated.get(key)!r} in the card, {value!r} from its rows")
    return found
