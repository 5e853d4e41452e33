"""The learner comparison's page, ``docs/results/learners.md``, from ``learners.json`` alone."""

from __future__ import annotations

import numpy as np

from etmpc.evaluation import metrics
from etmpc.experiments.studies import runner
from etmpc.systems import names


def fmt(value, digits=1) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def cell(r, key="score") -> str:
    if r is None:
        return "–"
    if key == "failures":
        return "–" if r["failures"] is None else f"{r['failures']:.2f} ± {fmt(r['failures_ci95'], 2)}"
    return f"{fmt(r['score'])} ± {fmt(r['score_ci95'])}"


def made(document: dict) -> str:
    """Which commit made which tasks (each task's own, else the document's), with the dates."""
    by_commit: dict[tuple[str, str], list[str]] = {}
    for task, result in document["tasks"].items():
        when = result.get("made") or {"commit": document["commit"], "date": document["date"]}
        commit = when["commit"] + (" with uncommitted changes" if when.get("uncommitted_changes") else "")
        by_commit.setdefault((commit, when["date"]), []).append(task)
    return "; ".join(
        f"commit `{commit}` ({date}) for {', '.join(f'`{t}`' for t in tasks)}" for (commit, date), tasks in by_commit.items()
    )


def page(document: dict) -> str:
    lines = [
        "# Learners compared over training seeds",
        "",
        runner.generated("learners", "docs/results/learners.json"),
        "",
        f"Made on {document['machine']}: {made(document)}. On each task's stored test set (100 episodes), "
        "scores are paired with the best fixed schedule episode by episode: 0 is the best fixed schedule, 100 the "
        "oracle over it; ± is a 95 % CI. A learner is a distribution of runs: each of its training seeds is scored, "
        "and the shipped seed is the one chosen on validation episodes (training distribution), never on these. "
        "Failures are the task's own (falls, steps outside the geofence, ...) per episode. The rollout meter and "
        "the oracle simulate the future at every decision (the oracle knows it): they are what a policy could "
        "reach, not policies one could ship.",
        "",
        "| task | learner | shipped seed: score | failures / episode | seeds: mean ± sd [min, max] | training cost |",
        "|---|---|---|---|---|---|",
    ]
    for task, result in document["tasks"].items():
        rows = result["rows"]
        best = rows[result["best_fixed"]]
        lines.append(f"| `{task}` | best fixed `{result['best_fixed']}` | 0 | {cell(best, 'failures')} | | |")
        for name, learner in result["learners"].items():
            shipped = rows[learner["chosen_policy"]]
            scores = learner["seed_scores"]
            cost = learner["cost"]
            spent = "–" if cost is None else f"{cost['wall_seconds'] / 60:.0f} min on {cost['workers']} workers"
            if cost is not None and "environment_steps" in cost:
                spent += f", {cost['environment_steps']} environment steps per seed"
            elif cost is not None:
                spent += f", {cost['seeds_in_lockstep']} seeds together"
            lines.append(
                f"| | {name} (seed {learner['chosen']} of {len(scores)}) | {cell(shipped)} | {cell(shipped, 'failures')} | "
                f"{fmt(learner['seed_mean'])} ± {fmt(learner['seed_sd'])} [{fmt(min(scores))}, {fmt(max(scores))}] | {spent} |"
            )
            if result["shield"] is not None:
                rule = result["shield"]["rule"]
                spec = f"shield:{rule}:{learner['chosen_policy']}"
                lines.append(f"| | {name} + shield `{rule}` | {cell(rows[spec])} | {cell(rows[spec], 'failures')} | | |")
        for name, spec in result["bounds"].items():
            lines.append(f"| | {name} `{spec}` | {cell(rows[spec])} | {cell(rows[spec], 'failures')} | | |")
    missing = [task for task in names() if task not in document["tasks"]]
    if missing:
        listed = ", ".join(f"`{task}`" for task in missing)
        lines += ["", f"Not run yet: {listed} (`etmpc study learners --task TASK`)."]
    lines += ["", "## Across the tasks above", ""]
    lines += [
        "The interquartile mean (rliable's IQM, over every task's episode scores) of each learner's shipped seed, "
        "and of every seed pooled, with 95 % stratified bootstrap intervals:",
        "",
        "| learner | IQM, shipped seed | IQM, all seeds |",
        "|---|---|---|",
    ]
    for name in ("DPI", "PPO"):
        shipped = [r["rows"][r["learners"][name]["chosen_policy"]]["episode_scores"] for r in document["tasks"].values()]
        pooled = [
            np.concatenate([r["rows"][p]["episode_scores"] for p in r["learners"][name]["seeds"].values()])
            for r in document["tasks"].values()
        ]
        low, high = metrics.iqm_ci95(shipped)
        plow, phigh = metrics.iqm_ci95(pooled)
        one = metrics.iqm(shipped)
        every = metrics.iqm(pooled)
        lines.append(f"| {name} | {one:.1f} [{low:.1f}, {high:.1f}] | {every:.1f} [{plow:.1f}, {phigh:.1f}] |")
    return "\n".join(lines) + "\n"
