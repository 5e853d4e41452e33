"""The safety audit's page, ``docs/results/safety.md``, made from ``safety.json`` alone (``etmpc study safety
--page-only``): what the audit stream is, one line per task saying which learner rows pass, and each task's table."""

from __future__ import annotations

from etmpc.experiments.studies import runner

#: What one failure is on a safety task, by the name the task gives its failures (``failure_name``).
COUNTS = {
    "falls": "a fall (the pole beyond 1.2 rad from upright) counts once, and the pole is put back upright; the "
    "rail's bumpers cost reward while the cart presses them but are not counted",
    "outside geofence": "each step that ends outside the geofence or on the ground counts one, so an episode that "
    "stays out 9 steps counts 9: severity is in the count",
}

#: The tasks that count failures which are not safety events, and what they count instead (one line each).
NOT_SAFETY = {
    "cart_pendulum/balance": "*off balance*, steps that end with the pole more than 0.1 rad from upright: a band a "
    "well-kept pole stays in, not a fall (no periodic schedule lets it fall), and the task reads no margin to one",
    "battery/trading": "*curtailed*, intervals whose trade the empty or full battery cut: money lost, no hazard",
    "reacher/jumps": "*far from target*, steps that end more than 0.1 m from the target: tracking quality",
    "reacher/jumps_late": "*far from target*, as `reacher/jumps`",
}


def page(document: dict) -> str:
    """The page of ``document`` (``safety.json``)."""
    target = document["target"]
    lines = [
        "# Safety audit: the shipped learners' failures against the best fixed schedule",
        "",
        runner.generated("safety", "docs/results/safety.json"),
        "",
        "On each task whose failures are safety events (its system reads a margin to a failure, `safety_margin`, as a "
        "shield does), the best fixed schedule and every shipped learner row of the [leaderboard](../leaderboard.md) "
        "on that task (with the same specs) are played on the same fresh episodes: the **audit stream** "
        f"(`AUDIT_ENTROPY` = {document['audit_entropy']:#x} in `etmpc/learning/config.py`), drawn from the training "
        "distribution apart from the training, selection, validation and stored test episodes, and kept for "
        "reporting: nothing is ever chosen on it. Each learner row is paired with the schedule episode by episode. "
        f"The issue's target: the upper bound of the 95 % CI of the paired difference, learner failures minus the "
        f"schedule's per episode, at most **{target:g}** (normal CI, 1.96 sd / sqrt(n); the paired percentile "
        "bootstrap's interval beside it, seeded). The objective column is the paired gain over the schedule in % "
        "of its mean objective (above 0: the learner is better), ± its 95 % CI. Played on "
        f"{document['machine']}; each task says the commit that made its table (its outcomes may be kept from an "
        "earlier run in `--work`, which records the commit that played them).",
        "",
        "What a failure is: " + "; ".join(f"**{name}**: {text}" for name, text in COUNTS.items()) + ".",
        "",
        "Not safety tasks: " + "; ".join(f"`{task}` counts {text}" for task, text in NOT_SAFETY.items()) + ".",
        "",
        "| task | episodes | best fixed: failures / episode | meet the target | miss it |",
        "|---|---:|---|---|---|",
    ]
    for task, t in document["tasks"].items():
        fixed = t["best_fixed"]
        met = [r["row"] for r in t["rows"] if r["meets_target"]]
        missed = [r["row"] for r in t["rows"] if not r["meets_target"]]
        lines.append(
            f"| `{task}` | {t['episodes']} | `{fixed['spec']}`: {fixed['failures']:.3f} | "
            f"{', '.join(met) or 'none'} | {', '.join(missed) or 'none'} |"
        )
    lines.append("")
    for task, t in document["tasks"].items():
        lines += section(task, t)
    return "\n".join(lines)


def section(task: str, t: dict) -> list[str]:
    """One task's table: the schedule, then each learner row paired with it."""
    made = t["made"]
    dirty = " with uncommitted changes" if made.get("uncommitted_changes") else ""
    fixed = t["best_fixed"]
    lines = [
        f"## `{task}`",
        "",
        f"{t['episodes']} audit episodes; failures: *{t['failure_name']}*. Made at commit `{made['commit']}`{dirty} "
        f"({made['date']}), in {t['seconds'] / 60:.1f} min of play.",
        "",
        "| row | failures / episode | episodes with a failure | most in one episode | learner − fixed, failures / "
        "episode (95 % CI) | upper bound | bootstrap 95 % CI | meets | learner − fixed, share of episodes with a "
        "failure | objective vs fixed | recomputes |",
        "|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|",
        f"| best fixed `{fixed['spec']}` | {fixed['failures']:.3f} ± {fixed['failures_ci95']:.3f} | "
        f"{fixed['failed_episodes']} | {fixed['worst_episode_failures']:g} | | | | | | | {fixed['recomputes']:.1f} |",
    ]
    for r in t["rows"]:
        low, high = r["failures_difference_bootstrap"]
        lines.append(
            f"| {r['row']} `{r['spec']}` | {r['failures']:.3f} ± {r['failures_ci95']:.3f} | {r['failed_episodes']} | "
            f"{r['worst_episode_failures']:g} | {r['failures_difference']:+.3f} ± {r['failures_difference_ci95']:.3f} | "
            f"{r['failures_difference_upper']:+.3f} | [{low:+.3f}, {high:+.3f}] | {'yes' if r['meets_target'] else '**no**'} "
            f"| {r['failed_episodes_difference']:+.3f} ± {r['failed_episodes_difference_ci95']:.3f} "
            f"| {r['objective_gain_percent']:+.2f} % ± {r['objective_gain_percent_ci95']:.2f} | {r['recomputes']:.1f} |"
        )
    return [*lines, ""]
