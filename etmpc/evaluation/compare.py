"""Policies against a reference on the same episodes: paired differences with 95 % confidence intervals.

Every policy of an evaluation meets the same test-set episodes, so a policy is compared with a
reference episode by episode: the mean difference, its 95 % CI (normal approximation, ``1.96 sd /
sqrt(n)``), the same as a percentage of the reference's mean, and the episodes where it is better. On a
task that counts failures (falls, steps outside a geofence, ...) the failures are paired too: the mean
difference per episode (> 0: more failures than the reference) and its 95 % CI.
``etmpc evaluate --against SPEC`` prints :func:`format_against`.
"""

from __future__ import annotations

import numpy as np

from etmpc.common.wording import spread
from etmpc.common.errors import EtmpcError
from etmpc.evaluation import metrics


def per_episode(evaluation: dict, policies=None, value: str = "objective") -> dict[int, float]:
    """Episode -> the mean ``value`` (the objective, or ``"failures"``) of ``policies`` (default: every
    policy in the file) over their finite runs (seeds and passes together)."""
    values: dict[int, list[float]] = {}
    for r in evaluation["runs"]:
        if r["finite"] and (policies is None or r["policy"] in policies):
            values.setdefault(r["episode"], []).append(r[value])
    return {e: float(np.mean(v)) for e, v in values.items()}


def paired_failures(mine: dict[int, float], theirs: dict[int, float]) -> dict:
    """Failures per episode (episode -> mean) against the reference's on their common episodes: ``mine``'s
    mean, the mean difference per episode (> 0: more) and its 95 % CI."""
    common = sorted(set(mine) & set(theirs))
    diff = metrics.paired_differences([mine[e] for e in common], [theirs[e] for e in common], "min")
    return {
        "failures_mean": float(np.mean([mine[e] for e in common])),
        "difference": diff["mean_difference"],
        "ci95": diff["ci95"],
    }


def paired(a: dict[int, float], b: dict[int, float], sense: str, episodes=None) -> dict:
    """``a`` against ``b`` on their common episodes (or ``episodes``): the mean difference ``a - b``
    with its 95 % CI (:func:`~etmpc.evaluation.metrics.paired_differences`), and the same as a
    percentage of ``|mean b|``, signed so that > 0 is better."""
    common = sorted(set(a) & set(b) if episodes is None else set(episodes) & set(a) & set(b))
    mine, theirs = [a[e] for e in common], [b[e] for e in common]
    diff = metrics.paired_differences(mine, theirs, sense)
    mean, ci = diff["mean_difference"], diff["ci95"]
    scale = abs(float(np.mean(theirs))) if common else float("nan")
    return {
        "episodes": len(common),
        "objective_mean": float(np.mean(mine)) if common else float("nan"),
        "reference_mean": float(np.mean(theirs)) if common else float("nan"),
        "mean_difference": mean,
        "ci95": ci,
        "gain_percent": 100.0 * metrics.oriented(mean, sense) / scale,
        "gain_percent_ci95": 100.0 * ci / scale,
        "better_episodes": diff["better_episodes"],
    }


def against(evaluation: dict, reference: str) -> dict[str, dict]:
    """Each policy of ``evaluation`` (an evaluation's JSON) against ``reference``, paired per episode;
    gains > 0 are better, whatever the objective's sense."""
    policies = evaluation["policies"]
    if reference not in policies:
        raise EtmpcError(f"--against {reference}: not one of the evaluated policies ({', '.join(policies)})")
    sense = policies[reference]["objective_sense"]
    base = per_episode(evaluation, {reference})
    counted = all(r.get("failures") is not None for r in evaluation["runs"] if r["finite"])  # the task counts failures
    base_failures = per_episode(evaluation, {reference}, "failures") if counted else None
    return {
        spec: dict(
            paired(per_episode(evaluation, {spec}), base, sense),
            recomputes_mean=row["recomputes_mean"],
            clairvoyant=row.get("clairvoyant", row.get("upper_bound", False)),  # upper_bound: an older etmpc's name
            failures=None
            if base_failures is None
            else paired_failures(per_episode(evaluation, {spec}, "failures"), base_failures),
        )
        for spec, row in policies.items()
        if spec != reference
    }


def format_against(evaluation: dict, reference: str) -> str:
    """The table of :func:`against`: objective, paired difference and gain (95 % CI), episodes better."""
    rows = against(evaluation, reference)
    ref = evaluation["policies"][reference]
    name = next((row.get("failure_name") for row in evaluation["policies"].values() if row.get("failure_name")), None)
    counted = name is not None and all(r["failures"] is not None for r in rows.values())
    width = max([16] + [len(spec) + 2 for spec in rows])
    head = (
        f"{'policy':<{width}}{'objective':>12}{'difference':>13}{'± 95 % CI':>11}{'gain %':>9}{'± CI':>7}{'better':>9}"
        f"{'recomputes':>12}" + (f"{'Δ failures ± CI':>19}" if counted else "")
    )
    lines = [
        f"paired over the same test-set episodes against {reference} ({ref['objective_mean']:.5f}, "
        f"{ref['recomputes_mean']:.2f} recomputes); gain > 0 is better",
        head,
        "-" * len(head),
    ]
    for spec, r in rows.items():
        label = spec + (" (oracle)" if r["clairvoyant"] else "")
        failures = f"{r['failures']['difference']:>+11.2f} ± {spread(r['failures']['ci95']):<5}" if counted else ""
        lines.append(
            f"{label:<{width}}{r['objective_mean']:>12.5f}{r['mean_difference']:>+13.5f}{spread(r['ci95'], '.5f'):>11}"
            f"{r['gain_percent']:>+9.2f}{spread(r['gain_percent_ci95']):>7}{r['better_episodes']:>5d}/{r['episodes']:<3d}"
            f"{r['recomputes_mean']:>12.2f}{failures}"
        )
    if counted:
        lines.append(f"Δ failures: {name} per episode against {reference}'s on the same episodes (> 0: more), 95 % CI")
    return "\n".join(lines)
